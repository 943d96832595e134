"""report.md and its figures for a calibration (see :mod:`.calibration`), and :func:`write_outputs`, which
writes them with report.json, scheduler.yaml and shaper.yaml.

Figures (PNG, matplotlib's Agg backend):

- ``modes_vs_pose.png``: each identified mode's natural frequency and damping ratio against each grid
  joint, one series of points (no joining lines: :func:`modes_figure`) per value of the other grid joints,
  with two-sigma error bars;
- ``spectra.png``: the spectrum of the first free decay at every pose, identified modes marked;
- ``residual.png``: the residual vibration predicted at every pose for the fixed (home) shaper
  and for the scheduled shaper, nominal and worst over the modes' two-sigma uncertainty, each compared
  with its like (:func:`residual_figure`).

Each ``*_figure`` function builds its figure and returns it (tests inspect the matplotlib objects);
:func:`figures` writes them.
"""

from __future__ import annotations

import json
import math
import pathlib
from typing import Any

import numpy as np

from shaper_nodes.core.files import write_atomic

from .calibration import Calibration, assemble, plan_from_setup, wiring_of
from .calibration_outputs import report_dict, scheduler_yaml, shaper_yaml
from .text import plus_minus_fixed

#: the residual figure's series: (report key, label); nominal and worst case side by side, like with like
RESIDUAL_SERIES = (("fixed", "fixed (home) shaper, nominal modes"),
                   ("scheduled", "scheduled, nominal modes"),
                   ("fixed_worst_2sigma", "fixed (home) shaper, worst over the modes' two sigma"),
                   ("scheduled_worst_2sigma", "scheduled, worst over the modes' two sigma"))


