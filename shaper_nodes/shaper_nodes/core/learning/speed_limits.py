"""The rules a time-scaled move is held to, free of ROS: what the speed learner (:mod:`.speed`) and a node
around it need, measurable on a robot (the learner node's ``speed_moves`` mode).

A move's planned trajectory q(t) run ``s`` times faster is q(s t): velocities x s, accelerations x s^2, duration
/ s, the same path.

- :func:`limit_ceiling`: the largest factor the joint velocity and acceleration limits allow on a planned profile;
- :func:`time_scale`: a planned trajectory's points run ``s`` times faster (times / s up to the motion's
  last point, velocities x s, accelerations x s^2; the hold after the motion keeps its length);
- :func:`limit_breach`: the first point of a profile past a joint velocity or acceleration limit, named;
- :func:`effort_check`: the efforts measured during a move (a robot's /joint_states effort: joint torques, N m)
  against the joints' torque limits: the largest ratio, and the first joint past its limit, named (the plan's
  velocities and accelerations are checked before the move; the torque it took is known only after, and is
  predicted for the next factor before a raise, :mod:`.speed_peaks`); :func:`peak_check` the same for any measured
  peak (the joint speeds: a robot may overshoot its plan);
- :func:`acceleration_tolerance`: the accelerometer level that corresponds to a displacement tolerance at
  the flange, ``x (2 pi f)^2`` at the mode ``f`` (a sinusoid of amplitude x at f has the acceleration
  amplitude x (2 pi f)^2; at the move's lowest mode the same acceleration means the largest displacement,
  so the conversion is conservative for the higher modes and for the position loop's faster transient).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["SpeedError", "acceleration_tolerance", "effort_check", "limit_breach", "limit_ceiling", "limits_held",
           "motion_end_index", "peak_check", "time_scale"]


class SpeedError(ValueError):
    """Bad settings or state of the speed learner; the message names the problem."""


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SpeedError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise SpeedError(f"{name} must be finite and > 0, got {value!r}")
    return v



def limit_ceiling(velocities: np.ndarray, accelerations: np.ndarray, max_velocity: Sequence[float] | np.ndarray,
                  max_acceleration: Sequence[float] | np.ndarray) -> float:
    """The largest time-scaling factor that keeps a planned profile inside joint limits.

    Parameters
    ----------
    velocities, accelerations : (N, J) array
        The planned profile, rad/s and rad/s^2.
    max_velocity, max_acceleration : (J,) array_like
        Joint limits, rad/s and rad/s^2 (> 0; inf: no limit).

    Returns
    -------
    float
        min over joints of v_max / |v| and sqrt(a_max / |a|) (inf for a joint that does not move).
    """
    v = np.max(np.abs(np.asarray(velocities, dtype=float)), axis=0)
    a = np.max(np.abs(np.asarray(accelerations, dtype=float)), axis=0)
    vmax = np.asarray(max_velocity, dtype=float)
    amax = np.asarray(max_acceleration, dtype=float)
    if v.shape != vmax.shape or a.shape != amax.shape:
        raise SpeedError(f"limits for {vmax.size} and {amax.size} joints, profile has {v.size}")
    if not (np.all(vmax > 0) and np.all(amax > 0)):  # nan fails too
        raise SpeedError("joint velocity and acceleration limits must be > 0 (inf: no limit)")
    with np.errstate(divide="ignore"):
        s_v = np.where(v > 0, vmax / np.where(v > 0, v, 1.0), np.inf)
        s_a = np.where(a > 0, np.sqrt(amax / np.where(a > 0, a, 1.0)), np.inf)
    return float(min(np.min(s_v), np.min(s_a)))


def limits_held(peaks: np.ndarray, limits: Sequence[float] | np.ndarray) -> list[int]:
    """Indices of the joints whose peak magnitude exceeds its limit (empty: every limit held)."""
    p = np.abs(np.asarray(peaks, dtype=float)).reshape(-1)
    lim = np.asarray(limits, dtype=float).reshape(-1)
    if p.shape != lim.shape:
        raise SpeedError(f"{p.size} peaks against {lim.size} limits")
    return [int(i) for i in np.flatnonzero(~(p <= lim))]


def motion_end_index(positions: np.ndarray, tolerance: float = 1e-9) -> int:
    """Index of a trajectory's last point whose positions differ from the point before it (0 if none does):
    the points after it hold the final pose.

    Parameters
    ----------
    positions : (N, J) array
        The points' joint positions, rad.
    tolerance : float
        Largest change (rad) that still counts as holding.
    """
    q = np.asarray(positions, dtype=float)
    if q.shape[0] < 2:
        return 0
    moving = np.flatnonzero(np.any(np.abs(np.diff(q, axis=0)) > tolerance, axis=1))
    return int(moving[-1] + 1) if moving.size else 0


def time_scale(times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None,
               accelerations: np.ndarray | None, factor: float
               ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A planned trajectory's points run ``factor`` times faster on the same path.

    The motion (up to :func:`motion_end_index`) is q(s t): its points' times / s, velocities x s,
    accelerations x s^2. The points after it hold the final pose; they keep their spacing (a dwell at the
    goal stays as long as planned), shifted to the scaled motion's end.

    Parameters
    ----------
    times : (N,) array
        The points' times from the start, s (increasing).
    positions : (N, J) array
        Joint positions, rad (unchanged: the same path).
    velocities, accelerations : (N, J) array or None
        rad/s and rad/s^2 (None: not given; stays None).
    factor : float
        s > 0 (1: as planned).

    Returns
    -------
    times, velocities, accelerations
        The scaled points' times (s), velocities and accelerations.
    """
    s = _positive("factor", factor)
    t = np.asarray(times, dtype=float)
    m = motion_end_index(positions)
    out = t / s
    out[m + 1:] = t[m] / s + (t[m + 1:] - t[m])
    v = None if velocities is None else np.asarray(velocities, dtype=float) * s
    a = None if accelerations is None else np.asarray(accelerations, dtype=float) * s * s
    return out, v, a


