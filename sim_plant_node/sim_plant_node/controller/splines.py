"""Joint trajectories sampled as joint_trajectory_controller samples them, free of ROS.

Between consecutive points each joint follows a polynomial chosen by the fields both points
have: positions only, linear (constant velocity, zero acceleration); positions and velocities,
cubic (Hermite); positions, velocities and accelerations, quintic. Before the first point the
trajectory runs from the state it started from (positions, velocities, accelerations of the
last command) to the first point by the same rule. After the last point it holds the last
point's positions, velocities and accelerations.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Point:
    """A trajectory point: time from the trajectory's start (s) and per-joint values (None: not given)."""

    time: float
    positions: np.ndarray
    velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None


def _coefficients(a: Point, b: Point, duration: float) -> np.ndarray:
    """Polynomial coefficients (6, n), lowest power first, of the segment a -> b over ``duration`` s."""
    t = duration
    pa, pb = a.positions, b.positions
    c = np.zeros((6, pa.size))
    c[0] = pa
    if t <= 0:
        return c
    if a.velocities is None or b.velocities is None:  # linear
        c[1] = (pb - pa) / t
        return c
    va, vb = a.velocities, b.velocities
    c[1] = va
    if a.accelerations is None or b.accelerations is None:  # cubic
        c[2] = (3 * (pb - pa) - (2 * va + vb) * t) / t**2
        c[3] = (2 * (pa - pb) + (va + vb) * t) / t**3
        return c
    aa, ab = a.accelerations, b.accelerations  # quintic
    c[2] = aa / 2
    c[3] = (20 * (pb - pa) - (8 * vb + 12 * va) * t - (3 * aa - ab) * t**2) / (2 * t**3)
    c[4] = (30 * (pa - pb) + (14 * vb + 16 * va) * t + (3 * aa - 2 * ab) * t**2) / (2 * t**4)
    c[5] = (12 * (pb - pa) - 6 * (vb + va) * t + (ab - aa) * t**2) / (2 * t**5)
    return c


_EXPONENTS = np.arange(6)
_DV = np.arange(1.0, 6.0)
_DA = np.array([2.0, 6.0, 12.0, 20.0])


def _stacked(c: np.ndarray) -> np.ndarray:
    """The segment's position, velocity and acceleration polynomials side by side, (6, 3 n), lowest power
    first: one product with the powers of s samples all three."""
    n = c.shape[1]
    out = np.zeros((6, 3 * n))
    out[:, :n] = c
    out[:5, n:2 * n] = _DV[:, None] * c[1:]
    out[:4, 2 * n:] = _DA[:, None] * c[2:]
    return out


def _evaluate(c: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    powers = s**_EXPONENTS
    return powers @ c, (_DV * powers[:5]) @ c[1:], (_DA * powers[:4]) @ c[2:]


class Trajectory:
    """A trajectory from ``start`` (the state when it took over), times from the trajectory's stamp.

    Parameters
    ----------
    start : Point
        Positions, velocities and accelerations when the trajectory takes over, at ``start.time``
        (negative when the trajectory's stamp lies in the future; before it the start state holds).
    points : list of Point
        The trajectory's points, times strictly increasing and >= 0.
    """

    def __init__(self, start: Point, points: list[Point]) -> None:
        if not points:
            raise ValueError("a trajectory needs at least one point")
        self.points = [start, *points]
        self._segments = [_coefficients(a, b, b.time - a.time)
                          for a, b in zip(self.points, self.points[1:], strict=False)]
        self._stacks = [_stacked(c) for c in self._segments]
        self.times = np.array([p.time for p in self.points])
        self._times = self.times.tolist()
        self._t0 = self._times[0]
        last = self.points[-1]
        n = last.positions.size
        self._hold = np.concatenate([last.positions, np.zeros(n) if last.velocities is None else last.velocities,
                                     np.zeros(n) if last.accelerations is None else last.accelerations])

    @property
    def end_time(self) -> float:
        """Time from start of the last point, s."""
        return float(self.times[-1])

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities, accelerations at ``t`` s after the start."""
        last = self.points[-1]
        if t >= last.time:
            n = last.positions.size
            return (last.positions.copy(),
                    np.zeros(n) if last.velocities is None else last.velocities.copy(),
                    np.zeros(n) if last.accelerations is None else last.accelerations.copy())
        t = max(t, float(self.times[0]))
        k = max(int(self.times.searchsorted(t, side="right")) - 1, 0)
        return _evaluate(self._segments[k], t - self.times[k])

    def sample_stacked(self, t: float) -> np.ndarray:
        """Positions, velocities and accelerations at ``t`` s after the start side by side, (3 n,): one product
        of the powers of the time into the segment with its three polynomials (:meth:`sample` to float rounding)."""
        times = self._times
        if t >= times[-1]:
            return self._hold.copy()
        t = max(t, self._t0)
        k = max(bisect.bisect_right(times, t) - 1, 0)
        return (t - times[k]) ** _EXPONENTS @ self._stacks[k]
