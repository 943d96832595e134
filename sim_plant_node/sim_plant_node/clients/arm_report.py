"""The arm demo's report: the results table, the per-case sums, the per-move learner's table, the samples lost
and the tool deviation plot, written to results.csv, results.md and tool_deviation.png."""

from __future__ import annotations

import csv
import math
import pathlib
from typing import Any

import numpy as np

from ..arm.metrics import noise_floor
from . import arm_split
from .arm_client import ArmClient, MoveRun


def table(rows: list[dict[str, Any]]) -> list[str]:
    head = ["case", "move", "residual RMS m/s^2", "% of unshaped", "peak mm", "settling s", "move+settle s",
            "shaper delay s", "path deviation mm"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        move = f"{r['move']} ({r['lost']})" if r.get("lost") else r["move"]
        out.append(f"| {r['case']} | {move} | {r['residual_rms']:.4f} | {r['percent']:.1f} | {r['peak_mm']:.4f} |"
                   f" {r['settling_s']:.3f} | {r['move_and_settle_s']:.3f} | {r['delay_s']:.3f} |"
                   f" {r['path_deviation_mm']:.3f} |")
    return out


def per_move_table(per_move: list[list[tuple[MoveRun, Any, Any]]], rows: list[dict[str, Any]],
                    noise: float) -> list[str]:
    """The per-move case, per move and cycle: the residual RMS (m/s^2) and the move + settle time (s), the last
    cycle's against the schedule's (its row of the case ``scheduled``, if run), and what the learner's last
    report of the move says."""
    def status(report: Any) -> str:
        m = dict(zip(report.metric_names, report.metric_values, strict=True))
        if m.get("skipped"):
            return "skipped"
        if "speed_factor" in m:  # speed-up per move
            from .arm_speed import status as speed_status

            return speed_status(m)
        if "cost" in m:  # MRILC per move
            action = next((k.split(".", 1)[1] for k in m if k.startswith("action.")), "?")
            return (f"cost {m['cost']:.4g} m/s^2, {action}; correction used {m['max_correction_rad']:.2e} rad,"
                    f" limit excess {m['limit_excess']:.1g}")
        if m.get("held") and "a1_next" not in m:
            return "held at the schedule alone"
        if "a1_next" not in m or m["a1_next"] != m["a1_next"]:
            return "the schedule alone next"
        return (f"factor A1 {m['a1_next']:.3f}, T2 {1e3 * m['t2_next']:.1f} ms"
                + (" (held)" if m.get("held") else ""))

    cycles = len(per_move)
    head = ["move", *[f"c{k + 1}" for k in range(cycles)], "last % of scheduled", "learner's last report"]
    out = [f"Per move and cycle (the per-move learner's cycles; accelerometer noise {noise:g} m/s^2, its floor"
           f" {noise_floor(noise).floor:.4f} m/s^2 in this RMS): residual RMS m/s^2, then move + settle s", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for what, key in (("residual", "residual_rms"), ("move+settle", "move_and_settle_s")):
        for i, (run, _, _) in enumerate(per_move[0]):
            name = f"{run.index + 1}. {run.name}"
            values = [float(getattr(c[i][1], key)) for c in per_move]
            sched = next((r[key] for r in rows if r["case"] == "scheduled" and r["move"] == run.name), None)
            ratio = f"{100 * values[-1] / sched:.1f}" if sched else "-"
            fmt = "{:.4f}" if key == "residual_rms" else "{:.3f}"
            out.append(f"| {name} {what} | " + " | ".join(fmt.format(v) for v in values)
                       + f" | {ratio} | {status(per_move[-1][i][2]) if what == 'residual' else ''} |")
    return out


def losses(client: ArmClient) -> str:
    """One line: the samples the client checked and those lost (gaps in the stamps), per stream."""
    gaps = client.lockstep.gaps
    lost = client.lockstep.describe_lost()
    checked = ", ".join(f"{name} {g.samples}" for name, g in gaps.items())
    return (f"Samples lost: {lost.removeprefix('lost ')} (the moves they touch are marked above); received:"
            f" {checked}" if lost else
            f"Samples lost: none (no gap in the stamps; received: {checked})")


def sums(rows: list[dict[str, Any]], cases: list[str], noise: float) -> list[str]:
    """Per case: the residual summed over the cycle's moves, as measured and above the accelerometer's noise
    (sqrt(RMS^2 - 3 noise^2) per move: the noise adds 3 noise^2 to the mean square over three axes), and their
    ratios to the unshaped and the fixed shaper's."""
    def above(rms: float) -> float:
        return math.sqrt(max(rms * rms - 3.0 * noise * noise, 0.0))

    total = {c: sum(r["residual_rms"] for r in rows if r["case"] == c) for c in cases}
    clean = {c: sum(above(r["residual_rms"]) for r in rows if r["case"] == c) for c in cases}
    out = ["| case | summed residual RMS m/s^2 | % of unshaped | % of fixed | above the noise m/s^2 | % of fixed |",
           "|---|---|---|---|---|---|"]
    for c in cases:
        lost = sum(1 for r in rows if r["case"] == c and r.get("lost"))
        name = f"{c} ({lost} move{'s' if lost != 1 else ''} with lost samples)" if lost else c
        has = "fixed" in total and total["fixed"] > 0 and clean["fixed"] > 0
        fixed = f"{100 * total[c] / total['fixed']:.1f}" if has else "-"
        fixed_clean = f"{100 * clean[c] / clean['fixed']:.1f}" if has else "-"
        out.append(f"| {name} | {total[c]:.4f} | {100 * total[c] / total['none']:.1f} | {fixed} | {clean[c]:.4f} |"
                   f" {fixed_clean} |")
    return out


def plot(path: pathlib.Path, traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]], cases: list[str],
         moves: list[str]) -> Any:
    """tool_deviation.png: per move, each case's distance of the flange from where it comes to rest (mm)
    against the time from the planned end of the move (s), with the settling band
    (:data:`~sim_plant_node.arm.metrics.SETTLE_TOLERANCE`, 0.05 mm) shaded; the figure is returned
    (closed) for inspection.

    Every case keeps its own colour and line style, the first drawn widest, so a case whose trace is
    another's (the schedule and the fixed shaper apply the same shaper where a move ends at the home
    reach) shows as a coloured dash over it; the panel's title names such pairs (within 0.001 mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..arm.metrics import SETTLE_TOLERANCE

    band_mm = SETTLE_TOLERANCE * 1e3
    same_mm = 1e-3  # traces within a micrometre of each other are one on the figure
    styles = ["-", "--", "-.", ":"]
    fig, axes = plt.subplots(len(moves), 1, figsize=(10, 2.3 * len(moves)), sharex=True, squeeze=False)
    for ax, move in zip(axes[:, 0], moves, strict=True):
        drawn: list[tuple[str, np.ndarray]] = []
        same: list[str] = []
        ax.axhspan(0.0, band_mm, color="0.85", zorder=0, label=f"settling band ({band_mm:g} mm)")
        for i, case in enumerate(cases):
            if (case, move) not in traces:
                continue
            t, d = traces[(case, move)]
            ax.plot(t, d, lw=max(0.7, 2.2 - 0.4 * i), ls=styles[i % len(styles)], color=f"C{i % 10}",
                    label=case, zorder=2 + i)
            twin = next((c for c, e in drawn if e.shape == d.shape and np.allclose(e, d, rtol=0, atol=same_mm)), None)
            if twin is not None:
                same.append(f"{case} = {twin}")
            drawn.append((case, d))
        ax.set_title(move + (f"  (same trace within {same_mm:g} mm: {', '.join(same)})" if same else ""), fontsize=9)
        ax.set_ylabel("tool dev. (mm)")
        ax.grid(alpha=0.3)
        ax.set_yscale("symlog", linthresh=0.01)
    axes[0, 0].legend(loc="upper right", fontsize=8, ncol=len(cases) + 1)
    axes[-1, 0].set_xlabel("time from the planned end of the move (s): distance of the flange from where it comes"
                           " to rest")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


def case_rows(client: ArmClient, case: str, runs: list[MoveRun], installed: str,
              reference_paths: dict[int, np.ndarray], rows: list[dict[str, Any]],
              traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]) -> None:
    """Measure a case's last cycle ``runs``: a row per move into ``rows``, its flange's distance from rest (mm)
    against the time from the move's planned end (s) into ``traces``; the unshaped case (``none``) sets each move's
    reference tool path in ``reference_paths``."""
    for run in runs:
        if case == "none":
            reference_paths[run.index] = client.tool_path("cmd", run.start, run.end)[1]
        m, _ = client.measure(run, reference_paths[run.index])
        lt, tool = client.tool_path("link", run.start, run.end)
        planned_end = run.start + run.planned
        traces[(case, f"{run.index + 1}. {run.name}")] = (
            lt - planned_end, 1e3 * np.linalg.norm(tool - tool[-1], axis=1))
        rows.append({"case": case, "move": f"{run.index + 1}. {run.name}", **m.__dict__,
                     "move_and_settle_s": m.move_and_settle_s, "installed": installed,
                     "lost": client.lockstep.describe_lost(run.start, run.end),
                     **arm_split.columns(client.splits.of(run.start, run.end))})


def write_report(out: pathlib.Path, rows: list[dict[str, Any]], cases: list[str],
                 per_move: list[list[tuple[MoveRun, Any, Any]]],
                 traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]], moves: list[str], noise: float,
                 payload_table: list[str]) -> None:
    """Each row's residual as a percentage of the unshaped case's; results.csv, results.md (the note on the
    measures, the tables; ``payload_table`` last) and tool_deviation.png in ``out``; the note and the tables
    printed."""
    for r in rows:
        base = next(x for x in rows if x["case"] == "none" and x["move"] == r["move"])
        r["percent"] = 100.0 * r["residual_rms"] / base["residual_rms"] if base["residual_rms"] > 0 else math.nan
    keys = ["case", "move", "residual_rms", "percent", "residual_peak", "peak_mm", "settling_s", "move_s",
            "move_and_settle_s", "delay_s", "path_deviation_mm", "installed", "lost"]
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    lines = [*table(rows), "", *sums(rows, cases, noise)]
    if per_move:
        lines += ["", *per_move_table(per_move, rows, noise)]
        if "scheduled_speedup" in cases:
            from .arm_speed import summary

            lines += summary(per_move, rows)
    lines += payload_table
    lines += arm_split.table(rows, cases, noise)
    from ..arm.metrics import RESIDUAL_WINDOW, SETTLE_TOLERANCE

    note = (f"Residual vibration: the flange IMU's specific force minus its mean, over {RESIDUAL_WINDOW:g} s after"
            f" the commanded motion ends (accelerometer noise {noise:g} m/s^2); peak: the flange's largest"
            f" distance from where it comes to rest in that window; settling: from the planned end of the move until"
            f" the flange stays within {SETTLE_TOLERANCE * 1e3:g} mm; delay: commanded motion end minus planned end;"
            " path deviation: commanded tool path against the unshaped one. Last cycle of each case.")
    (out / "results.md").write_text("# Arm demo\n\n" + note + "\n\n" + "\n".join(lines) + "\n")
    plot(out / "tool_deviation.png", traces, cases, moves)
    print()
    print(note)
    print("\n".join(lines))