def limit_breach(times: np.ndarray, velocities: np.ndarray, accelerations: np.ndarray,
                 max_velocity: Sequence[float] | np.ndarray, max_acceleration: Sequence[float] | np.ndarray,
                 names: Sequence[str]) -> str | None:
    """The first joint limit a profile breaks, in one line (None: every point within every limit).

    Parameters
    ----------
    times : (N,) array
        The points' times, s.
    velocities, accelerations : (N, J) array
        rad/s and rad/s^2.
    max_velocity, max_acceleration : (J,) array_like
        The joints' limits, rad/s and rad/s^2.
    names : sequence of str
        The joints' names.
    """
    for what, unit, values, limits in (("velocity", "rad/s", velocities, max_velocity),
                                       ("acceleration", "rad/s^2", accelerations, max_acceleration)):
        x = np.abs(np.asarray(values, dtype=float))
        lim = np.asarray(limits, dtype=float)
        over = x > lim[None, :]
        if np.any(over):
            i, j = (int(k) for k in np.argwhere(over)[0])
            return (f"joint {names[j]}: {what} {x[i, j]:.4g} {unit} above its limit {lim[j]:.4g} {unit} at the point"
                    f" of t = {float(times[i]):.3f} s")
    return None


def peak_check(peaks: np.ndarray | Sequence[float], limits: Sequence[float] | np.ndarray, names: Sequence[str],
               quantity: str = "effort", unit: str = "N m") -> tuple[float, int, str | None]:
    """The peaks measured during a move (joint efforts, N m; joint speeds, rad/s) against the joints' limits.

    Parameters
    ----------
    peaks : (J,) array_like
        The largest |value| each joint measured during the move.
    limits : (J,) array_like
        The joints' limits, in the same unit (> 0; inf: no limit).
    names : sequence of str
        The joints' names.
    quantity, unit : str
        What the peaks are (``effort``, ``velocity``) and their unit, for the line.

    Returns
    -------
    ratio : float
        The largest |value| / limit over the joints (0 for a joint without a limit; nan if a limit is nan).
    joint : int
        The index of the joint of that ratio (-1: no joint).
    breach : str or None
        The joint furthest past its limit, in one line (None: every joint within its limit; a nan value or limit
        counts as exceeded).
    """
    p = np.abs(np.asarray(peaks, dtype=float)).reshape(-1)
    lim = np.asarray(limits, dtype=float).reshape(-1)
    if p.shape != lim.shape or len(names) != p.size:
        plural = {"effort": "efforts", "velocity": "velocities"}.get(quantity, quantity)
        raise SpeedError(f"{p.size} {plural} against {lim.size} limits and {len(names)} names")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.where(np.isinf(lim), 0.0, p / lim)
    joint = int(np.argmax(np.nan_to_num(ratios, nan=np.inf))) if ratios.size else -1
    ratio = float(ratios[joint]) if ratios.size else 0.0
    over = limits_held(p, lim)
    if not over:
        return ratio, joint, None
    j = joint if joint in over else over[0]  # the joint furthest past its limit
    return ratio, joint, (f"joint {names[j]}: measured |{quantity}| {p[j]:.4g} {unit} above its limit"
                          f" {lim[j]:.4g} {unit}")


def effort_check(peaks: np.ndarray | Sequence[float], limits: Sequence[float] | np.ndarray,
                 names: Sequence[str]) -> tuple[float, int, str | None]:
    """:func:`peak_check` of the efforts measured during a move (a robot's /joint_states effort: joint torques, N m,
    or N for a prismatic joint) against the joints' effort limits."""
    return peak_check(peaks, limits, names, "effort", "N m")


def acceleration_tolerance(displacement: float, frequency_hz: float) -> float:
    """The accelerometer level, m/s^2, that a displacement tolerance at the flange corresponds to at a mode.

    Parameters
    ----------
    displacement : float
        Tolerance of the settled flange, m (0.05 mm: 5e-5).
    frequency_hz : float
        The mode's frequency, Hz (the move's lowest: the conversion is then conservative, module docstring).

    Returns
    -------
    float
        ``displacement * (2 pi frequency_hz)^2``.
    """
    x, f = _positive("displacement", displacement), _positive("frequency_hz", frequency_hz)
    return x * (2.0 * math.pi * f) ** 2
