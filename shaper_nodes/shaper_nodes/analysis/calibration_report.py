"""report.md and its figures for a calibration (see :mod:`.calibration`), and :func:`write_outputs`, which
writes them with report.json, scheduler.yaml and shaper.yaml.

Figures (PNG, matplotlib's Agg backend):

- ``modes_vs_pose.png``: each mode's natural frequency and damping ratio against each grid
  joint, one line per value of the other grid joints, with two-sigma error bars;
- ``spectra.png``: the spectrum of the first free decay at every pose, identified modes marked;
- ``residual.png``: the residual vibration predicted at every pose for the fixed (home) shaper
  and for the scheduled shaper (nominal, and worst over the modes' two-sigma uncertainty).
"""

from __future__ import annotations

import json
import math
import pathlib
from typing import Any

import numpy as np

from shaper_nodes.core.files import write_atomic

from .calibration import Calibration, report_dict, scheduler_yaml, shaper_yaml


def figures(out: pathlib.Path, cal: Calibration) -> list[pathlib.Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []

    def save(fig: Any, name: str) -> None:
        tmp = out / (name + ".tmp.png")
        fig.savefig(tmp, dpi=100)
        plt.close(fig)
        write_atomic(out / name, tmp.read_bytes())
        tmp.unlink()
        paths.append(out / name)

    c = cal.plan.config
    names = list(c.joint_names)
    grid = [r for r in cal.results if r.grid_index is not None]
    if grid and c.grid_joints:
        k = max(len(r.modes) for r in grid)
        fig, axes = plt.subplots(2, len(c.grid_joints), figsize=(5 * len(c.grid_joints), 6.5), squeeze=False)
        for a, joint in enumerate(c.grid_joints):
            j = names.index(joint)
            others = sorted({tuple(np.delete(np.asarray(r.grid_index), a)) for r in grid if r.grid_index})
            for other in others:
                rows = sorted((r for r in grid if r.grid_index is not None
                               and tuple(np.delete(np.asarray(r.grid_index), a)) == other),
                              key=lambda r: r.positions[j])
                label = ", ".join(f"{c.grid_joints[b]} {rows[0].positions[names.index(c.grid_joints[b])]:+.2f}"
                                  for b in range(len(c.grid_joints)) if b != a)
                for mi in range(k):
                    pts = [(r.positions[j], r.modes[mi]) for r in rows if len(r.modes) > mi]
                    if not pts:
                        continue
                    xs = [p[0] for p in pts]
                    axes[0, a].errorbar(xs, [p[1].hz for p in pts], [2 * p[1].omega_std / (2 * math.pi) for p in pts],
                                        marker="o", ms=3, lw=0.8, capsize=2, label=label if mi == 0 else None)
                    axes[1, a].errorbar(xs, [p[1].zeta for p in pts], [2 * p[1].zeta_std for p in pts],
                                        marker="o", ms=3, lw=0.8, capsize=2)
            _label_mode_axes(axes[:, a], joint, legend=len(c.grid_joints) > 1)
        fig.suptitle("Modes against the pose (error bars: two sigma)", fontsize=10)
        fig.tight_layout()
        save(fig, "modes_vs_pose.png")

    with_spec = [r for r in cal.results if r.spectrum is not None]
    if with_spec:
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
        save(fig, "spectra.png")

    if any(cal.residuals):
        fig, ax = plt.subplots(figsize=(max(6.0, 0.6 * len(cal.results)), 3.6))
        x = np.arange(len(cal.results))
        for key, label, off in (("fixed", "fixed (home) shaper", -0.25), ("scheduled", "scheduled", 0.0),
                                ("scheduled_worst_2sigma", "scheduled, worst over 2 sigma", 0.25)):
            ax.bar(x + off, [100 * row.get(key, math.nan) for row in cal.residuals], 0.25, label=label)
        ax.set_xticks(x, [r.name for r in cal.results], rotation=45, ha="right", fontsize=7)
        ax.set_ylabel("predicted residual vibration (%)")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, axis="y")
        fig.tight_layout()
        save(fig, "residual.png")
    return paths


def _label_mode_axes(col: Any, joint: str, legend: bool) -> None:
    """Labels of one grid joint's column of modes_vs_pose.png. The legend names the other grid joints'
    values of each line: with one grid joint there are none (and matplotlib warns of an empty legend)."""
    col[0].set_ylabel("natural frequency (Hz)")
    col[1].set_ylabel("damping ratio")
    col[1].set_xlabel(f"{joint} (rad)")
    if legend:
        col[0].legend(fontsize=7)
    for ax in col:
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
             " | flags |",
             "|---|" + "---|" * len(c.grid_joints or c.joint_names) + "---|---|---|---|"]
    names = list(c.joint_names)
    for r, res in zip(cal.results, cal.residuals, strict=True):
        joints = [f"{r.positions[names.index(j)]:+.3f}" for j in (c.grid_joints or c.joint_names)]
        modes = "; ".join(f"{m.hz:.3f} +- {m.omega_std / (2 * math.pi):.3f}, {m.zeta:.4f} +- {m.zeta_std:.4f}"
                          for m in r.modes)
        lines.append(f"| {r.name} | " + " | ".join(joints) + f" | {modes} | {100 * res.get('fixed', math.nan):.1f} |"
                     f" {100 * res.get('scheduled', math.nan):.1f} | {'; '.join(r.flags) or '-'} |")
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


def write_outputs(out: pathlib.Path, cal: Calibration, recording: str = "recording") -> list[pathlib.Path]:
    """report.json, report.md with figures, scheduler.yaml and shaper.yaml in ``out``; the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    figs = figures(out, cal)
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
