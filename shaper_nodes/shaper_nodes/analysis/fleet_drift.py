"""Drift of each robot's vibration mode across its recordings, against the robot's own baseline.

The rule (docs/guide/fleet.md). A robot's recordings are taken in the order of their start time; those
that gave no mode (or could not be analysed) are listed but take no part. The **baseline** is the
robot's first ``baseline`` recordings with a mode: its frequency f_b and damping ratio z_b are
the means of those recordings' strongest mode (the strongest that rings, as analyze_bag decides),
its scatter s_f, s_z their sample standard deviations. Every later recording is compared on its
(ringing) mode nearest f_b (frequency f, damping z, one-sigma uncertainties u_f, u_z from the
identification). The comparison's sigma allows for both the recording's own uncertainty and the
recording-to-recording scatter the baseline showed, and for the baseline mean's own error::

    sigma_f = sqrt(max(u_f, s_f)^2 + max(rms u_f,baseline, s_f)^2 / n_baseline)    (same for z)

A recording is **out** when its frequency moved by more than ``max_frequency_shift`` (fraction of
f_b) *and* by more than ``sigmas`` sigma_f, or its damping ratio changed by more than the larger of
``max_damping_change`` z_b and ``damping_floor`` *and* by more than ``sigmas`` sigma_z. As the
identifier's on-robot drift watch (:class:`~shaper_nodes.core.identification.drift.DriftWatch`)
does with cycles, an **alert** is raised once ``confirm`` recordings in a row are out, so one odd
recording raises nothing.

The **baseline is checked** too (:func:`_baseline_check`), since a drift inside it would otherwise move
f_b along and never be seen: a baseline recording more than ``max_frequency_shift`` f_b and ``sigmas``
of its own uncertainty from f_b is out (scatter), and a least-squares trend over the baseline that
changes by more than ``max_frequency_shift`` f_b from its first to its last recording, at more than
``sigmas`` standard errors, is a drift (trend). Either makes the robot's verdict ALERT
(:attr:`RobotDrift.verdict`, the one string the terminal, the report and the plot's title print, so
the plot and the verdict agree: a point drawn out is either confirmed, or counted in the verdict as
"not confirmed").

For an alert: the new mode (mean of the recordings out since the run began, with the larger of
their rms uncertainty and their scatter), the retune (the shaper
:func:`~shaper_nodes.core.identification.recommend_shaper` recommends for the new mode), and how the
baseline's recommended shaper fares there: V at the new mode and its working band
(:func:`~shaper_nodes.core.identification.drift.check_mode`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.identification import IdentificationError, ModeFit, recommend_shaper
from shaper_nodes.core.identification.drift import check_mode

from .fleet import Result


@dataclass(frozen=True)
class DriftRule:
    """The alert rule's numbers (see the module docstring).

    baseline : recordings with a mode in the baseline; max_frequency_shift : fraction of f_b;
    max_damping_change : fraction of z_b; damping_floor : smallest damping change counted (ratio,
    absolute); sigmas : the change must exceed this many combined sigma; confirm : recordings out in
    a row before an alert; target, sigmas_box, min_saving : the recommendation of the retune.
    """

    baseline: int = 5
    max_frequency_shift: float = 0.05
    max_damping_change: float = 0.5
    damping_floor: float = 0.005
    sigmas: float = 3.0
    confirm: int = 2
    target: float = 0.05
    sigmas_box: float = 2.0
    min_saving: float = 0.2

    def __post_init__(self) -> None:
        if self.baseline < 1 or self.confirm < 1:
            raise ValueError(f"baseline and confirm must be >= 1 recording, got {self.baseline}, {self.confirm}")
        if not (self.max_frequency_shift > 0 and self.max_damping_change > 0 and self.damping_floor >= 0
                and self.sigmas >= 0):
            raise ValueError("max_frequency_shift and max_damping_change must be > 0, damping_floor and sigmas >= 0")


@dataclass
class Point:
    """One recording of a robot, compared with the baseline (NaN where it does not apply)."""

    result: Result
    in_baseline: bool = False
    frequency_hz: float = float("nan")
    frequency_std_hz: float = float("nan")
    zeta: float = float("nan")
    zeta_std: float = float("nan")
    shift: float = float("nan")  # (f - f_b) / f_b
    shift_sigmas: float = float("nan")
    damping_change: float = float("nan")  # z - z_b
    damping_sigmas: float = float("nan")
    out: bool = False
    why: str = ""


@dataclass
class Alert:
    """A confirmed drift of one robot: from which recording, the new mode and the retune."""

    robot: str
    first_out: str  # path of the first recording of the run that is out
    raised_at: str  # path of the recording that confirmed it
    start_s: float
    recordings_out: int
    frequency_hz: float
    frequency_std_hz: float
    zeta: float
    shift: float
    damping_change: float
    why: str
    retune: dict[str, Any] | None
    baseline_shaper: dict[str, Any] | None


@dataclass
class RobotDrift:
    """A robot's recordings compared with its baseline, and its alerts."""

    robot: str
    points: list[Point]
    baseline_hz: float = float("nan")
    baseline_scatter_hz: float = float("nan")
    baseline_zeta: float = float("nan")
    baseline_scatter_zeta: float = float("nan")
    baseline_recommendation: dict[str, Any] | None = None
    alerts: list[Alert] = field(default_factory=list)
    note: str = ""
    baseline_issue: str = ""  # the baseline itself drifts or scatters (its check), "" if steady

    @property
    def verdict(self) -> str:
        """The robot's verdict, one string for the terminal, the report and the plot's title: "ALERT" with
        a confirmed drift or an unsteady baseline; else "ok", with the recordings out not (yet) confirmed."""
        if self.alerts or self.baseline_issue:
            return "ALERT"
        if not math.isfinite(self.baseline_hz):
            return "no baseline"
        n = sum(1 for p in self.points if p.out)
        return f"ok ({n} recording{'s' if n > 1 else ''} out, not confirmed)" if n else "ok"


