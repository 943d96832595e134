"""The arm demo's pick-and-place cycle and its MoveIt-like time parametrisation, free of ROS.

Poses (rad, the UR joint order): HOME at mid reach; PICK reached out in front (elbow opened,
the lowest mode lowest); ROTATED, HOME turned 1.2 rad about the base; PLACE folded in over
there (elbow closed, the lowest mode highest). The cycle: HOME -> PICK -> HOME -> ROTATED ->
PLACE -> ROTATED -> HOME, reaching out and in and turning, as a pick-and-place cell does.

Each move is time-parametrised as MoveIt's time-optimal parametrisation does for a straight
joint-space path: every joint on the same trapezoidal velocity profile (the one with the
largest travel at the velocity and acceleration limits, the others scaled), waypoints every
``step`` s with positions, velocities and accelerations; the acceleration jumps at the corners
of the trapezoid, as it does in such trajectories.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

HOME = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
PICK = np.array([0.0, -1.0, 0.5, -1.07, -1.57, 0.0])
ROTATED = np.array([1.2, -1.57, 1.57, -1.57, -1.57, 0.0])
PLACE = np.array([1.2, -1.9, 2.4, -2.07, -1.57, 0.0])
CYCLE = (("home", HOME), ("rotated", ROTATED), ("place", PLACE), ("rotated", ROTATED), ("home", HOME),
         ("pick", PICK), ("home", HOME))
#: joint velocity and acceleration limits of the moves, rad/s and rad/s^2
MAX_VELOCITY = 1.5
MAX_ACCELERATION = 6.0


@dataclass(frozen=True)
class Move:
    """A time-parametrised joint-space move: waypoint times (s) and (N, 6) positions, velocities, accelerations."""

    name: str
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def trapezoid_move(name: str, start: np.ndarray, goal: np.ndarray, max_velocity: float = MAX_VELOCITY,
                   max_acceleration: float = MAX_ACCELERATION, step: float = 0.01) -> Move:
    """The move from ``start`` to ``goal`` on a synchronised trapezoidal profile (module docstring)."""
    d = np.asarray(goal, dtype=float) - np.asarray(start, dtype=float)
    dist = float(np.max(np.abs(d)))
    if not dist > 0:
        raise ValueError(f"move {name!r} does not move")
    ta = max_velocity / max_acceleration
    if dist < max_velocity * ta:  # triangular
        ta = math.sqrt(dist / max_acceleration)
        total, v = 2 * ta, max_acceleration * ta
    else:
        total, v = dist / max_velocity + ta, max_velocity
    t = np.arange(0.0, total, step)
    t = np.append(t, total) if total - t[-1] > 1e-9 else np.append(t[:-1], total)
    s = np.where(t < ta, 0.5 * max_acceleration * t**2,
                 np.where(t <= total - ta, 0.5 * max_acceleration * ta**2 + v * (t - ta),
                          dist - 0.5 * max_acceleration * (total - t) ** 2))
    sd = np.where(t < ta, max_acceleration * t, np.where(t <= total - ta, v, max_acceleration * (total - t)))
    sdd = np.where(t < ta, max_acceleration, np.where(t <= total - ta, 0.0, -max_acceleration))
    sd[-1] = sdd[-1] = 0.0
    u = d / dist
    return Move(name, t, start + np.outer(s, u), np.outer(sd, u), np.outer(sdd, u))


def cycle_moves() -> list[Move]:
    """The pick-and-place cycle's moves, named ``from->to``."""
    return [trapezoid_move(f"{a}->{b}", pa, pb) for (a, pa), (b, pb) in itertools.pairwise(CYCLE)]


def goal_points(move: Move, dwell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The trajectory goal the demo's client sends for ``move``: times (s from the start), (N, 6) positions, velocities,
    accelerations. Its first point is the move's start at time 0, as a planner's (MoveIt's) is the robot's present
    state at time 0: a shaper node in front of the controller shapes the motion from there (the controller's own
    interpolation from the measured state to a first point later than 0 is not shaped, docs/guide/robot.md); then
    the move's waypoints, and the goal again ``dwell`` s after the motion, at rest. The controller replaces the
    point at time 0 with the measured state (:mod:`sim_plant_node.controller.jtc`)."""
    times = np.append(move.times, move.duration + float(dwell))
    positions = np.vstack([move.positions, move.positions[-1]])
    velocities = np.vstack([move.velocities, np.zeros(move.positions.shape[1])])
    accelerations = np.vstack([move.accelerations, np.zeros(move.positions.shape[1])])
    return times, positions, velocities, accelerations


def time_scaled(move: Move, factor: float) -> Move:
    """``move`` run ``factor`` times faster on the same path: times / factor, velocities x factor,
    accelerations x factor^2 (factor > 1 speeds up; 1 returns the move as it is).

    Raises
    ------
    ValueError
        ``factor`` not finite and > 0.
    """
    s = float(factor)
    if not (math.isfinite(s) and s > 0.0):
        raise ValueError(f"time-scaling factor must be finite and > 0, got {factor!r}")
    if s == 1.0:
        return move
    return Move(move.name, move.times / s, move.positions.copy(), move.velocities * s, move.accelerations * s * s)
