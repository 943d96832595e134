"""Whole-trajectory shaping for joint_trajectory_controller.

The waypoints are resampled on the command-rate grid, convolved with the discretised shaper,
and differentiated, giving a trajectory that joint_trajectory_controller accepts: strictly
increasing times, finite values, and zero velocity and acceleration at the last point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.checks import InputError, finite_array, strictly_increasing

from .fir import StreamingShaper
from .sparse_fir import SparseFir

#: most points of one trajectory (a message or a request), refused before any work
MAX_TRAJECTORY_POINTS = 100_000
#: most samples of a shaped trajectory (its span x the command rate, plus the shaper): 10 min at
#: 500 Hz; bounds the memory and time of one request (about 17 MB per joint)
MAX_TRAJECTORY_SAMPLES = 300_000
#: the latest time a shaped point may have: builtin_interfaces/Duration holds int32 seconds
MAX_TIME_S = float(2**31 - 1)


def check_extent(times: np.ndarray, rate: float, extra: int = 0, max_samples: int = MAX_TRAJECTORY_SAMPLES) -> None:
    """Refuse a trajectory whose times are negative or whose resampling would pass the limits
    (``max_samples``, at most :data:`MAX_TRAJECTORY_SAMPLES`).

    Raises
    ------
    InputError
        ``too_large`` (too many points or samples) or ``non_increasing_time`` (a negative time).
    """
    t = np.asarray(times, dtype=float)
    if t.size > MAX_TRAJECTORY_POINTS:
        raise InputError("too_large", f"{t.size} points exceed the limit of {MAX_TRAJECTORY_POINTS}")
    if t.size and np.any(t < 0):
        k = int(np.argmax(t < 0))
        raise InputError("non_increasing_time", f"time_from_start of point {k} is negative ({t[k]:g} s)")
    span = float(t[-1] - t[0]) if t.size else 0.0
    samples = span * rate + 2 + extra
    limit = min(int(max_samples), MAX_TRAJECTORY_SAMPLES)
    if not samples <= limit:
        raise InputError("too_large", f"the trajectory spans {span:.6g} s: {samples:.6g} samples at {rate:g} Hz"
                         f" exceed the limit of {limit}")
    end = (float(t[-1]) if t.size else 0.0) + (extra + 2) / rate
    if not end < MAX_TIME_S:
        raise InputError("too_large", f"the shaped trajectory would end at {end:.10g} s, beyond the"
                         f" {MAX_TIME_S:.0f} s a builtin_interfaces/Duration holds")


@dataclass(frozen=True)
class SampledTrajectory:
    """A trajectory on a uniform grid: times (s) and (N, J) positions, velocities, accelerations."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


def resample(
    times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None, rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """Resample waypoints on the grid ``times[0] + k / rate`` up to and including the last time.

    Cubic Hermite interpolation where velocities are given for every waypoint, linear
    otherwise. The grid is extended to the next sample after the last waypoint, holding the
    final value there.
    """
    t = strictly_increasing("time_from_start", times)
    p = np.asarray(positions, dtype=float)
    if p.shape[0] != t.size:
        raise InputError("wrong_size", f"{p.shape[0]} points of positions for {t.size} times")
    dt = 1.0 / rate
    n = int(np.ceil((t[-1] - t[0]) * rate - 1e-9)) + 1
    grid = t[0] + dt * np.arange(n)
    grid_in = np.minimum(grid, t[-1])
    if t.size == 1:
        return grid, np.repeat(p[:1], n, axis=0)
    if velocities is not None:
        from scipy.interpolate import CubicHermiteSpline  # on first use: scipy.interpolate is 0.3 s of CPU at start

        spline = CubicHermiteSpline(t, p, np.asarray(velocities, dtype=float), axis=0)
        out = spline(grid_in)
    else:
        out = np.column_stack([np.interp(grid_in, t, p[:, j]) for j in range(p.shape[1])])
    out[-1] = p[-1]  # the grid's last point is the last waypoint (within 1e-9 samples): it ends there exactly
    return grid, out


def shape_trajectory(
    times: np.ndarray,
    positions: np.ndarray,
    fir: SparseFir,
    rate: float,
    velocities: np.ndarray | None = None,
    max_samples: int = MAX_TRAJECTORY_SAMPLES,
) -> SampledTrajectory:
    """Shape a whole trajectory.

    Parameters
    ----------
    times : (N,) array
        Waypoint times from the trajectory start, s, strictly increasing.
    positions : (N, J) array
        Waypoint positions (rad or m), finite.
    fir : SparseFir
        The discretised shaper at ``rate``.
    rate : float
        Command rate, Hz.
    velocities : (N, J) array, optional
        Waypoint velocities; if given, used for cubic Hermite resampling.
    max_samples : int
        Most samples of the shaped trajectory (refused before any work beyond it; at most
        :data:`MAX_TRAJECTORY_SAMPLES`).

    Returns
    -------
    SampledTrajectory
        Starting at ``times[0]``, ``fir.length`` samples longer than the resampled input plus
        one sample at rest, so the last point has zero velocity and acceleration.
    """
    p = finite_array("positions", positions)
    if p.ndim != 2:
        raise InputError("wrong_size", "positions must be an (N, J) array")
    check_extent(strictly_increasing("time_from_start", times), rate, fir.length, max_samples)
    if velocities is not None:
        velocities = finite_array("velocities", velocities, size=p.size).reshape(p.shape)
    grid, sampled = resample(times, p, velocities, rate)
    tail = fir.length  # long enough for the shaper to finish, plus one sample at rest
    held = np.vstack([sampled, np.repeat(sampled[-1:], tail, axis=0)])
    shaper = StreamingShaper(fir, p.shape[1])
    shaped = shaper.process(held)
    shaped[-1] = sampled[-1]
    dt = 1.0 / rate
    out_t = grid[0] + dt * np.arange(shaped.shape[0])
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, by name
        vel = np.gradient(shaped, dt, axis=0) if shaped.shape[0] > 1 else np.zeros_like(shaped)
        acc = np.gradient(vel, dt, axis=0) if shaped.shape[0] > 1 else np.zeros_like(shaped)
    vel[-1] = 0.0
    acc[-1] = 0.0
    for name, values in (("positions", shaped), ("velocities", vel), ("accelerations", acc)):
        if not np.all(np.isfinite(values)):  # finite input can still overflow here: nothing of it is passed on
            raise InputError("non_finite", f"the shaped trajectory's {name} are not finite: the input is too large"
                             " or too steep to pass on")
    return SampledTrajectory(out_t, shaped, vel, acc)
