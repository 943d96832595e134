"""The fleet report: per robot its modes over time, the drift alerts and the retune to apply.

Files: ``fleet.md`` (the rule, per robot its baseline and alerts, the failed recordings, the plot),
``recordings.csv`` (one row per recording and mode), ``alerts.csv`` (one row per alert),
``fleet.json`` (everything) and ``modes.png`` (per robot the dominant mode's frequency over the
recording start time, with one-sigma bars, the baseline band f_b +- the frequency limit, the
recordings out marked, and each alert's first recording).
"""

from __future__ import annotations

import csv
import dataclasses
import datetime
import json
import math
import pathlib
from collections.abc import Sequence
from typing import Any

from .fleet import FleetRun
from .fleet_drift import DriftRule, RobotDrift
from .report import json_ready
from .text import counted, plus_minus, value


def _f(x: float | None, spec: str = ".4g") -> str:
    return value(x, spec)


def _when(t: float) -> str:
    if not math.isfinite(t):
        return "n/a"
    return datetime.datetime.fromtimestamp(t, tz=datetime.UTC).strftime("%Y-%m-%d %H:%M:%S")


def fleet_doc(run: FleetRun, drift: Sequence[RobotDrift], rule: DriftRule) -> dict[str, Any]:
    """Everything, as plain data (``fleet.json``)."""
    return json_ready({
        "rule": dataclasses.asdict(rule),
        "recordings": len(run.results), "analysed": run.analysed, "cached": run.cached,
        "failed": [{"path": r.path, "robot": r.robot, "error": r.error} for r in run.results if r.error],
        "seconds": run.seconds, "where": run.where,
        "robots": [{
            "robot": d.robot, "verdict": d.verdict, "note": d.note, "baseline_issue": d.baseline_issue,
            "baseline_hz": d.baseline_hz,
            "baseline_scatter_hz": d.baseline_scatter_hz,
            "baseline_zeta": d.baseline_zeta, "baseline_scatter_zeta": d.baseline_scatter_zeta,
            "baseline_recommendation": d.baseline_recommendation,
            "alerts": [dataclasses.asdict(a) for a in d.alerts],
            "recordings": [{**p.result.to_json(), "in_baseline": p.in_baseline, "compared_hz": p.frequency_hz,
                            "compared_zeta": p.zeta, "shift": p.shift, "shift_sigmas": p.shift_sigmas,
                            "damping_change": p.damping_change, "damping_sigmas": p.damping_sigmas, "out": p.out,
                            "why": p.why} for p in d.points],
        } for d in drift],
    })


def _shaper_text(s: dict[str, Any] | None) -> str:
    if not s:
        return "none (no shaper meets the target)"
    return (f"{s['family']} ({1e3 * s['duration_s']:.1f} ms, designed at {s['designed_hz']:.4g} Hz, zeta"
            f" {s['designed_zeta']:.3g}; V {100 * s['v_nominal']:.2g} % nominal, {100 * s['v_worst']:.2g} % worst)")


def headline(run: FleetRun, drift: Sequence[RobotDrift]) -> str:
    """The run in one line: recordings, robots, how many analysed, from the cache, failed; its time."""
    return (f"{counted(len(run.results), 'recording')} of {counted(len(drift), 'robot')}: {run.analysed} analysed"
            f" ({run.where}), {run.cached} from the cache, {sum(1 for r in run.results if r.error)} could not be"
            f" analysed; {run.seconds:.1f} s" + (f" (cluster start {run.startup_s:.1f} s)" if run.startup_s else ""))