def _rms(x: Sequence[float]) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else 0.0


def _mode(frequency_hz: float, zeta: float, std_hz: float, zeta_std: float) -> ModeFit:
    return ModeFit(2 * math.pi * frequency_hz, zeta, 2 * math.pi * std_hz, zeta_std, 1.0, "fleet")


def _recommend(mode: ModeFit, rule: DriftRule) -> tuple[dict[str, Any] | None, Any]:
    try:
        rec = recommend_shaper([mode], rule.target, sigmas=rule.sigmas_box, min_saving=rule.min_saving)
    except IdentificationError:
        return None, None
    if rec.best is None:
        return None, None
    b = rec.best
    return ({"family": b.family, "duration_s": b.duration, "v_nominal": b.nominal_vibration,
             "v_worst": b.worst_vibration, "amplitudes": [float(a) for a in b.shaper.amplitudes],
             "times_s": [float(t) for t in b.shaper.times], "designed_hz": mode.hz, "designed_zeta": mode.zeta},
            b.shaper)


def robot_drift(robot: str, results: Sequence[Result], rule: DriftRule) -> RobotDrift:
    """Compare one robot's recordings with its baseline and raise its alerts (the module's rule)."""
    ordered = sorted(results, key=lambda r: (math.inf if not math.isfinite(r.start_s) else r.start_s, r.path))
    points = [Point(r) for r in ordered]
    usable = [p for p in points if not p.result.error and p.result.modes]
    out = RobotDrift(robot, points)
    if len(usable) <= rule.baseline:
        out.note = (f"{len(usable)} recordings with a mode, all in the baseline of {rule.baseline}: none after it"
                    " to compare with it yet")
    base = usable[:rule.baseline]
    for p in base:
        p.in_baseline = True
        m = p.result.modes[0]
        p.frequency_hz, p.frequency_std_hz = float(m["frequency_hz"]), float(m["frequency_std_hz"] or 0.0)
        p.zeta, p.zeta_std = float(m["zeta"]), float(m["zeta_std"] or 0.0)
    if not base:
        out.note = "no recording with a mode"
        return out
    f = np.array([p.frequency_hz for p in base])
    z = np.array([p.zeta for p in base])
    n = len(base)
    out.baseline_hz, out.baseline_zeta = float(f.mean()), float(z.mean())
    out.baseline_scatter_hz = float(f.std(ddof=1)) if n > 1 else 0.0
    out.baseline_scatter_zeta = float(z.std(ddof=1)) if n > 1 else 0.0
    base_uf = max(_rms([p.frequency_std_hz for p in base]), out.baseline_scatter_hz)
    base_uz = max(_rms([p.zeta_std for p in base]), out.baseline_scatter_zeta)
    out.baseline_issue = _baseline_check(base, out.baseline_hz, rule)
    base_mode = _mode(out.baseline_hz, out.baseline_zeta, base_uf, base_uz)
    out.baseline_recommendation, base_shaper = _recommend(base_mode, rule)
    run: list[Point] = []
    for p in usable[rule.baseline:]:
        m = min([m for m in p.result.modes if m.get("rings", True)] or p.result.modes,
                key=lambda m: abs(float(m["frequency_hz"]) - out.baseline_hz))
        p.frequency_hz, p.frequency_std_hz = float(m["frequency_hz"]), float(m["frequency_std_hz"] or 0.0)
        p.zeta, p.zeta_std = float(m["zeta"]), float(m["zeta_std"] or 0.0)
        sf = math.hypot(max(p.frequency_std_hz, out.baseline_scatter_hz), base_uf / math.sqrt(n))
        sz = math.hypot(max(p.zeta_std, out.baseline_scatter_zeta), base_uz / math.sqrt(n))
        df, dz = p.frequency_hz - out.baseline_hz, p.zeta - out.baseline_zeta
        p.shift, p.damping_change = df / out.baseline_hz, dz
        p.shift_sigmas = abs(df) / sf if sf > 0 else math.inf
        p.damping_sigmas = abs(dz) / sz if sz > 0 else math.inf
        why = []
        if abs(p.shift) > rule.max_frequency_shift and p.shift_sigmas > rule.sigmas:
            why.append(f"frequency {p.frequency_hz:.4g} Hz is {100 * p.shift:+.1f} % from the baseline's"
                       f" {out.baseline_hz:.4g} Hz ({p.shift_sigmas:.1f} sigma)")
        limit = max(rule.max_damping_change * out.baseline_zeta, rule.damping_floor)
        if abs(dz) > limit and p.damping_sigmas > rule.sigmas:
            why.append(f"damping ratio {p.zeta:.3g} changed by {dz:+.3g} from the baseline's {out.baseline_zeta:.3g}"
                       f" ({p.damping_sigmas:.1f} sigma)")
        p.out, p.why = bool(why), "; ".join(why)
        run = [*run, p] if p.out else []
        if len(run) == rule.confirm:
            out.alerts.append(_alert(robot, run, out, base_shaper, rule))
        elif len(run) > rule.confirm:  # the alert of this run, updated with every further recording out
            out.alerts[-1] = _alert(robot, run, out, base_shaper, rule)
    return out


