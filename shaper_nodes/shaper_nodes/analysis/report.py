"""Output of an analysis: a terminal table, a JSON document, and a report folder.

The folder holds ``report.md`` (everything, with the plots), ``cycles.csv`` (one row per cycle),
``modes.csv``, ``candidates.csv`` (every shaper family designed on the modes), one CSV per
learner replay, ``summary.json`` (what ``--json`` prints) and the plots: ``traces.png``
(one panel per group of cycles, i.e. per plant, payload or pose, at most
:data:`MAX_TRACES_PER_PANEL` cycles overlaid in each, from each cycle's start, the residual
windows marked), ``spectrum.png`` (log frequency axis over the band around the identified modes,
which are marked, and below it V(f) of the recommended and the active shapers with the
tolerance), ``sensitivity.png`` (V against frequency of the recommended and the recorded shapers
near the first mode, its band shaded), and, only when a learner replay made two or more updates,
``learning.png`` (LIST's M and parameters per cycle) and ``learning_mrilc.png`` (MRILC's RMS(e),
RMS(u1) and RMS(u2) per iteration); report.md says why there is no learning plot otherwise.
"""

from __future__ import annotations

import csv
import json
import math
import pathlib
from typing import Any

import numpy as np

from shaper_nodes.core.identification import NO_SHAPER_NEEDED
from shaper_nodes.recordings import describe_damage

from .analyze import Analysis, shaper_of
from .report_figures import (  # noqa: F401 (re-exported: the figures and their data)
    MAX_TRACES_PER_PANEL,
    SPECTRUM_HIGH,
    SPECTRUM_LOW,
    _plots,
    figures,
    learning_curves,
    spectrum_band,
    trace_scale,
)
from .text import plus_minus


