"""The page of ``scheduled_list_speedup`` (issue 31's "scheduled + learning + speed-up"), from its runs' JSON.

``python -m reproductions.arm_speed_list NOISE_FREE.json NOISY.json [--docs DIR]`` writes
``docs/results/arm_learning_speed_list.md`` from two runs of :mod:`reproductions.arm_learning`
(``--cases scheduled,scheduled_list_speedup --cycles 10 --no-docs --json ...``, the second with
``--noise 0.01``); it runs nothing. The case is opt-in there (not in the default case list), so
docs/results/arm_learning.md is unchanged by it.
"""

from __future__ import annotations

import argparse
import json
import pathlib
from typing import Any

from reproductions.common import docs_option

CASE = "scheduled_list_speedup"
BASE = "scheduled"
GOAL = 0.20  # the issue: the cycle's summed move + settle at least 20 % shorter than the scheduled cycle
TOL_MM = 0.05
Row = dict[str, Any]


def _sums(rows: list[Row], case: str, key: str) -> dict[int, float]:
    out: dict[int, float] = {}
    for r in rows:
        if r["case"] == case:
            out[r["cycle"]] = out.get(r["cycle"], 0.0) + float(r[key])
    return out


def section(doc: dict[str, Any]) -> list[str]:
    """One run's section: the cycle sums, the last cycle per move, the goals and the notes."""
    rows, noise = doc["rows"], float(doc["noise"])
    mine = [r for r in rows if r["case"] == CASE]
    cycles = sorted({r["cycle"] for r in mine})
    t_case, t_base = _sums(rows, CASE, "move_settle_s"), _sums(rows, BASE, "move_settle_s")
    r_case, r_base = _sums(rows, CASE, "residual_rms"), _sums(rows, BASE, "residual_rms")
    head = f"IMU noise {noise:g} m/s^2 per axis (seed 0)" if noise > 0 else "noise-free"
    out = [f"## {head}", "",
           "| cycle | " + " | ".join(str(c) for c in cycles) + " |", "|---|" + "---|" * len(cycles),
           "| phase | " + " | ".join(next(r["phase"] for r in mine if r["cycle"] == c) for c in cycles) + " |",
           "| move + settle s, summed | " + " | ".join(f"{t_case[c]:.3f}" for c in cycles) + " |",
           f"| {BASE} move + settle s | " + " | ".join(f"{t_base[c]:.3f}" for c in cycles) + " |",
           "| shorter than the schedule | " + " | ".join(f"{100 * (1 - t_case[c] / t_base[c]):.1f} %" for c in cycles)
           + " |",
           "| residual RMS m/s^2, summed | " + " | ".join(f"{r_case[c]:.4f}" for c in cycles) + " |",
           f"| {BASE} residual RMS m/s^2 | " + " | ".join(f"{r_base[c]:.4f}" for c in cycles) + " |", ""]
    last = cycles[-1]
    out += [f"Per move at cycle {last}: the speed factor, the LIST factors kept, the flange's true peak and the node's"
            " accelerometer estimate of it (mm; the peak of the IMU's deviation from its mean from the commanded end"
            " + 0.1 s to 1 s, at the schedule's lowest mode at the goal), which of the two judged the cycle, the move"
            " + settle time against the schedule's, the largest joint speed against 180 deg/s and torque against"
            " its limit.", "",
            "| move | speed factor | LIST factors | true peak mm | estimate mm | judged by | move + settle s |"
            f" {BASE} s | speed / 180 deg/s | torque / limit |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in (x for x in mine if x["cycle"] == last):
        b = next(x for x in rows if x["case"] == BASE and x["move"] == r["move"] and x["cycle"] == last)
        out.append(f"| {r['move']} | {r['speed_factor']:.2f} | {r.get('factors', 0)} | {r['peak_mm']:.4f} |"
                   f" {r.get('estimate_mm', float('nan')):.4f} | {r.get('judged_by', '-')} |"
                   f" {r['move_settle_s']:.3f} | {b['move_settle_s']:.3f} | {r['velocity_ratio']:.2f} |"
                   f" {r['torque_ratio']:.2f} |")
    speed = [r for r in mine if r["phase"] == "speed"]
    reached = next((c for c in cycles if t_case[c] <= (1 - GOAL) * t_base[c]), None)
    bad = [r for r in speed if r.get("violation")]
    quiet = min((r for r in mine if r["cycle"] == last), key=lambda r: r["peak_mm"])
    out += ["", "**The issue's goals, measured:**", "",
            f"- Speed-up: the summed move + settle {t_case[last]:.3f} s at cycle {last} against {t_base[last]:.3f} s"
            f" for the schedule at planned speed ({100 * (1 - t_case[last] / t_base[last]):.1f} % shorter); at least"
            f" 20 % shorter from cycle {reached}. " + ("**Met.**" if reached is not None else "**Not met.**"),
            f"- Limits over the speed-up's cycles: joint speed at most {max(r['velocity_ratio'] for r in speed):.2f}"
            f" of 180 deg/s, torque at most {max(r['torque_ratio'] for r in speed):.2f} of the UR5e's limits"
            " (acceleration is not limited here: the reproduction's ceiling uses speed alone). Settled flange at"
            f" most {max(r['peak_mm'] for r in speed):.4f} mm true, {max(r['estimate_mm'] for r in speed):.4f} mm"
            f" estimated (tolerance {TOL_MM:g} mm). Cycles judged bad: {len(bad)}"
            + ("" if not bad else " (" + "; ".join(f"c{r['cycle']} {r['move']}: {r['violation']}" for r in bad)
               + ")") + ".",
            "- Judged by: " + ("the node's accelerometer estimate (the noise in it)" if noise > 0 else
                               "the flange's true peak")
            + (f": on the move that rings least at cycle {last} ({quiet['move']}) it reads"
               f" {quiet['estimate_mm']:.4f} mm against {quiet['peak_mm']:.4f} mm true, the noise's share of the"
               " tolerance." if noise > 0 else "."),
            f"- At cycle {last} the factors are " + ", ".join(f"{f:.2f}" for f in sorted({r['speed_factor'] for r in
                                                                                    mine if r['cycle'] == last}))
            + (", still rising (no cycle judged bad yet): more cycles would go further, up to the ceiling or the"
               " tolerance." if not bad else "."), ""]
    out += [f"- {n}" for n in doc.get("notes", {}).get(CASE, [])] + [""]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_speed_list", description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=pathlib.Path, nargs="+", help="the runs' JSON (noise-free, then with noise)")
    docs_option(p, "arm_learning_speed_list.md")
    args = p.parse_args(argv)
    docs = [json.loads(path.read_text()) for path in args.runs]
    lines = ["# Scheduled + LIST per move + speed-up, learned in turn (issue 31, item 6)", "",
             "Generated by `python -m reproductions.arm_speed_list` from `python -m reproductions.arm_learning --cases"
             " scheduled,scheduled_list_speedup --cycles 10 --no-docs --json A.json` and the same with `--noise 0.01`"
             " (the ROS-free arm and controller, deterministic). The case"
             " (`reproductions/arm_learning/speed.py`, `scheduled_list_speedup`) learns as the two learner nodes do"
             " when both run (docs/guide/learning.md,"
             " tests/test_learning_speed_list.py): first LIST's paying factors per move over the schedule (the rule of"
             " `scheduled_list_factor`) at the planned speed, the speed learner held; once every move's LIST has"
             " stopped, LIST held, each move's time-scaling factor is learned over the schedule and its kept factors"
             " (`SpeedLearner`, step 0.1, ceiling from 180 deg/s). A speed-up cycle is good when the velocity and"
             " torque limits hold and the settled flange is within 0.05 mm: noise-free by the flange's true peak"
             " (as the `speedup` case), with noise by the node's accelerometer estimate (`node_speed_estimate`, what"
             " nodes/learner_speed.py measures on a robot).", ""]
    for doc in docs:
        lines += section(doc)
    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "arm_learning_speed_list.md").write_text("\n".join(lines).rstrip() + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
