"""Simulated plants and tasks, free of ROS.

MckPlant
    Flexible joints, one m-c-k system per joint (seeds 000 and 002): the joint (base) position
    x1 is commanded, the tip x2 follows through a spring k and damper c with mass m,
        m x2'' = k (x1 - x2) + c (x1' - x2'),   x2 / x1 = (c s + k) / (m s^2 + c s + k).
    Between samples the base moves linearly from the previous command to the new one (a
    first-order hold, as an interpolating position controller does), and the plant is
    integrated exactly over each period with the matrix exponential of the system augmented
    with the base position and its (constant) slope. The tip acceleration is x2''.
CycleTask
    A repeated point-to-point task with a trapezoidal velocity profile, alternating between
    two poses, with a dwell after every move for the residual vibration to show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm


def mck_from_mode(omega: float, zeta: float, mass: float = 1.0) -> tuple[float, float, float]:
    """Mass (kg), damping (N s/m) and stiffness (N/m) of an m-c-k system with this mode."""
    k = mass * omega**2
    return mass, 2.0 * zeta * math.sqrt(k * mass), k


class MckPlant:
    """Per-joint m-c-k flexible joints integrated exactly under a first-order-hold base motion.

    Parameters
    ----------
    mass, damping, stiffness : array_like
        Per joint, kg, N s/m and N/m (or the rotational equivalents), all > 0 (damping >= 0).
    rate : float
        Integration (command) rate, Hz.
    """

    def __init__(self, mass, damping, stiffness, rate: float) -> None:
        m = np.atleast_1d(np.asarray(mass, dtype=float))
        c = np.atleast_1d(np.asarray(damping, dtype=float))
        k = np.atleast_1d(np.asarray(stiffness, dtype=float))
        if not (m.shape == c.shape == k.shape):
            raise ValueError(f"mass, damping, stiffness sizes differ: {m.size}, {c.size}, {k.size}")
        if not (np.all(np.isfinite(m)) and np.all(np.isfinite(c)) and np.all(np.isfinite(k))):
            raise ValueError("plant parameters must be finite")
        if np.any(m <= 0) or np.any(k <= 0) or np.any(c < 0):
            raise ValueError("plant parameters need mass > 0, stiffness > 0, damping >= 0")
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
        self.m, self.c, self.k = m, c, k
        self.rate = float(rate)
        self.dt = 1.0 / self.rate
        self.joints = m.size
        self._phi = np.stack([self._transition(*p) for p in zip(m, c, k)])
        # state per joint: x2, v2, x1, r (base slope)
        self.state = np.zeros((self.joints, 4))

    def _transition(self, m: float, c: float, k: float) -> np.ndarray:
        a = np.array(
            [
                [0.0, 1.0, 0.0, 0.0],
                [-k / m, -c / m, k / m, c / m],
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, 0.0, 0.0],
            ]
        )
        return expm(a * self.dt)

    @property
    def natural_frequency(self) -> np.ndarray:
        """Undamped natural frequency of each joint's mode, rad/s."""
        return np.sqrt(self.k / self.m)

    @property
    def damping_ratio(self) -> np.ndarray:
        """Damping ratio of each joint's mode."""
        return self.c / (2.0 * np.sqrt(self.k * self.m))

    def reset(self, position) -> None:
        """Put every joint at rest: base and tip at ``position``, no motion."""
        p = np.broadcast_to(np.asarray(position, dtype=float), (self.joints,))
        self.state = np.column_stack([p, np.zeros(self.joints), p, np.zeros(self.joints)])

    def step(self, command) -> None:
        """Advance one period while the base moves linearly to ``command``."""
        u = np.asarray(command, dtype=float).reshape(self.joints)
        self.state[:, 3] = (u - self.state[:, 2]) / self.dt
        self.state = np.einsum("jab,jb->ja", self._phi, self.state)
        self.state[:, 2] = u  # exact by construction; removes round-off drift

    @property
    def base_position(self) -> np.ndarray:
        return self.state[:, 2].copy()

    @property
    def base_velocity(self) -> np.ndarray:
        return self.state[:, 3].copy()

    @property
    def tip_position(self) -> np.ndarray:
        return self.state[:, 0].copy()

    @property
    def tip_velocity(self) -> np.ndarray:
        return self.state[:, 1].copy()

    @property
    def tip_acceleration(self) -> np.ndarray:
        """x2'' at the end of the last period (left limit), m/s^2 or rad/s^2."""
        x2, v2, x1, r = self.state.T
        return (self.k * (x1 - x2) + self.c * (r - v2)) / self.m


