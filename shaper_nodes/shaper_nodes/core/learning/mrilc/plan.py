"""A move's MRILC set-up from its commanded profile, and its error from the measured accelerometer, free of ROS.

What :class:`~.moves.MoveLearner` needs besides its operator, built from one move's commanded joint profile
(the shaped goal's points, times from the move's start) the way ``reproductions.arm_mrilc`` builds it:

- the **motion end** (:func:`motion_end`): the time the commanded positions stop changing;
- the **output grid**: accelerometer samples every ``output_period`` s from the move's start to
  ``residual_window`` s after the motion end;
- the **basis**, two families of cubic B-splines per joint: ``spacing`` s apart in the last ``tail`` s of the
  shaped motion (the arm's modes, 6-25 Hz) and ``fine_spacing`` s apart in its last ``fine_tail`` s (the
  position loop's own transient, 30-100 Hz, which the motion's last acceleration step starts and which is over
  within about 20 ms of the motion's end); the correction and its first two derivatives vanish at the move's
  start and end: the goal and the timing stay;
- the **weights**: 0 during the motion and for ``skip`` s after it, 1 in the residual window, so that what is
  learned is the residual as it is measured (the rigid reference at rest is constant there, and the error's
  mean, or with ``trend_degree`` > 0 its trend, is taken out: :func:`residual_error`).

:func:`plan_move` returns a :class:`MovePlan` (with ``families``: for each family where its first B-spline
starts, in output samples, how many there are per joint and their spacing, what the operator's provider needs;
:func:`plan_operator` calls the provider per family and puts the columns in the learner's order);
:func:`residual_error` turns a window of accelerometer samples into the learner's error e = y_m - y;
:func:`limit_breach` names the first joint and limit a corrected profile breaks (the applier refuses the
correction then).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .model import MrilcError
from .profile import JointLimits, Profile, spline_basis

__all__ = ["Family", "MovePlan", "PlanSettings", "limit_breach", "motion_end", "plan_move", "plan_operator",
           "residual_error"]

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PlanSettings:
    """How a move's learner is set up (the reproduction's values by default).

    spacing : s between the B-spline knots (resolves up to about 1 / (3 spacing) Hz)
    tail : s before the motion end the correction may act in (where the linearisation at the goal holds)
    fine_spacing : s between the second family's knots (the position loop's transient)
    fine_tail : s before the motion end the second family acts in (0: no second family)
    output_period : s between the accelerometer samples compared
    residual_window : s after the motion end that are learned from
    skip : s after the motion end left out
    trend_degree : degree of the polynomial taken out of the error per axis over the window (0: its mean, as the
        residual's measure takes it out)
    """

    spacing: float = 0.04
    tail: float = 0.4
    fine_spacing: float = 0.004
    fine_tail: float = 0.048
    output_period: float = 1e-3
    residual_window: float = 1.0
    skip: float = 0.0
    trend_degree: int = 0

    def __post_init__(self) -> None:
        for name in ("spacing", "tail", "fine_spacing", "output_period", "residual_window"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise MrilcError(f"{name} must be finite and > 0 s, got {v!r}")
        if not (math.isfinite(self.fine_tail) and self.fine_tail >= 0):
            raise MrilcError(f"fine_tail must be finite and >= 0 s, got {self.fine_tail!r}")
        if not (math.isfinite(self.skip) and 0 <= self.skip < self.residual_window):
            raise MrilcError(f"skip must be in [0, residual_window) s, got {self.skip!r}")
        if self.trend_degree < 0:
            raise MrilcError(f"trend_degree must be >= 0, got {self.trend_degree}")


@dataclass(frozen=True)
class Family:
    """One family of the basis: its first B-spline starts ``first`` output samples after the move's start; ``count``
    B-splines per joint, ``spacing`` s apart."""

    first: int
    count: int
    spacing: float


@dataclass(frozen=True)
class MovePlan:
    """One move's set-up: the motion end (s from the move's start), the output grid (s), the profile and basis at
    the goal's points, the weight of each output sample (grid x 3, k-major), and the basis' families (per joint the
    coefficients are the first family's, then the second's)."""

    motion_end: float
    grid: Array
    profile: Profile
    weights: Array
    families: tuple[Family, ...]

    @property
    def first(self) -> int:
        """Where the first family starts, output samples."""
        return self.families[0].first

    @property
    def count(self) -> int:
        """B-splines per joint, every family."""
        return sum(f.count for f in self.families)


def motion_end(times: npt.ArrayLike, positions: npt.ArrayLike, tolerance: float = 1e-9) -> float:
    """The time (s) the commanded positions (N, joints) stop changing (their last change above ``tolerance``)."""
    t = np.asarray(times, dtype=float)
    c = np.asarray(positions, dtype=float)
    moving = np.flatnonzero(np.any(np.abs(np.diff(c, axis=0)) > tolerance, axis=1))
    return float(t[moving[-1] + 1]) if moving.size else float(t[0])


def plan_move(times: npt.ArrayLike, positions: npt.ArrayLike, velocities: npt.ArrayLike,
              accelerations: npt.ArrayLike, start: npt.ArrayLike, settings: PlanSettings = PlanSettings()
              ) -> MovePlan:
    """The set-up of a move whose commanded points are at ``times`` (s from the move's start, > 0) with
    ``positions``, ``velocities``, ``accelerations`` ((N, joints): rad, rad/s, rad/s^2), starting at rest at
    ``start`` (rad).

    Raises
    ------
    MrilcError
        Sizes that differ, non-finite values, times not increasing, or a motion shorter than four knots.
    """
    t = np.asarray(times, dtype=float)
    q, v, a = (np.asarray(x, dtype=float) for x in (positions, velocities, accelerations))
    q0 = np.asarray(start, dtype=float).ravel()
    if t.ndim != 1 or q.shape != (t.size, q0.size) or v.shape != q.shape or a.shape != q.shape:
        raise MrilcError(f"the profile must be {t.size} points of {q0.size} joints (positions, velocities,"
                         f" accelerations), got {q.shape}, {v.shape}, {a.shape}")
    if not all(np.all(np.isfinite(x)) for x in (t, q, v, a, q0)) or t.size == 0 or t[0] <= 0 or np.any(
            np.diff(t) <= 0):
        raise MrilcError("the profile's times must be finite, > 0 and increasing, its values finite")
    s = settings
    end = motion_end(np.append(0.0, t), np.vstack([q0, q]))
    grid = np.asarray(s.output_period * np.arange(1, int(round((end + s.residual_window) / s.output_period)) + 1),
                      dtype=np.float64)
    families: list[Family] = []
    parts: list[tuple[Array, Array, Array]] = []
    for spacing, tail in ((s.spacing, s.tail), (s.fine_spacing, s.fine_tail)):
        if tail <= 0 and families:
            continue
        offset = max(0.0, math.floor((end - tail) / s.output_period + 1e-9) * s.output_period)
        count = int((end - offset) / spacing + 1e-9) - 3
        if count < 1:
            raise MrilcError(f"the shaped motion ({end:.3f} s) is too short for a correction with knots {spacing} s"
                             f" apart in its last {tail} s")
        families.append(Family(int(round(offset / s.output_period)), count, spacing))
        parts.append(spline_basis(t - offset, spacing, count))
    basis = tuple(np.hstack([p[i] for p in parts]) for i in range(3))
    profile = Profile(q, v, a, (basis[0], basis[1], basis[2]))
    weights = np.repeat(np.where(grid < end + s.skip, 0.0, 1.0), 3)
    return MovePlan(end, grid, profile, weights, tuple(families))


def plan_operator(plan: MovePlan, provider: Callable[..., npt.ArrayLike], goal: npt.ArrayLike, joints: int,
                  period: float) -> Array:
    """The lifted operator G of ``plan`` ((grid x 3) x (count x joints), columns joint-major, per joint the first
    family's then the second's): ``provider(goal, count, samples, first, spacing, period)`` (e.g.
    ``sim_plant_node.arm.lifted:arm_operator``) once per family.

    Raises
    ------
    MrilcError
        A provider's block of the wrong shape or with a non-finite value.
    """
    samples = plan.grid.size
    blocks = []
    for f in plan.families:
        g = np.asarray(provider(np.asarray(goal, dtype=float), f.count, samples, f.first, f.spacing, period),
                       dtype=float)
        if g.shape != (samples * 3, f.count * joints) or not np.all(np.isfinite(g)):
            raise MrilcError(f"the operator's provider gave {g.shape} for a family of {f.count} B-splines on"
                             f" {joints} joints; {(samples * 3, f.count * joints)} finite values expected")
        blocks.append(g.reshape(samples * 3, joints, f.count))
    return np.asarray(np.concatenate(blocks, axis=2).reshape(samples * 3, -1))


def residual_error(plan: MovePlan, times: npt.ArrayLike, accel: npt.ArrayLike, degree: int = 0) -> Array:
    """The learner's error e = y_m - y ((grid x 3,) flattened, k-major) from accelerometer samples ``accel``
    ((M, 3), m/s^2) at ``times`` (s from the move's start, increasing), interpolated onto the plan's grid.

    The reference y_m is the rigid arm's specific force: at rest after the motion (where the weights are not
    zero) a constant, which the polynomial of degree ``degree`` fitted per axis over the residual window (and
    taken out of e everywhere) absorbs, as it absorbs a sensor's bias: with degree 0 (the mean) what is left in
    the window is the residual as its measure has it (:func:`~shaper_nodes.core.shaping.vibration.residual_vibration`
    with the mean removed), the position loop's transient and the arm's vibration both.

    Raises
    ------
    MrilcError
        Samples that do not cover the grid, or non-finite values.
    """
    t = np.asarray(times, dtype=float)
    y = np.asarray(accel, dtype=float)
    if t.ndim != 1 or y.shape != (t.size, 3) or not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise MrilcError(f"the accelerometer window must be finite, (samples, 3), got {y.shape}")
    if t.size < 2 or t[0] > plan.grid[0] + 1e-9 or t[-1] < plan.grid[-1] - plan.grid[0]:
        span = f"{t[0]:.3f}-{t[-1]:.3f} s" if t.size else "none"
        raise MrilcError(f"the accelerometer samples ({span} from the move's start) do not cover the move's"
                         f" window ({plan.grid[0]:.3f}-{plan.grid[-1]:.3f} s)")
    measured = np.column_stack([np.interp(plan.grid, t, y[:, i]) for i in range(3)])
    e = -measured
    rest = plan.weights[::3] > 0
    rel = plan.grid - plan.motion_end
    fit = np.polynomial.polynomial.polyfit(rel[rest], e[rest], degree)
    return np.asarray((e - np.polynomial.polynomial.polyval(rel, fit).T).ravel())


def limit_breach(q: Array, v: Array, a: Array, limits: JointLimits, names: list[str] | None = None,
                 base: tuple[Array, Array, Array] | None = None) -> str | None:
    """The first limit a corrected (samples, joints) profile breaks, as words naming the joint and the limit
    (None: all held; 1e-9 relative allowed for rounding). With ``base``, the uncorrected profile: where it is already
    past a limit, only what the correction adds beyond it counts (as :func:`~.profile.excess` does)."""
    tol = 1e-9
    for j in range(q.shape[1]):
        joint = names[j] if names is not None and j < len(names) else f"joint {j}"
        lo, hi = limits.position_min[j], limits.position_max[j]
        vm, am = limits.velocity[j], limits.acceleration[j]
        if base is not None:
            lo, hi = min(lo, float(base[0][:, j].min())), max(hi, float(base[0][:, j].max()))
            vm = max(vm, float(np.max(np.abs(base[1][:, j]))))
            am = max(am, float(np.max(np.abs(base[2][:, j]))))
        checks = (("position", float(q[:, j].min()), lo, "below its minimum", -1.0),
                  ("position", float(q[:, j].max()), hi, "above its maximum", 1.0),
                  ("velocity", float(np.max(np.abs(v[:, j]))), vm, "above its limit", 1.0),
                  ("acceleration", float(np.max(np.abs(a[:, j]))), am, "above its limit", 1.0))
        for what, value, bound, how, sign in checks:
            if sign * (value - bound) > tol * max(1.0, abs(bound)):
                return f"{joint} {what} {value:.6g} {how} {bound:.6g}"
    return None