def modes_figure(cal: Calibration) -> Any:
    """modes_vs_pose.png: every identified mode's natural frequency (Hz) and damping ratio against each
    grid joint (rad), with two-sigma error bars, or None without a grid.

    Points, not lines: a pose's k-th mode by frequency is not the same physical mode at the next pose
    (modes cross as the pose changes), and a calibration measures frequencies and damping, not mode
    shapes, so nothing tells which point continues which; joining them drew lines through several
    physical modes. One series per value of the other grid joints (each named in the legend; with one
    grid joint a single series, "identified modes"), each in its own colour and marker."""
    import matplotlib.pyplot as plt

    c = cal.plan.config
    names = list(c.joint_names)
    grid = [r for r in cal.results if r.grid_index is not None and r.modes]
    if not grid or not c.grid_joints:
        return None
    markers = "osD^vP*X<>"
    fig, axes = plt.subplots(2, len(c.grid_joints), figsize=(5 * len(c.grid_joints), 6.5), squeeze=False)
    for a, joint in enumerate(c.grid_joints):
        j = names.index(joint)
        other = [b for b in range(len(c.grid_joints)) if b != a]

        def key(r: Any, other: list[int] = other) -> tuple[float, ...]:
            return tuple(round(float(r.positions[names.index(c.grid_joints[b])]), 6) for b in other)

        groups = sorted({key(r) for r in grid})
        offsets = np.linspace(-1, 1, len(groups)) * 0.006 * (max(r.positions[j] for r in grid)
                                                              - min(r.positions[j] for r in grid)) \
            if len(groups) > 1 else np.zeros(1)
        for g, (values, off) in enumerate(zip(groups, offsets, strict=True)):
            rows = [r for r in grid if key(r) == values]
            label = ", ".join(f"{c.grid_joints[b]} {v:+.2f} rad" for b, v in zip(other, values, strict=True)) \
                or "identified modes"
            xs = [r.positions[j] + off for r in rows for _ in r.modes]
            ms = [m for r in rows for m in r.modes]
            style = dict(fmt=markers[g % len(markers)], color=f"C{g % 10}", ms=4, capsize=2, lw=0.8, ls="none")
            axes[0, a].errorbar(xs, [m.hz for m in ms], [2 * m.omega_std / (2 * math.pi) for m in ms],
                                label=label, **style)
            axes[1, a].errorbar(xs, [m.zeta for m in ms], [2 * m.zeta_std for m in ms], label=label, **style)
        _label_mode_axes(axes[:, a], joint)
    fig.suptitle("Identified modes against the pose\n(one point per mode and pose; error bars: two sigma)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def spectra_figure(cal: Calibration) -> Any:
    """spectra.png: the first free decay's normalised spectrum at every pose, its modes marked; or None."""
    import matplotlib.pyplot as plt

    with_spec = [r for r in cal.results if r.spectrum is not None]
    if not with_spec:
        return None
    cols = min(4, len(with_spec))
    rows_n = math.ceil(len(with_spec) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(3.2 * cols, 2.4 * rows_n), squeeze=False, sharex=True)
    hi = cal.settings.band_hz[1] if cal.settings.band_hz else 50.0
    for ax, r in zip(axes.flat, with_spec, strict=False):
        assert r.spectrum is not None
        f, p = r.spectrum
        sel = (f > 0.5) & (f <= hi)
        ax.semilogy(f[sel], p[sel] / max(float(p[sel].max()), 1e-300), lw=0.7)
        for m in r.modes:
            ax.axvline(m.hz, color="C3", lw=0.6, ls="--")
        ax.set_title(r.name, fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(with_spec):]:
        ax.axis("off")
    for ax in axes[-1, :]:
        ax.set_xlabel("Hz")
    fig.suptitle("Spectrum of the first free decay at each pose (dashed: identified modes)", fontsize=10)
    fig.tight_layout()
    return fig


def residual_figure(cal: Calibration) -> Any:
    """residual.png: per pose, the residual vibration (%) predicted for the fixed (home) shaper and the
    scheduled one, each on the pose's nominal modes (left) and at the worst corner of their two-sigma
    box (right), like with like; or None.

    Points on a linear axis whose bottom lies below zero: the scheduled shaper is designed on the very
    modes measured at each calibrated pose, so its nominal residual there is zero, drawn as points on
    the zero line (as bars, it was invisible)."""
    import matplotlib.pyplot as plt

    if not any(cal.residuals):
        return None
    x = np.arange(len(cal.results))
    fig, axes = plt.subplots(1, 2, figsize=(max(9.0, 1.0 * len(cal.results)), 3.8), sharey=True, squeeze=False)
    top = max([100 * v for row in cal.residuals for v in row.values() if math.isfinite(v)] + [1.0])
    panels = ((axes[0, 0], RESIDUAL_SERIES[:2], "on the identified modes"),
              (axes[0, 1], RESIDUAL_SERIES[2:], "worst over the modes' two-sigma box"))
    for ax, series, title in panels:
        for (key, label), (marker, colour, off) in zip(series, (("o", "C0", -0.12), ("D", "C3", 0.12)), strict=True):
            ax.plot(x + off, [100 * row.get(key, math.nan) for row in cal.residuals], marker, color=colour, ms=6,
                    ls="none", label=label)
        ax.set_xticks(x, [r.name for r in cal.results], rotation=45, ha="right", fontsize=7)
        ax.set_title(title, fontsize=9)
        ax.set_ylim(-0.04 * top, 1.4 * top)  # the legend above the highest point
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3, axis="y")
    axes[0, 0].set_ylabel("predicted residual vibration (%)")
    fig.suptitle("Residual vibration predicted at each calibrated pose (scheduled: designed on the pose's own"
                 " modes, 0 % nominal)", fontsize=9)
    fig.tight_layout()
    return fig


#: the figures, in report order: (file name, the function that builds it)
FIGURES = (("modes_vs_pose.png", modes_figure), ("spectra.png", spectra_figure), ("residual.png", residual_figure))
#: the figure that takes longest to draw (a panel per pose): :class:`.calibration_pool.PosePipeline` starts it first
LONGEST = "spectra.png"


def write_figure(out: pathlib.Path, cal: Calibration, name: str) -> pathlib.Path | None:
    """Writes figure ``name`` (one of :data:`FIGURES`; PNG, Agg) into ``out`` if ``cal`` has data for it; its path,
    or None."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = dict(FIGURES)[name](cal)
    if fig is None:
        return None
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / (name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    write_atomic(out / name, tmp.read_bytes())
    tmp.unlink()
    return out / name


def figures(out: pathlib.Path, cal: Calibration) -> list[pathlib.Path]:
    """Writes the figures that ``cal`` has data for (PNG, Agg) into ``out``; the paths written."""
    return [path for name, _ in FIGURES if (path := write_figure(out, cal, name)) is not None]


def _label_mode_axes(col: Any, joint: str) -> None:
    """Labels and legends of one grid joint's column of modes_vs_pose.png."""
    col[0].set_ylabel("natural frequency (Hz)")
    col[1].set_ylabel("damping ratio")
    col[1].set_xlabel(f"{joint} (rad)")
    for ax in col:
        ax.legend(fontsize=7, loc="best")
        ax.grid(alpha=0.3)


