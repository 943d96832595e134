"""The repeated point-to-point task of the 1-D plants, free of ROS (:class:`CycleTask`): moves between two poses
on a trapezoidal (or step, or ramp) profile, a dwell after each, and the cycle events at the samples they happen
(START, MOTION_END, END as shaper_msgs/CycleEvent); handed on by :mod:`.plants`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START

__all__ = ["PROFILES", "CycleTask", "TaskEvent", "check_task", "trapezoid", "trapezoid_fraction"]


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


#: the move profiles of :class:`CycleTask`
PROFILES = ("trapezoid", "step", "ramp")


def check_task(*, max_velocity: float = 1.0, max_acceleration: float = 1.0, dwell: float = 0.0, rate: float = 1.0,
               cycles: int = 1, profile: str = "trapezoid") -> None:
    """:class:`CycleTask`'s checks of its settings (one alone: the others keep valid defaults)."""
    if not (max_velocity > 0 and max_acceleration > 0 and dwell >= 0 and rate > 0 and cycles >= 1):
        raise ValueError("task needs max_velocity > 0, max_acceleration > 0, dwell >= 0, cycles >= 1")
    if profile not in PROFILES:
        raise ValueError(f"task profile must be one of {', '.join(PROFILES)}; got {profile!r}")


class CycleTask:
    """Repeated point-to-point moves between two poses with a dwell after each.

    Cycle i moves from ``poses[i % 2]`` to ``poses[(i + 1) % 2]``; with ``round_trip`` every
    cycle goes from the start pose to the goal, dwells, comes back and dwells again, so that
    all cycles are the same (what iterative learning needs). Every step of the task gives
    the command for that sample and the cycle events that happen at it: START with the first
    sample of a cycle, MOTION_END with the sample where the command reaches the cycle's last
    target, END with the last dwell sample.

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
    profile : str
        'trapezoid' (trapezoidal velocity within the limits), 'step' (the command jumps to the
        target at the first sample of the move) or 'ramp' (constant velocity ``max_velocity``,
        ``max_acceleration`` unused).
    round_trip : bool
        Every cycle is start -> goal -> start (see above).
    """

    def __init__(self, start, goal, max_velocity: float, max_acceleration: float, dwell: float,
                 rate: float, cycles: int, profile: str = "trapezoid", round_trip: bool = False) -> None:
        self.start = np.asarray(start, dtype=float).ravel()
        self.goal = np.asarray(goal, dtype=float).ravel()
        if self.start.shape != self.goal.shape:
            raise ValueError("start and goal poses differ in size")
        check_task(max_velocity=max_velocity, max_acceleration=max_acceleration, dwell=dwell, rate=rate,
                   cycles=cycles, profile=profile)
        dist = float(np.max(np.abs(self.goal - self.start)))
        self.profile, self.round_trip = profile, bool(round_trip)
        if profile == "trapezoid":
            self.move_duration, ta = trapezoid(dist, max_velocity, max_acceleration)
        else:  # step: no duration; ramp: no acceleration phase
            self.move_duration, ta = (0.0 if profile == "step" else dist / max_velocity), 0.0
        self.rate = float(rate)
        self.move_samples = int(math.ceil(self.move_duration * rate - 1e-9))
        leg = self.move_samples + 1 + int(round(dwell * rate))  # one move and its dwell
        s = trapezoid_fraction(np.arange(leg) / rate, self.move_duration, ta)
        self._s = np.concatenate([s, 1.0 - s]) if self.round_trip else s
        self.samples_per_cycle = self._s.size
        self.motion_end_sample = self.samples_per_cycle - leg + self.move_samples
        self.cycles = int(cycles)
        self.index = 0

    @property
    def done(self) -> bool:
        return self.index >= self.cycles * self.samples_per_cycle

    def pose(self, cycle: int) -> tuple[np.ndarray, np.ndarray]:
        """(start, goal) of a cycle."""
        return (self.start, self.goal) if cycle % 2 == 0 or self.round_trip else (self.goal, self.start)

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
        if k == self.motion_end_sample:
            events.append(TaskEvent(MOTION_END, cycle, a, b))
        if k == self.samples_per_cycle - 1:
            events.append(TaskEvent(END, cycle, a, b))
        self.index += 1
        return command, events