def markdown(run: FleetRun, drift: Sequence[RobotDrift], rule: DriftRule, plot: str | None) -> str:
    """The report as Markdown."""
    alerts = [a for d in drift for a in d.alerts]
    lines = [
        "# Fleet report", "",
        headline(run, drift) + ".", "",
        f"Rule: baseline = each robot's first {rule.baseline} recordings with a mode (by start time); a later"
        f" recording is out when its mode moved by more than {100 * rule.max_frequency_shift:g} % and"
        f" {rule.sigmas:g} sigma, or its damping ratio by more than the larger of"
        f" {100 * rule.max_damping_change:g} % and {rule.damping_floor:g} and {rule.sigmas:g} sigma;"
        f" an alert after {rule.confirm} recordings out in a row (docs/guide/fleet.md).", "",
        f"**{len(alerts)} alert(s)**" + (": " + ", ".join(sorted({a.robot for a in alerts})) if alerts else ""), "",
        "| robot | recordings | baseline mode Hz | scatter Hz | baseline zeta | out | verdict | new mode Hz | retune |",
        "|---|---:|---:|---:|---:|---:|---|---:|---|",
    ]
    for d in drift:
        a = d.alerts[-1] if d.alerts else None
        lines.append(f"| {d.robot} | {len(d.points)} | {_f(d.baseline_hz)} | {_f(d.baseline_scatter_hz, '.2g')} |"
                     f" {_f(d.baseline_zeta, '.3g')} | {sum(p.out for p in d.points)} |"
                     f" {'**ALERT**' if d.verdict == 'ALERT' else d.verdict} | {_f(a.frequency_hz) if a else ''} |"
                     f" {a.retune['family'] if a and a.retune else ''} |")
    for d in drift:
        if not d.alerts and not d.note and not d.baseline_issue:
            continue
        lines += ["", f"## {d.robot}", ""]
        if d.note:
            lines.append(f"- {d.note}")
        if d.baseline_issue:
            lines.append(f"- **the baseline is not steady**: {d.baseline_issue}")
        if d.baseline_recommendation:
            lines.append(f"- baseline shaper: {_shaper_text(d.baseline_recommendation)}")
        for a in d.alerts:
            lines.append(f"- **alert** from {a.first_out} ({_when(a.start_s)} UTC), confirmed at {a.raised_at};"
                         f" {a.recordings_out} recordings out: {a.why}")
            lines.append(f"  - new mode {plus_minus(a.frequency_hz, a.frequency_std_hz, unit='Hz')}, zeta {a.zeta:.3g}"
                         f" ({100 * a.shift:+.1f} %, zeta {a.damping_change:+.3g})")
            if a.baseline_shaper:
                b = a.baseline_shaper
                band = (f"working band {b['band_hz'][0]:.4g}-{b['band_hz'][1]:.4g} Hz" if b["band_hz"]
                        else "no working band")
                lines.append(f"  - the baseline's {b['family']} leaves V = {100 * b['v_at_new_mode']:.3g} % at the new"
                             f" mode ({'inside' if b['inside_band'] else 'outside'} its {band})")
            lines.append(f"  - retune: {_shaper_text(a.retune)}")
    failed = [r for r in run.results if r.error]
    if failed:
        lines += ["", "## Recordings that could not be analysed", ""]
        lines += [f"- {r.path} ({r.robot}): {r.error}" for r in failed]
    if plot:
        lines += ["", f"![modes over time]({plot})"]
    return "\n".join(lines) + "\n"


def write_csv(path: pathlib.Path, drift: Sequence[RobotDrift]) -> None:
    """``recordings.csv``: one row per recording and mode (a recording without mode: one row, empty)."""
    head = ["robot", "path", "start_utc", "start_s", "cycles", "mode", "frequency_hz", "frequency_std_hz", "zeta",
            "zeta_std", "recommended", "in_baseline", "shift", "shift_sigmas", "damping_change", "out", "error"]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        for d in drift:
            for p in d.points:
                r = p.result
                rec = r.recommendation["family"] if r.recommendation else ""
                common = [d.robot, r.path, _when(r.start_s), _f(r.start_s, ".3f")]
                cmp = [int(p.in_baseline), _f(p.shift, ".4f"), _f(p.shift_sigmas, ".2f"), _f(p.damping_change, ".4f"),
                       int(p.out), r.error]
                if not r.modes:
                    w.writerow([*common, r.cycles, "", "", "", "", "", rec, *cmp])
                for k, m in enumerate(r.modes):
                    w.writerow([*common, r.cycles, k + 1, _f(m["frequency_hz"], ".6g"),
                                _f(m["frequency_std_hz"], ".3g"), _f(m["zeta"], ".4g"), _f(m["zeta_std"], ".3g"), rec,
                                *cmp])


