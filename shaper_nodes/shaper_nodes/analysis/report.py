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
from shaper_nodes.core.shaping import Shaper, percentage_vibration
from shaper_nodes.recordings import describe_damage

from .analyze import Analysis, shaper_of
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


#: most cycles overlaid in one traces panel (evenly spread over the group when it has more)
MAX_TRACES_PER_PANEL = 8
#: the spectrum's band around the identified modes: from this fraction of the lowest ...
SPECTRUM_LOW = 0.2
#: ... to this multiple of the highest
SPECTRUM_HIGH = 5.0


def learning_curves(an: Analysis) -> tuple[dict[str, list[dict]], dict[str, list[dict]], list[str]]:
    """The LIST and MRILC learning curves worth a plot (two or more updates), and why others are not plotted."""
    curves: dict[str, list[dict]] = {}
    mrilc: dict[str, list[dict]] = {}
    why: list[str] = []
    if not an.replays:
        why.append("no learner replay was asked for (--learners '')")
    for name, rep in an.replays.items():
        rows = [r for r in rep.rows if "skipped" not in r]
        if len(rows) < 2:
            skipped = [r["skipped"] for r in rep.rows if "skipped" in r]
            because = (f"{len(skipped)} cycle(s) not learned from: {skipped[0]}" if skipped else
                       "; ".join(rep.notes))
            why.append(f"the {name.upper()} replay made {len(rows)} update(s): a learning curve needs two or more"
                       + (f" ({because})" if because else ""))
        elif "rms_e" in rows[0]:
            mrilc[name] = rows
        elif "M" in rows[0]:
            curves[name] = rows
    return curves, mrilc, why