def trapezoid(distance: float, max_velocity: float, max_acceleration: float) -> tuple[float, float]:
    """Duration (s) and acceleration time (s) of a rest-to-rest trapezoidal move."""
    d = abs(distance)
    if d == 0.0:
        return 0.0, 0.0
    ta = max_velocity / max_acceleration
    if d >= max_velocity * ta:
        return d / max_velocity + ta, ta
    ta = math.sqrt(d / max_acceleration)
    return 2.0 * ta, ta


def trapezoid_fraction(t: np.ndarray, duration: float, ta: float) -> np.ndarray:
    """Normalised position s(t) in [0, 1] of a trapezoidal move."""
    t = np.clip(np.asarray(t, dtype=float), 0.0, duration)
    if duration == 0.0:
        return np.ones_like(t)
    tc = duration - 2.0 * ta
    vpk = 1.0 / (ta + tc)  # normalised peak velocity
    acc = vpk / ta if ta > 0 else 0.0
    s = np.where(
        t < ta,
        0.5 * acc * t**2,
        np.where(
            t <= ta + tc,
            0.5 * acc * ta**2 + vpk * (t - ta),
            1.0 - 0.5 * acc * (duration - t) ** 2,
        ),
    )
    return np.clip(s, 0.0, 1.0)


@dataclass(frozen=True)
class TaskEvent:
    """A cycle boundary: kind 0 START, 1 MOTION_END, 2 END (as shaper_msgs/CycleEvent)."""

    kind: int
    cycle: int
    start: np.ndarray
    goal: np.ndarray


START, MOTION_END, END = 0, 1, 2


class CycleTask:
    """Repeated point-to-point moves between two poses with a dwell after each.

    Cycle i moves from ``poses[i % 2]`` to ``poses[(i + 1) % 2]``. Every step of the task gives
    the command for that sample and the cycle events that happen at it: START with the first
    sample of a cycle, MOTION_END with the sample where the command reaches the goal, END with
    the last dwell sample.

    Parameters
    ----------
    start, goal : array_like
        The two poses (rad or m), one value per joint.
    max_velocity, max_acceleration : float
        Limits of the largest joint move, rad/s and rad/s^2 (or m/s, m/s^2); the other joints
        move in proportion so that all arrive together.
    dwell : float
        Time after each move, s.
    rate : float
        Command rate, Hz.
    cycles : int
        Number of cycles.
    """

    def __init__(self, start, goal, max_velocity: float, max_acceleration: float, dwell: float,
                 rate: float, cycles: int) -> None:
        self.start = np.asarray(start, dtype=float).ravel()
        self.goal = np.asarray(goal, dtype=float).ravel()
        if self.start.shape != self.goal.shape:
            raise ValueError("start and goal poses differ in size")
        if not (max_velocity > 0 and max_acceleration > 0 and dwell >= 0 and rate > 0 and cycles >= 1):
            raise ValueError("task needs max_velocity > 0, max_acceleration > 0, dwell >= 0, cycles >= 1")
        dist = float(np.max(np.abs(self.goal - self.start)))
        self.move_duration, ta = trapezoid(dist, max_velocity, max_acceleration)
        self.rate = float(rate)
        self.move_samples = int(math.ceil(self.move_duration * rate - 1e-9))
        self.samples_per_cycle = self.move_samples + 1 + int(round(dwell * rate))
        k = np.arange(self.samples_per_cycle)
        self._s = trapezoid_fraction(k / rate, self.move_duration, ta)
        self.cycles = int(cycles)
        self.index = 0

    @property
    def done(self) -> bool:
        return self.index >= self.cycles * self.samples_per_cycle

    def pose(self, cycle: int) -> tuple[np.ndarray, np.ndarray]:
        """(start, goal) of a cycle."""
        return (self.start, self.goal) if cycle % 2 == 0 else (self.goal, self.start)

    def step(self) -> tuple[np.ndarray, list[TaskEvent]]:
        """The command for the next sample and the events at it."""
        if self.done:
            raise RuntimeError("task is done")
        cycle, k = divmod(self.index, self.samples_per_cycle)
        a, b = self.pose(cycle)
        command = a + (b - a) * self._s[k]
        events = []
        if k == 0:
            events.append(TaskEvent(START, cycle, a, b))
        if k == self.move_samples:
            events.append(TaskEvent(MOTION_END, cycle, a, b))
        if k == self.samples_per_cycle - 1:
            events.append(TaskEvent(END, cycle, a, b))
        self.index += 1
        return command, events
