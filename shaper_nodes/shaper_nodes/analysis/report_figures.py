"""The figures of a bag analysis' report (split out of :mod:`.report`, which writes them and re-exports
these names): ``traces.png`` (one panel per group of cycles, at most :data:`MAX_TRACES_PER_PANEL` cycles
each), ``spectrum.png`` (the band around the identified modes, V(f) of the recommended and active shapers
below it), ``sensitivity.png`` and, when a learner replay made two or more updates, ``learning.png`` and
``learning_mrilc.png``; :func:`figures` gives the data each plots, for tests and reports.
"""

from __future__ import annotations

import math
import pathlib

import numpy as np

from shaper_nodes.core.shaping import Shaper, percentage_vibration

from .analyze import Analysis
from .text import value

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
                    f" {value(float(np.median(same)), '.3g')} m/s²)")
                shown.add(r.shaper)
            else:
                color = plt.get_cmap("viridis")(0.85 * k / max(len(rows) - 1, 1))
                label = (f"#{i}" + ("" if r.shaper in ("", "unknown") else f" {r.shaper}")
                         + f" (RMS {value(r.rms, '.3g')} m/s²)")
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
                designed = g.recommendation.modes or tuple(g.modes)  # the modes it shapes (those that ring)
                out.append((f"recommended for {', '.join(f'{m.hz:.3g}' for m in designed)} Hz: {b.family}", b.shaper,
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
    marked = [e for e in sorted(modes, key=lambda e: e[0].omega) if lo <= e[0].hz <= hi]
    for m, where, color in marked:  # labelled in the legend, in frequency order: labels on the plot overlap
        for k, a in enumerate(axes[:, 0]):
            a.axvline(m.hz, color=color, ls="--", lw=0.9,
                      label=(f"{where}{m.hz:.4g} Hz, ζ {m.zeta:.2g}"
                             + (" (not used: " + an.ringing_issue(m).split(":")[0] + ")" if an.ringing_issue(m)
                                else "")) if k == 0 else None)
    if marked:
        ax.legend(fontsize=6, loc="lower left", title="identified modes", title_fontsize=6, framealpha=0.8)
    else:  # a well-shaped recording: no legend to draw (matplotlib warned "No artists with labels")
        ax.text(0.01, 0.03, "no mode identified in this band", transform=ax.transAxes, fontsize=7, color="0.3")
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