def figures(an: Analysis) -> dict[str, object]:
    """The report's figures, file name -> matplotlib Figure (not saved; the caller closes them)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: dict[str, object] = {"traces.png": _plot_traces(plt, an)}
    if an.spectrum is not None:
        figs["spectrum.png"] = _plot_spectrum(plt, an, an.spectrum)
    rcm = an.recommendation
    if an.modes and rcm is not None and rcm.best is not None:
        figs["sensitivity.png"] = _plot_sensitivity(plt, an, rcm.best.shaper, rcm.target)
    curves, mrilc, _why = learning_curves(an)
    if mrilc:
        figs["learning_mrilc.png"] = _plot_mrilc_learning(plt, mrilc)
    if curves:
        figs["learning.png"] = _plot_list_learning(plt, curves)
    return figs


def _plots(an: Analysis, out: pathlib.Path) -> list[pathlib.Path]:
    return [_save(fig, out / name) for name, fig in figures(an).items()]


def _trace_panels(an: Analysis) -> list[tuple[str, list[int]]]:
    """(title, rows of the cycles drawn) per traces panel: one per group of cycles, at most
    :data:`MAX_TRACES_PER_PANEL` cycles each, evenly spread."""
    groups = [(f"{g.label}", list(g.rows)) for g in an.groups] or [("all cycles", list(range(len(an.cycles))))]
    grouped = {i for _, rows in groups for i in rows}
    rest = [i for i in range(len(an.cycles)) if i not in grouped]
    if rest:
        groups.append(("cycles with no mode identified", rest))
    panels = []
    for title, rows in groups:
        drawn = rows if len(rows) <= MAX_TRACES_PER_PANEL else [
            rows[int(round(k))] for k in np.linspace(0, len(rows) - 1, MAX_TRACES_PER_PANEL)]
        shown = (f"{len(rows)} cycles" if len(drawn) == len(rows) else
                 f"{len(drawn)} of {len(rows)} cycles (evenly spread)")
        panels.append((f"{title}: {shown}", drawn))
    return panels


def trace_scale(an: Analysis) -> float:
    """The traces' linear threshold, m/s^2: the y axis is symmetric-log, linear within +- this (3 x the
    accelerometer noise measured per axis, so a trace at the noise floor shows as noise, not a flat line),
    logarithmic beyond it, so cycles 1000 times apart in amplitude are readable on one scale."""
    noise = an.accel_noise if math.isfinite(an.accel_noise) and an.accel_noise > 0 else 0.0
    if noise == 0.0:
        peaks = [r.peak for r in an.cycles if math.isfinite(r.peak) and r.peak > 0]
        noise = 1e-3 * max(peaks) if peaks else 1.0
    return 3.0 * noise


def _plot_traces(plt, an: Analysis):
    """traces.png: one panel per group of cycles (plant, payload or pose), the acceleration (m/s^2) on its
    most varying axis from each cycle's start, at most :data:`MAX_TRACES_PER_PANEL` cycles overlaid; coloured
    by shaper when the panel's cycles ran several (unshaped against shaped at a glance), else by cycle
    (light to dark from early to late); each residual window's start dotted. Every panel has the same
    y axis, symmetric-log (:func:`trace_scale`), and each cycle's legend entry gives its residual RMS, so a
    shaped cycle 1000 times quieter is seen as such, not as a flat line on another scale."""
    axis = int(np.argmax(np.nanvar(an.recording.accel.values, axis=0)))
    panels = _trace_panels(an)
    linear = trace_scale(an)
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.2 + 2.4 * len(panels)), squeeze=False, sharex=True,
                             sharey=True)
    for ax, (title, rows) in zip(axes[:, 0], panels, strict=True):
        shapers = list(dict.fromkeys(an.cycles[i].shaper for i in rows))
        by_shaper = len(shapers) > 1
        shown: set[str] = set()
        for k, i in enumerate(rows):
            t, a = an.traces[i]
            r = an.cycles[i]
            if not t.size:
                continue
            if by_shaper:
                color = plt.get_cmap("tab10")(shapers.index(r.shaper) % 10)
                same = [an.cycles[j].rms for j in rows if an.cycles[j].shaper == r.shaper]
                label = None if r.shaper in shown else (
                    f"{r.shaper} ({len(same)} cycle{'s' if len(same) > 1 else ''}, residual RMS"
                    f" {_f(float(np.median(same)), '.3g')} m/s²)")
                shown.add(r.shaper)
            else:
                color = plt.get_cmap("viridis")(0.85 * k / max(len(rows) - 1, 1))
                label = (f"#{i}" + ("" if r.shaper in ("", "unknown") else f" {r.shaper}")
                         + f" (RMS {_f(r.rms, '.3g')} m/s²)")
            mean = np.nanmean(a[:, axis]) if an.removed_mean else 0.0
            ax.plot(t, a[:, axis] - mean, lw=0.7, color=color, label=label)
            ax.axvline(r.window_start - r.start, color=color, lw=0.6, ls=":")
        ax.set_yscale("symlog", linthresh=linear)
        ax.axhspan(-linear, linear, color="0.85", alpha=0.5, lw=0)
        ax.set_title(title, fontsize=9, loc="left")
        ax.set_ylabel(f"a{'xyz'[axis] if axis < 3 else axis}{' - mean' if an.removed_mean else ''} (m/s²)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, loc="upper right", ncol=2 if len(rows) > 4 and not by_shaper else 1, framealpha=0.7)
    axes[-1, 0].set_xlabel(f"time from cycle start (s); dotted: start of the residual window\ny: symmetric log,"
                           f" linear within ±{linear:.2g} m/s² (shaded: 3 x the accelerometer noise)", fontsize=8)
    return fig


def spectrum_band(an: Analysis, spectrum: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
    """The spectrum plot's frequency range, Hz: ``--band-hz`` if given, else from :data:`SPECTRUM_LOW` x the
    lowest to :data:`SPECTRUM_HIGH` x the highest identified mode (of every group), within the computed
    spectrum; the whole spectrum (above 0 Hz) when no mode was identified."""
    f = spectrum[0]
    fmin, fmax = float(f[1]) if f.size > 1 else 0.1, float(f[-1])
    modes = [m.hz for g in an.groups for m in g.modes] or [m.hz for m in an.modes]
    if an.options.band_hz is not None:
        lo, hi = an.options.band_hz
    elif modes:
        lo, hi = SPECTRUM_LOW * min(modes), SPECTRUM_HIGH * max(modes)
    else:
        lo, hi = fmin, fmax
    lo, hi = max(lo, fmin), min(hi, fmax)
    return (lo, hi) if hi > lo else (fmin, fmax)


def _shapers_to_draw(an: Analysis) -> list[tuple[str, Shaper | tuple[np.ndarray, np.ndarray], str]]:
    """(label, shaper or (amplitudes, times), line style) of the recommended shaper(s) and the recorded ones."""
    out: list[tuple[str, Shaper | tuple[np.ndarray, np.ndarray], str]] = []
    if len(an.groups) > 1:
        for g in an.groups:
            if g.recommendation is not None and g.recommendation.best is not None:
                b = g.recommendation.best
                out.append((f"recommended for {', '.join(f'{m.hz:.3g}' for m in g.modes)} Hz: {b.family}", b.shaper,
                            "-"))
    elif an.recommendation is not None and an.recommendation.best is not None:
        out.append((f"recommended: {an.recommendation.best.family}", an.recommendation.best.shaper, "-"))
    seen = set()
    for r in an.cycles:
        if r.shaper_impulses is not None and r.shaper not in seen and len(r.shaper_impulses[0]) > 1:
            seen.add(r.shaper)
            out.append((f"active (recorded): {r.shaper}", (np.asarray(r.shaper_impulses[0], dtype=float),
                                                          np.asarray(r.shaper_impulses[1], dtype=float)), "--"))
    return out


def _group_color(k: int) -> str:
    return ("C1", "C2", "C4", "C5", "C6")[k % 5]


def _plot_spectrum(plt, an: Analysis, spectrum: tuple[np.ndarray, np.ndarray]):
    """spectrum.png: the residual windows' PSD ((m/s^2)^2/Hz) on a log frequency axis (Hz) over
    :func:`spectrum_band`, the identified modes marked and labelled; below it, on the same axis, the
    percentage vibration V (%) of the recommended and the active shapers with the tolerance marked."""
    f, p = spectrum
    lo, hi = spectrum_band(an, spectrum)
    shapers = _shapers_to_draw(an) if an.modes else []
    rows = 2 if shapers else 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 3.2 + 2.4 * (rows - 1)), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [3, 2][:rows]})
    ax = axes[0, 0]
    inside = (f >= lo) & (f <= hi) & (f > 0)
    ax.loglog(f[inside], p[inside], lw=0.9, color="C0")
    ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    # mode lines: one colour per group, the same as its recommended shaper's V(f) below
    modes = ([(m, "", "C3") for m in an.modes] if len(an.groups) < 2 else
             [(m, f"group {k + 1}: ", _group_color(k)) for k, g in enumerate(an.groups) for m in g.modes])
    for m, where, color in sorted(modes, key=lambda e: e[0].omega):
        if lo <= m.hz <= hi:  # labelled in the legend, in frequency order: labels on the plot overlap
            for k, a in enumerate(axes[:, 0]):
                a.axvline(m.hz, color=color, ls="--", lw=0.9,
                          label=(f"{where}{m.hz:.4g} Hz, ζ {m.zeta:.2g}"
                                 + (" (not used: " + an.ringing_issue(m).split(":")[0] + ")" if an.ringing_issue(m)
                                    else "")) if k == 0 else None)
    ax.legend(fontsize=6, loc="lower left", title="identified modes", title_fontsize=6, framealpha=0.8)
    ax.set_ylabel("PSD ((m/s²)²/Hz)")
    ax.set_title(f"residual vibration spectrum (Welch, averaged over cycles), {lo:.3g}-{hi:.3g} Hz", fontsize=9,
                 loc="left")
    ax.grid(alpha=0.3)
    ax.grid(alpha=0.12, which="minor", axis="x")
    if shapers:
        # at the damping of the first mode that rings: at a fit that does not (the arm demo's 55.9 Hz, zeta 0.6,
        # listed first) every curve stayed above 40 %, the recommended ZV's too (session 11)
        zeta = ([m for m in an.modes if not an.ringing_issue(m)] or an.modes)[0].zeta
        hz = np.geomspace(lo, hi, 600)
        va = axes[1, 0]
        for k, (label, sh, ls) in enumerate(shapers):
            amps, times = (sh.amplitudes, sh.times) if isinstance(sh, Shaper) else sh
            color = (_group_color(k) if len(an.groups) > 1 else "C0") if ls == "-" else f"C{7 + k % 3}"
            va.plot(hz, 100 * percentage_vibration(amps, times, 2 * np.pi * hz, zeta), ls=ls,
                    lw=1.4 if ls == "-" else 1.1, color=color, label=label)
        target = an.recommendation.target if an.recommendation is not None else an.options.target
        va.axhline(100 * target, color="0.3", lw=0.8, ls=":")
        va.annotate(f"tolerance {100 * target:g} %", (1.0, 100 * target), xycoords=("axes fraction", "data"),
                    xytext=(-3, 2), textcoords="offset points", fontsize=7, ha="right", va="bottom", color="0.3")
        va.set_ylabel(f"V (%) at ζ {zeta:.2g}")
        va.set_ylim(0, 110)
        va.grid(alpha=0.3, which="both")
        va.legend(fontsize=7, loc="upper left")
    axes[-1, 0].set_xlabel("frequency (Hz, log)")
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    xaxis = axes[-1, 0].xaxis
    xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    xaxis.set_minor_formatter(NullFormatter())
    return fig


def _plot_sensitivity(plt, an: Analysis, best: Shaper, target: float):
    """sensitivity.png: V (%) against frequency (Hz) of the recommended shaper ``best`` and of the recorded
    ones, at the first ringing mode's damping, up to 1.3 x the highest mode; every identified mode of
    the recommendation's group marked (a line, and its ±sigmas band shaded; dotted if it does not ring),
    and the ``target`` V (fraction) marked."""
    ringing = [m for m in an.modes if not an.ringing_issue(m)]
    top = min(ringing or an.modes, key=lambda m: m.omega)
    hz = np.linspace(0.01, 1.3 * max(m.hz for m in an.modes), 800)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.plot(hz, 100 * percentage_vibration(best.amplitudes, best.times, 2 * np.pi * hz, top.zeta),
            lw=1.5, label=f"recommended: {best.family}")
    seen = set()
    for r in an.cycles:
        if r.shaper_impulses is not None and r.shaper not in seen and len(r.shaper_impulses[0]) > 1:
            seen.add(r.shaper)
            ax.plot(hz, 100 * percentage_vibration(np.asarray(r.shaper_impulses[0], dtype=float),
                                                   np.asarray(r.shaper_impulses[1], dtype=float), 2 * np.pi * hz,
                                                   top.zeta), lw=0.8, ls="--", label=f"recorded: {r.shaper}")
    for k, m in enumerate(sorted(an.modes, key=lambda m: m.omega)):
        s = an.options.sigmas * m.omega_std / (2 * math.pi)
        rings = not an.ringing_issue(m)
        ax.axvspan(m.hz - s, m.hz + s, color="C3", alpha=0.15 if rings else 0.06,
                   label=f"mode ±{an.options.sigmas:g}\N{GREEK SMALL LETTER SIGMA}" if k == 0 else None)
        ax.axvline(m.hz, color="C3", lw=0.9, ls="-" if rings else ":",
                   label=f"mode {m.hz:.4g} Hz, ζ {m.zeta:.2g}" + ("" if rings else " (does not ring)"))
    ax.axhline(100 * target, color="0.5", lw=0.6, ls=":", label=f"target {100 * target:g} %")
    ax.set_xlim(0, hz[-1])
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("V (%)")
    ax.set_title(f"percentage vibration of the shapers at damping {top.zeta:.3g} (the {top.hz:.4g} Hz mode's)",
                 fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, loc="upper right", framealpha=0.8)
    return fig


def _plot_mrilc_learning(plt, mrilc: dict[str, list[dict]]):
    """learning_mrilc.png: RMS(e) (joint units), RMS(u1) and RMS(u2) (effort units) per iteration."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for name, rows in mrilc.items():
        if not rows:
            continue
        it = [r["iteration"] for r in rows]
        axes[0].semilogy(it, [r["rms_e"] for r in rows], "o-", ms=3, label=f"{name} RMS(e)")
        axes[1].plot(it, [r["rms_u1"] for r in rows], "o-", ms=3, label=f"{name} RMS(u1)")
        axes[1].plot(it, [r["rms_u2"] for r in rows], "s-", ms=3, label=f"{name} RMS(u2)")
    for ax, title in zip(axes, ("RMS(e) (joint units)", "efforts"), strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("iteration")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    return fig


def _plot_list_learning(plt, curves: dict[str, list[dict]]):
    """learning.png: LIST's M (m/s^2), next A1 and next T2 (s) per cycle."""
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
    for name, rows in curves.items():
        if not rows:
            continue
        c = [r["cycle"] for r in rows]
        axes[0].semilogy(c, [r["M"] for r in rows], "o-", ms=3, label=name)
        axes[1].plot(c, [r["a1_next"] for r in rows], "o-", ms=3, label=name)
        axes[2].plot(c, [r["t2_next"] for r in rows], "o-", ms=3, label=name)
    for ax, title in zip(axes, ("M (m/s²)", "A1 next", "T2 next (s)"), strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("cycle")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return fig


def _save(fig, path: pathlib.Path) -> pathlib.Path:
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