def write_alerts_csv(path: pathlib.Path, drift: Sequence[RobotDrift]) -> None:
    """``alerts.csv``: one row per alert."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["robot", "first_out", "start_utc", "recordings_out", "baseline_hz", "frequency_hz",
                    "frequency_std_hz", "shift", "baseline_zeta", "zeta", "retune_family", "retune_duration_s",
                    "baseline_shaper_v_at_new_mode", "why"])
        for d in drift:
            for a in d.alerts:
                w.writerow([a.robot, a.first_out, _when(a.start_s), a.recordings_out, _f(d.baseline_hz, ".6g"),
                            _f(a.frequency_hz, ".6g"), _f(a.frequency_std_hz, ".3g"), _f(a.shift, ".4f"),
                            _f(d.baseline_zeta, ".4g"), _f(a.zeta, ".4g"), a.retune["family"] if a.retune else "",
                            _f(a.retune["duration_s"], ".4g") if a.retune else "",
                            _f(a.baseline_shaper["v_at_new_mode"], ".3g") if a.baseline_shaper else "", a.why])


def plot_modes(path: pathlib.Path, drift: Sequence[RobotDrift], rule: DriftRule) -> None:
    """``modes.png``: per robot the compared mode over time, baseline band, recordings out, alerts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = [d for d in drift if any(math.isfinite(p.frequency_hz) for p in d.points)] or list(drift)
    cols = 2 if len(robots) > 1 else 1
    rows = max(1, math.ceil(len(robots) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 2.4 * rows), squeeze=False, sharex=False)
    for ax, d in zip(axes.flat, robots, strict=False):
        pts = [p for p in d.points if math.isfinite(p.frequency_hz) and math.isfinite(p.result.start_s)]
        if not pts:
            ax.set_title(f"{d.robot}: no mode")
            continue
        t0 = min(p.result.start_s for p in pts)
        days = 86400.0 if max(p.result.start_s for p in pts) - t0 > 2 * 86400 else 3600.0
        unit = "days" if days == 86400.0 else "hours"
        x = [(p.result.start_s - t0) / days for p in pts]
        if math.isfinite(d.baseline_hz):
            lo, hi = d.baseline_hz * (1 - rule.max_frequency_shift), d.baseline_hz * (1 + rule.max_frequency_shift)
            ax.axhspan(lo, hi, color="tab:green", alpha=0.15, label=f"baseline +-{100 * rule.max_frequency_shift:g} %")
            ax.axhline(d.baseline_hz, color="tab:green", lw=0.8)
        kinds = (("baseline", lambda p: p.in_baseline and not p.out, dict(color="tab:green", marker="s")),
                 ("within", lambda p: not p.in_baseline and not p.out, dict(color="tab:blue", marker="o")),
                 ("out", lambda p: p.out, dict(color="tab:red", marker="x")))
        for kind, sel, style in kinds:
            chosen = [(xi, p) for xi, p in zip(x, pts, strict=True) if sel(p)]
            if chosen:
                ax.errorbar([c[0] for c in chosen], [c[1].frequency_hz for c in chosen],
                            yerr=[c[1].frequency_std_hz for c in chosen], ls="none", ms=4, label=kind, **style)
        for a in d.alerts:
            ax.axvline((a.start_s - t0) / days, color="tab:red", ls="--", lw=1)
        ax.set_title(f"{d.robot}: {d.verdict}", color="tab:red" if d.verdict == "ALERT" else "black", fontsize=9)
        ax.set_xlabel(f"recording start, {unit} from the first")
        ax.set_ylabel("mode, Hz")
        ax.legend(fontsize=6, loc="best")
    for ax in list(axes.flat)[len(robots):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_fleet_report(run: FleetRun, drift: Sequence[RobotDrift], rule: DriftRule, out: str | pathlib.Path
                       ) -> list[pathlib.Path]:
    """Write the report folder; returns the files written."""
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "recordings.csv", out / "alerts.csv", out / "fleet.json", out / "modes.png", out / "fleet.md"]
    write_csv(files[0], drift)
    write_alerts_csv(files[1], drift)
    files[2].write_text(json.dumps(fleet_doc(run, drift, rule), indent=1, allow_nan=False) + "\n")
    plot_modes(files[3], drift, rule)
    files[4].write_text(markdown(run, drift, rule, files[3].name))
    return files