def _f(x: float, spec: str = ".4g") -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def json_ready(v: Any) -> Any:
    """``v`` with non-finite floats as None and numpy scalars as Python numbers, nested (for JSON)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: json_ready(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_ready(x) for x in v]
    if isinstance(v, np.generic):
        return json_ready(v.item())
    return v


def summary(an: Analysis) -> dict:
    """Everything the analysis found, as plain data (what ``--json`` prints)."""
    rec = an.recording
    rcm = an.recommendation
    doc = {
        "bag": rec.path, "reader": rec.reader, "messages_read": rec.messages_read, "topics": rec.topics,
        "segmentation": an.segmentation, "remove_mean": an.removed_mean,
        "damage": [{"file": d.path, "size_bytes": d.size, "readable_bytes": d.readable, "lost_bytes": d.lost_bytes,
                    "reason": d.reason, "lost_time_s": [t * 1e-9 for t in d.lost_time] if d.lost_time else None,
                    "skipped_chunks": d.skipped_chunks, "text": describe_damage(d)} for d in rec.damage],
        "time_origin_s": an.origin,
        "cycles": [{"cycle": r.cycle, "start_s": r.start - an.origin, "motion_end_s": r.motion_end - an.origin,
                    "window_start_s": r.window_start - an.origin, "end_s": r.end - an.origin, "residual_rms": r.rms,
                    "residual_peak": r.peak, "samples": r.samples,
                    "settling_time_s": r.settling_time, "shaper": r.shaper, "v_active": r.v_active,
                    "complete": r.complete, "issue": r.issue} for r in an.cycles],
        "modes": [{"frequency_hz": m.hz, "omega": m.omega, "zeta": m.zeta,
                   "frequency_std_hz": m.omega_std / (2 * math.pi), "zeta_std": m.zeta_std, "amplitude": m.amplitude,
                   "method": m.method, "not_used": an.ringing_issue(m)} for m in an.modes],
        "spectrum_peak_hz": (float(an.spectrum[0][int(np.argmax(an.spectrum[1][1:])) + 1])
                             if an.spectrum is not None and an.spectrum[0].size > 1 else None),
        "recommendation": None,
        "candidates": [],
        "predicted": an.predicted,
        "replays": {name: {"rows": r.rows, "notes": r.notes} for name, r in an.replays.items()},
        "notes": an.notes,
        "headline": an.headline,
    }
    if rcm is not None:
        doc["candidates"] = [{"family": c.family, "duration_s": c.duration, "v_nominal": c.nominal_vibration,
                              "v_worst": c.worst_vibration, "meets_target": c.meets_target} for c in rcm.candidates]
        if rcm.best is not None:
            doc["recommendation"] = {**shaper_of(rcm.best.shaper), "v_nominal": rcm.best.nominal_vibration,
                                     "v_worst": rcm.best.worst_vibration, "target": rcm.target}
        doc["rule"] = rcm.rule
    doc["no_shaper_needed"] = _no_shaper_needed(rcm)
    doc["max_damping"] = an.options.max_damping
    doc["noise_sigmas"] = an.options.noise_sigmas
    doc["groups"] = [_group(an, g) for g in an.groups]
    doc["settle_tolerance"] = an.settle_tolerance
    doc["accel_noise_m_s2"] = an.accel_noise
    return json_ready(doc)


def _group(an: Analysis, g) -> dict:
    """One group of cycles that see the same modes, as plain data."""
    best = g.recommendation.best if g.recommendation is not None else None
    modes = [{"frequency_hz": m.hz, "frequency_std_hz": m.omega_std / (2 * math.pi), "zeta": m.zeta,
              "zeta_std": m.zeta_std, "amplitude": m.amplitude, "not_used": an.ringing_issue(m)} for m in g.modes]
    return {"rows": g.rows, "cycles": g.cycles, "modes": modes, "no_shaper_needed": _no_shaper_needed(g.recommendation),
            "recommendation": None if best is None else {**shaper_of(best.shaper), "v_nominal": best.nominal_vibration,
                                                         "v_worst": best.worst_vibration},
            "rule": g.recommendation.rule if g.recommendation is not None else ""}


def _aside(an: Analysis, m) -> str:
    """' (does not ring ...)' or ' (at the noise floor ...)' for a mode not used for the shaper, else ''."""
    why = an.ringing_issue(m)
    return f" ({why}; not used for the shaper)" if why else ""


def _no_shaper_needed(rcm) -> bool:
    """The recommendation found no mode that rings."""
    return rcm is not None and rcm.best is None and not rcm.modes and bool(rcm.not_ringing)


def _settle(r) -> str:
    """Settling time, or '>' the window when the vibration is still outside the band at its end."""
    if math.isfinite(r.settling_time):
        return f"{r.settling_time:.3f}"
    return f">{r.end - r.window_start:.2f}" if r.samples else "n/a"


def table(an: Analysis) -> str:
    """The terminal table: cycles, modes, recommendation, replays, notes."""
    lines = [f"{an.recording.path}: {an.recording.messages_read} messages read ({an.recording.reader});"
             f" cycles from {an.segmentation}"]
    lines += an.headline
    for d in an.recording.damage:
        lines.append(f"WARNING: {describe_damage(d)}")
    lines.append(f"{'#':>4} {'cycle':>5} {'RMS m/s2':>10} {'peak m/s2':>10} {'settle s':>9} {'window s':>17}  shaper")
    for i, r in enumerate(an.cycles):
        lines.append(f"{i:>4} {r.cycle:>5} {_f(r.rms):>10} {_f(r.peak):>10} {_settle(r):>9}"
                     f" {_f(r.window_start - an.origin, '.3f'):>8}-{_f(r.end - an.origin, '.3f'):<8}  {r.shaper}"
                     + ("" if r.complete else "  (ends with the recording)") + (f"  [{r.issue}]" if r.issue else ""))
    if an.modes:
        lines.append("modes: " + "; ".join(f"{plus_minus(m.hz, m.omega_std / (2 * math.pi), unit='Hz')},"
                                          f" damping {plus_minus(m.zeta, m.zeta_std, '.3g')}{_aside(an, m)}"
                                          for m in an.modes))
    rcm = an.recommendation
    if rcm is not None and rcm.best is not None:
        p = an.predicted
        lines.append(f"recommended: {rcm.best.family} ({1e3 * rcm.best.duration:.1f} ms),"
                     f" V {100 * rcm.best.nominal_vibration:.2g} % at the mode,"
                     f" {100 * rcm.best.worst_vibration:.2g} % worst case;"
                     f" predicted residual {_f(p.get('rms_nominal', float('nan')))} m/s2"
                     f" (worst {_f(p.get('rms_worst', float('nan')))}) + noise, from an unshaped level of"
                     f" {_f(an.unshaped_level)} m/s2")
    if rcm is not None and rcm.rule:
        lines.append(rcm.rule)
    if len(an.groups) > 1:
        for g in an.groups:
            best = g.recommendation.best if g.recommendation is not None else None
            lines.append(f"group {g.label}: "
                         + "; ".join(f"{plus_minus(m.hz, m.omega_std / (2 * math.pi), unit='Hz')},"
                                     f" damping {m.zeta:.3g}{_aside(an, m)}" for m in g.modes)
                         + (f"; recommended {best.family} ({1e3 * best.duration:.1f} ms)" if best else
                            f"; {NO_SHAPER_NEEDED}" if _no_shaper_needed(g.recommendation) else ""))
    for name, rep in an.replays.items():
        learned = [r for r in rep.rows if "skipped" not in r]
        if learned and "rms_e" in learned[0]:
            last = learned[-1]
            lines.append(f"{name} replay: {len(learned)} update(s); RMS(e) {_f(learned[0]['rms_e'])} at iteration"
                         f" {learned[0]['iteration']} -> {_f(last['rms_e'])} at {last['iteration']}; RMS(u2)"
                         f" {_f(last['rms_u2'])}, residual {_f(last['residual'])}; {last['action']}")
        elif learned:
            last = learned[-1]
            lines.append(f"{name} replay: {len(learned)} update(s); M {_f(learned[0]['M'])} -> {_f(last['M'])};"
                         f" next A1 {last['a1_next']:.4f}, T2 {last['t2_next']:.4f} s")
        else:
            lines.append(f"{name} replay: no update ({'; '.join(rep.notes) or 'no cycle learned from'})")
    for note in an.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)


def write_report(an: Analysis, out: pathlib.Path) -> list[pathlib.Path]:
    """Write the report folder; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    doc = summary(an)
    files = []

    def csv_file(name: str, header: list[str], rows: list[list]) -> None:
        path = out / name
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            w.writerows(rows)
        files.append(path)

    csv_file("cycles.csv", ["cycle", "start_s", "motion_end_s", "window_start_s", "end_s", "residual_rms_m_s2",
                            "residual_peak_m_s2", "samples", "settling_time_s", "shaper", "v_active"],
             [[r.cycle, f"{r.start - an.origin:.9g}", f"{r.motion_end - an.origin:.9g}",
               f"{r.window_start - an.origin:.9g}", f"{r.end - an.origin:.9g}",
               f"{r.rms:.6g}", f"{r.peak:.6g}", r.samples, f"{r.settling_time:.6g}", r.shaper, f"{r.v_active:.4g}"]
              for r in an.cycles])
    csv_file("modes.csv", ["frequency_hz", "frequency_std_hz", "damping_ratio", "damping_std", "amplitude"],
             [[f"{m.hz:.6g}", f"{m.omega_std / (2 * math.pi):.3g}", f"{m.zeta:.5g}", f"{m.zeta_std:.3g}",
               f"{m.amplitude:.4g}"] for m in an.modes])
    if an.recommendation is not None:
        csv_file("candidates.csv", ["family", "duration_s", "v_nominal", "v_worst", "meets_target"],
                 [[c.family, f"{c.duration:.6g}", f"{c.nominal_vibration:.4g}", f"{c.worst_vibration:.4g}",
                   c.meets_target] for c in an.recommendation.candidates])
    for name, rep in an.replays.items():
        keys = sorted({k for r in rep.rows for k in r}, key=lambda k: (k != "cycle", k))
        csv_file(f"replay_{name}.csv", keys, [[r.get(k, "") for k in keys] for r in rep.rows])
    (out / "summary.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    files.append(out / "summary.json")
    plots = _plots(an, out)
    files += plots
    (out / "report.md").write_text(_markdown(an, doc, [p.name for p in plots]))
    files.append(out / "report.md")
    return files


def _markdown(an: Analysis, doc: dict, plots: list[str]) -> str:
    rec = an.recording
    md = [f"# Bag analysis: `{rec.path}`", "",
          f"{rec.messages_read} messages read with {rec.reader}; cycles from {an.segmentation};"
          f" accelerometer `{rec.topics['accel']}`" + (", window mean removed" if an.removed_mean else "")
          + f"; times in s from {an.origin:.0f} s on the recording's clock.", ""]
    for h in an.headline:
        md += [f"> **{h}**", ""]
    for d in doc["damage"]:
        md += [f"> **Damaged recording:** {d['text']}", ""]
    md += ["## Cycles", "", "Residual vibration: RMS and peak of the tip acceleration magnitude (m/s²) from the"
           " time the positions have come to rest after the move until the cycle's end; settling: time after"
           f" that until the magnitude stays within {an.options.band} (of the cycle's peak, or m/s²).", "",
           "| # | cycle | RMS (m/s²) | peak (m/s²) | settling (s) | window (s) | shaper |",
           "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(an.cycles):
        md.append(f"| {i} | {r.cycle} | {_f(r.rms)} | {_f(r.peak)} | {_settle(r)} |"
                  f" {r.window_start - an.origin:.3f}-{r.end - an.origin:.3f} | {r.shaper}"
                  + (f" ({r.issue})" if r.issue else "") + " |")
    md += ["", "## Modes and the recommended shaper", ""]
    md += _modes_markdown(an, doc)
    md += _groups_markdown(doc["groups"])
    if doc["recommendation"]:
        r, p = doc["recommendation"], an.predicted
        md += [f"Recommended: **{r['family']}**, {1e3 * r['duration']:.1f} ms, impulses "
               + ", ".join(f"{a:.4f} at {1e3 * t:.2f} ms" for a, t in zip(r["amplitudes"], r["times"], strict=True))
               + f"; V {100 * r['v_nominal']:.3g} % at the mode, {100 * r['v_worst']:.3g} % worst case over ±"
               f"{an.options.sigmas:g} \N{GREEK SMALL LETTER SIGMA}. Predicted residual vibration"
               f" {_f(p.get('rms_nominal', float('nan')))} m/s²"
               f" (worst {_f(p.get('rms_worst', float('nan')))}) plus the sensor noise, from an unshaped level of"
               f" {_f(an.unshaped_level)} m/s² (median over {p.get('cycles_used', 0)} cycles of RMS / V of the"
               " active shaper).", "", f"The {doc['rule']}.", "",
               "| family | duration (ms) | V at mode (%) | worst V (%) | meets target |",
               "|---|---|---|---|---|"]
        for c in doc["candidates"]:
            md.append(f"| {c['family']} | {1e3 * c['duration_s']:.1f} | {100 * c['v_nominal']:.3g} |"
                      f" {100 * c['v_worst']:.3g} | {'yes' if c['meets_target'] else 'no'} |")
        md.append("")
    for name, rep in an.replays.items():
        md += [f"## {name.upper()} replay", "", "; ".join(rep.notes), ""]
        learned = [r for r in rep.rows if "skipped" not in r]
        if learned and "rms_e" in learned[0]:
            md += ["Errors in the joints' units (e = y_m - y, y_m the reference model's response to the"
                   " applied reference); efforts in the effort's units.", "",
                   "| cycle | iteration | RMS(e) | RMS(u1) | RMS(u2) | residual | action |",
                   "|---|---|---|---|---|---|---|"]
            for row in rep.rows:
                md.append(f"| {row['cycle']} | skipped: {row['skipped']} | | | | | |" if "skipped" in row else
                          f"| {row['cycle']} | {row['iteration']} | {_f(row['rms_e'])} | {_f(row['rms_u1'])} |"
                          f" {_f(row['rms_u2'])} | {_f(row['residual'])} | {row['action']} |")
            md.append("")
            continue
        if learned:
            md += ["| cycle | M (m/s²) | phi (deg) | action | A1 used | T2 used (s) | A1 next | T2 next (s) |",
                   "|---|---|---|---|---|---|---|---|"]
        for row in rep.rows:
            if "skipped" in row:
                md.append(f"| {row['cycle']} | skipped: {row['skipped']} | | | | | | |" if learned else
                          f"- cycle {row['cycle']}: skipped: {row['skipped']}")
            else:
                md.append(f"| {row['cycle']} | {_f(row['M'])} | {math.degrees(row['phi']):.1f} | {row['action']} |"
                          f" {_f(row['a1_used'], '.5f')} | {_f(row['t2_used'], '.5f')} | {row['a1_next']:.5f} |"
                          f" {row['t2_next']:.5f} |")
        md.append("")
    if plots:
        md += ["## Plots", ""] + [f"![{p}]({p})" for p in plots] + [""] + _no_learning_plot(an)
    if an.notes:
        md += ["## Notes", ""] + [f"- {n}" for n in an.notes] + [""]
    return "\n".join(md)


def _modes_markdown(an: Analysis, doc: dict) -> list[str]:
    """The table of the modes, each said used for the shaper or not and why; "no shaper needed" when none rings."""
    md: list[str] = []
    if an.modes:
        md += ["| mode | frequency (Hz) | damping ratio | used for the shaper |", "|---|---|---|---|"]
        for i, m in enumerate(an.modes):
            md.append(f"| {i + 1} | {plus_minus(m.hz, m.omega_std / (2 * math.pi))} |"
                      f" {plus_minus(m.zeta, m.zeta_std)} |"
                      f" {'no: ' + an.ringing_issue(m) if an.ringing_issue(m) else 'yes'} |")
        md.append("")
        if doc["no_shaper_needed"]:
            md += [f"{NO_SHAPER_NEEDED[0].upper()}{NO_SHAPER_NEEDED[1:]}: no identified mode rings (damping ratio"
                   f" at most {an.options.max_damping:g} and initial amplitude above {an.options.noise_sigmas:g} x the"
                   " accelerometer noise).", ""]
    else:
        md += ["No mode identified.", ""]
    return md


def _no_learning_plot(an: Analysis) -> list[str]:
    """Why the report has no learning plot (nothing when it has one)."""
    curves, mrilc, why = learning_curves(an)
    if curves or mrilc:
        return []
    return ["No learning plot: " + "; ".join(why or ["no learner update"]) + ".", ""]


def _groups_markdown(groups: list[dict]) -> list[str]:
    """The per-group table when the cycles see different modes (nothing for one group)."""
    if len(groups) < 2:
        return []
    md = ["The cycles see different modes (several plants, payloads or poses); per group:", "",
          "| cycles | modes (Hz) | recommended |", "|---|---|---|"]
    for g in groups:
        r = g["recommendation"]
        shaper = (f"{r['family']} ({1e3 * r['duration']:.1f} ms)" if r else
                  "none needed (no mode rings)" if g["no_shaper_needed"] else "none")
        md.append(f"| {', '.join(f'#{r}' for r in g['rows'])} | "
                  + ", ".join(plus_minus(m["frequency_hz"], m["frequency_std_hz"]) for m in g["modes"])
                  + f" | {shaper} |")
    return [*md, ""]