def markdown(cal: Calibration, report: dict[str, Any], figs: list[str], recording: str) -> str:
    c = cal.plan.config
    lines = ["# Calibration report", "",
             f"{len(cal.results)} of {len(cal.plan.steps)} poses measured"
             + ("" if report["complete"] else " (incomplete: rerun with --resume)")
             + f"; {c.repeats} excitations each; recording: `{recording}`.", "",
             "Modes: natural frequency (Hz) and damping ratio with one-sigma uncertainties; flags name what the"
             " repeats did not agree on.", "",
             "| pose | " + " | ".join(c.grid_joints or c.joint_names) + " | modes (Hz, zeta) | fixed % | scheduled %"
             " | fixed, worst 2 sigma % | scheduled, worst 2 sigma % | flags |",
             "|---|" + "---|" * len(c.grid_joints or c.joint_names) + "---|---|---|---|---|---|"]
    names = list(c.joint_names)
    for r, res in zip(cal.results, cal.residuals, strict=True):
        joints = [f"{r.positions[names.index(j)]:+.3f}" for j in (c.grid_joints or c.joint_names)]
        modes = "; ".join(f"{plus_minus_fixed(m.hz, m.omega_std / (2 * math.pi), 3)},"
                          f" {plus_minus_fixed(m.zeta, m.zeta_std, 4)}" for m in r.modes)
        pct = " | ".join(f"{100 * res.get(k, math.nan):.1f}" for k, _ in RESIDUAL_SERIES)
        lines.append(f"| {r.name} | " + " | ".join(joints) + f" | {modes} | {pct} | {'; '.join(r.flags) or '-'} |")
    lines += [""]
    if "scheduler" in report:
        s = report["scheduler"]
        lines += [f"Scheduler rule base (`scheduler.yaml`): {s['rules']} rules over {', '.join(s['premises'])},"
                  f" {s['family']} shapers on the interpolated modes."]
    if "fallback" in report:
        f = report["fallback"]
        lines += [f"Fallback (`shaper.yaml`): {f['family']} on the home pose's modes"
                  f" {', '.join(f'{x:.3f} Hz' for x in f['frequencies_hz'])}, {f['duration_s']:.3f} s long."]
    if cal.notes:
        lines += ["", "Choices:", ""] + [f"- {n}" for n in cal.notes]
    lines += ["", "Predicted residual: percentage vibration the shaper leaves on the pose's identified modes,"
              " weighted by their amplitudes."]
    lines += [""] + [f"![{f}]({f})" for f in figs]
    return "\n".join(lines) + "\n"


def write_outputs(out: pathlib.Path, cal: Calibration, recording: str = "recording",
                  figs: list[pathlib.Path] | None = None) -> list[pathlib.Path]:
    """report.json, report.md with figures, scheduler.yaml and shaper.yaml in ``out``; the paths written. ``figs``:
    the figures already written (by :func:`write_figure`), in report order; without, :func:`figures` writes them."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    figs = figures(out, cal) if figs is None else figs
    written += figs
    report = report_dict(cal)
    if cal.rule_base is not None:
        write_atomic(out / "scheduler.yaml", scheduler_yaml(cal))
        written.append(out / "scheduler.yaml")
    if cal.fallback is not None:
        write_atomic(out / "shaper.yaml", shaper_yaml(cal))
        written.append(out / "shaper.yaml")
    write_atomic(out / "report.md", markdown(cal, report, [f.name for f in figs], recording))
    write_atomic(out / "report.json", json.dumps(report, indent=1) + "\n")
    return [*written, out / "report.md", out / "report.json"]


def assemble_from_setup(setup: dict[str, Any], results: list[Any]) -> Calibration:
    """The calibration from its poses' results on the setup they were recorded with (as
    :func:`.calibration.compute` assembles it; ``calibrate`` runs it in a worker of its pool: the recording process
    imports neither the fits nor matplotlib)."""
    plan, settings, family, threshold = plan_from_setup(setup)
    return assemble(plan, settings, family, threshold, results, wiring_of(setup))