def _baseline_check(base: Sequence[Point], f_b: float, rule: DriftRule) -> str:
    """Whether the baseline is steady ("" if so, else why; marks its points that are out).

    Scatter: a baseline recording whose frequency is further from the baseline's mean than the
    frequency limit (``max_frequency_shift`` f_b) and than ``sigmas`` times its own uncertainty is out.
    Trend: the least-squares line of the frequency over the baseline recordings (in their order)
    changes by more than the frequency limit from the first to the last and its slope is more than
    ``sigmas`` standard errors from zero. Either makes the baseline unfit to compare with.
    """
    why = []
    for p in base:
        d = p.frequency_hz - f_b
        if abs(d) > rule.max_frequency_shift * f_b and abs(d) > rule.sigmas * p.frequency_std_hz:
            p.out = True
            p.shift = d / f_b
            p.why = f"inside the baseline: {p.frequency_hz:.4g} Hz is {100 * d / f_b:+.1f} % from its mean {f_b:.4g} Hz"
    n_out = sum(1 for p in base if p.out)
    if n_out:
        why.append(f"{n_out} of the {len(base)} baseline recordings are more than"
                   f" {100 * rule.max_frequency_shift:g} % from its mean {f_b:.4g} Hz")
    if len(base) >= 3:
        x = np.arange(len(base), dtype=float)
        f = np.array([p.frequency_hz for p in base])
        slope, icpt = np.polyfit(x, f, 1)
        resid = f - (slope * x + icpt)
        se = math.sqrt(float(resid @ resid) / (len(base) - 2) / float(((x - x.mean()) ** 2).sum()))
        u = max(_rms([p.frequency_std_hz for p in base]) / math.sqrt(float(((x - x.mean()) ** 2).sum())), se)
        change = float(slope) * (len(base) - 1)
        if abs(change) > rule.max_frequency_shift * f_b and (u == 0 or abs(slope) > rule.sigmas * u):
            why.append(f"the baseline drifts: its frequency trend changes by {100 * change / f_b:+.1f} % over its"
                       f" {len(base)} recordings ({abs(slope) / u if u else math.inf:.1f} sigma)")
    return "; ".join(why)


def _alert(robot: str, run: list[Point], drift: RobotDrift, base_shaper: Any, rule: DriftRule) -> Alert:
    f = np.array([p.frequency_hz for p in run])
    z = np.array([p.zeta for p in run])
    uf = max(_rms([p.frequency_std_hz for p in run]), float(f.std(ddof=1)) if len(run) > 1 else 0.0)
    uz = max(_rms([p.zeta_std for p in run]), float(z.std(ddof=1)) if len(run) > 1 else 0.0)
    new = _mode(float(f.mean()), float(z.mean()), uf, uz)
    retune, _ = _recommend(new, rule)
    fares = None
    if base_shaper is not None:
        design_hz = [m.omega / (2 * math.pi) for m in base_shaper.modes]
        check = check_mode(base_shaper.amplitudes, base_shaper.times, design_hz, new, rule.target)
        fares = {"family": base_shaper.family, "v_at_new_mode": check.vibration, "inside_band": check.inside,
                 "band_hz": list(check.band_hz) if check.band_hz else None}
    return Alert(robot, run[0].result.path, run[rule.confirm - 1].result.path, run[0].result.start_s, len(run),
                 new.hz, uf, new.zeta, new.hz / drift.baseline_hz - 1.0, new.zeta - drift.baseline_zeta,
                 run[-1].why, retune, fares)


def fleet_drift(results: Sequence[Result], rule: DriftRule) -> list[RobotDrift]:
    """Every robot's drift (robots sorted by name)."""
    robots: dict[str, list[Result]] = {}
    for r in results:
        robots.setdefault(r.robot, []).append(r)
    return [robot_drift(name, robots[name], rule) for name in sorted(robots)]
