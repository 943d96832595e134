"""An emulation of joint_trajectory_controller (ros2_controllers, Jazzy), free of ROS.

What it follows (the controller's documented and coded behaviour, Jazzy 4.x), for a robot with
position command interfaces and position and velocity state interfaces (as ur_robot_driver):

- **Validation** of every trajectory, from the action or the topic, in the controller's order
  and with its texts: all controller joints named (``allow_partial_joints_goal`` false), names
  not empty, points not empty, a non-zero stamp whose trajectory ends in the past, unknown
  joints, non-zero final velocity (``allow_nonzero_velocity_at_trajectory_end`` false),
  strictly increasing ``time_from_start``, field sizes, efforts (not supported). A refused goal
  is rejected (no result: the action's codes INVALID_JOINTS and OLD_HEADER_TIMESTAMP are not
  used by the controller). This emulation also refuses non-finite values, which the controller
  does not check, with the same kind of message.
- **Sampling** at the update rate: the error and feedback from the sample at ``time``, the
  command from the sample at ``time + period``; splines by the fields given
  (:mod:`.splines`), the first segment from the state at the trajectory's first update (the
  measured positions and velocities); a zero stamp starts at the first update.
- **Tolerances**: per joint, 0 unchecked; path tolerances while the trajectory runs, goal
  tolerances past its end; ``goal_time_tolerance`` 0 waits for the goal tolerance indefinitely.
  Per-goal values: > 0 replaces the default, -1 erases it, 0 keeps it, any other negative
  value or an unknown joint falls back to the defaults for the whole goal. With position
  commands the velocity error is not computed (the controller computes it only with velocity
  or effort commands), so only position tolerances act.
- **Outcomes**: success (0, "Goal successfully reached!") keeps commanding the last point;
  path violation (-4, "Aborted due to path tolerance violation") and goal time exceeded (-5,
  "Aborted due to goal_time_tolerance exceeding by X seconds") hold the measured position; a
  cancel holds the measured position; a new goal preempts the active one (-1, "Current goal
  cancelled due to new incoming action."). A topic trajectory replaces the trajectory without
  ending an active goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .splines import Point, Trajectory

SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
OLD_HEADER_TIMESTAMP = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
SUCCESS_TEXT = "Goal successfully reached!"
PATH_TEXT = "Aborted due to path tolerance violation"
PREEMPT_TEXT = "Current goal cancelled due to new incoming action."
FLT_EPSILON = 1.1920929e-07


class TrajectoryRefused(ValueError):
    """A trajectory the controller refuses; the message is the controller's log text."""


@dataclass
class RawPoint:
    """A trajectory point as the message has it (empty lists for fields not given)."""

    time: float
    positions: list[float]
    velocities: list[float] = field(default_factory=list)
    accelerations: list[float] = field(default_factory=list)
    effort: list[float] = field(default_factory=list)


@dataclass
class Outcome:
    """How an action goal ended: ``status`` 'succeeded', 'aborted' or 'canceled', error code and text."""

    status: str
    code: int
    text: str


@dataclass
class Tolerances:
    """Per-joint position tolerances (rad, 0 unchecked) on the path and at the goal, and the goal time (s)."""

    path: np.ndarray
    goal: np.ndarray
    goal_time: float = 0.0


def validate(joints: tuple[str, ...], names: list[str], points: list[RawPoint], stamp: float, now: float) -> None:
    """Refuse what joint_trajectory_controller refuses, in its order, with its log texts.

    Raises
    ------
    TrajectoryRefused
    """
    if len(names) != len(joints):
        raise TrajectoryRefused("Joints on incoming trajectory don't match the controller joints.")
    if not names:
        raise TrajectoryRefused("Empty joint names on incoming trajectory.")
    if not points:
        raise TrajectoryRefused("Empty trajectory received.")
    if stamp != 0.0 and stamp + points[-1].time < now:
        raise TrajectoryRefused(f"Received trajectory with non-zero start time ({stamp:f}) that ends in the past "
                                f"({stamp + points[-1].time:f})")
    for name in names:
        if name not in joints:
            raise TrajectoryRefused(f"Incoming joint {name} doesn't match the controller's joints.")
    for name, v in zip(names, points[-1].velocities, strict=False):
        if not abs(v) <= FLT_EPSILON:
            raise TrajectoryRefused(f"Velocity of last trajectory point of joint {name} is not zero: {v:.15f}")
    _validate_points(names, points)
    if not (math.isfinite(stamp) and all(math.isfinite(p.time) and p.time >= 0 for p in points)):
        raise TrajectoryRefused("Non-finite or negative time in the trajectory.")


def _validate_points(names: list[str], points: list[RawPoint]) -> None:
    """The per-point checks of :func:`validate`: times strictly increasing, field sizes, finite, no effort."""
    for i, p in enumerate(points):
        if i > 0 and not p.time > points[i - 1].time:
            raise TrajectoryRefused(f"Time between points {i - 1} and {i} is not strictly increasing, it is "
                                    f"{points[i - 1].time:f} and {p.time:f} respectively")
        for what in ("positions", "velocities", "accelerations"):
            values = getattr(p, what)
            if (what == "positions" or values) and len(values) != len(names):
                raise TrajectoryRefused(f"Mismatch between joint_names size ({len(names)}) and {what} "
                                        f"({len(values)}) at point #{i}.")
            if not all(math.isfinite(x) for x in values):
                raise TrajectoryRefused(f"Non-finite {what} at point #{i} (the controller would pass it on; "
                                        "this emulation refuses it).")
        if p.effort:
            raise TrajectoryRefused("Trajectories with effort fields are currently not supported.")


def goal_tolerances(defaults: Tolerances, joints: tuple[str, ...], path: list[tuple[str, float]],
                    goal: list[tuple[str, float]], goal_time: float) -> tuple[Tolerances, str | None]:
    """The tolerances of one goal from its (joint, position tolerance) lists; a problem falls back to the defaults.

    Returns the tolerances and the controller's error text when it fell back (None otherwise).
    """
    out = Tolerances(defaults.path.copy(), defaults.goal.copy(), defaults.goal_time)
    for field_name, entries, target in (("path_tolerance", path, out.path), ("goal_tolerance", goal, out.goal)):
        for name, value in entries:
            if name not in joints:
                return defaults, (f"joint '{name}' specified in goal.{field_name} does not exist. "
                                  "Using default tolerances.")
            if value == -1.0:
                target[joints.index(name)] = 0.0
            elif value > 0:
                target[joints.index(name)] = value
            elif value != 0.0:
                return defaults, f"{field_name} for joint '{name}' is {value}: using default tolerances."
    if goal_time > 0:
        out.goal_time = goal_time
    elif goal_time == -1.0:
        out.goal_time = 0.0
    elif goal_time != 0.0:
        return defaults, f"Specified illegal goal_time_tolerance: {goal_time:f}. Using default tolerances"
    return out, None


class JointTrajectoryController:
    """The controller's state between updates (module docstring).

    Parameters
    ----------
    joints : tuple of str
        The controller's joints, in its order.
    period : float
        Update period, s (1 / update rate).
    defaults : Tolerances
        The parameters' tolerances (``constraints.<joint>.trajectory``/``.goal``, ``constraints.goal_time``).
    position : array_like
        The position held at start.
    """

    def __init__(self, joints: tuple[str, ...], period: float, defaults: Tolerances, position: Any) -> None:
        self.joints = tuple(joints)
        self.period = float(period)
        self.defaults = defaults
        self.tolerances = defaults
        self.command = np.asarray(position, dtype=float).copy()
        self.command_velocity = np.zeros(len(joints))
        self._points: list[Point] | None = None  # a new trajectory, waiting for its first update
        self._stamp = 0.0
        self.trajectory: Trajectory | None = None
        self.start_time = 0.0
        self.holding = True
        self.goal_active = False
        self.desired = (self.command.copy(), np.zeros(len(joints)), np.zeros(len(joints)))
        self.error = np.zeros(len(joints))
        self._ahead: tuple[float, Trajectory | None, Any] = (math.nan, None, None)  # the last update's later sample

    # ------------------------------------------------------------------ inputs
    def accept(self, names: list[str], points: list[RawPoint], stamp: float) -> None:
        """Take a validated trajectory (action or topic); it starts at its first update."""
        order = [names.index(j) for j in self.joints]
        pick = lambda values: None if not values else np.asarray(values, dtype=float)[order]  # noqa: E731
        self._points = [Point(p.time, pick(p.positions), pick(p.velocities), pick(p.accelerations))  # type: ignore[arg-type]
                        for p in points]
        self._stamp = stamp

    def start_goal(self, tolerances: Tolerances) -> None:
        """An action goal now owns the trajectory: its tolerances apply until it ends."""
        self.goal_active = True
        self.tolerances = tolerances

    def hold(self, position: Any) -> None:
        """Hold ``position`` (after a cancel or an abort): a one-point trajectory at time 0."""
        self._points = None
        self.trajectory = None
        self.holding = True
        self.command = np.asarray(position, dtype=float).copy()
        self.command_velocity = np.zeros(len(self.joints))

    def end_goal(self) -> None:
        self.goal_active = False

    @property
    def running(self) -> bool:
        """A trajectory is being executed (or waits for its first update)."""
        return self._points is not None or (self.trajectory is not None and not self.holding)

    # ------------------------------------------------------------------ update
    def update(self, time: float, position: np.ndarray, velocity: np.ndarray) -> Outcome | None:
        """One control period at ``time``: new command (``self.command``) and the goal's outcome, if it ends now."""
        if self._points is not None:
            self.start_time = time if self._stamp == 0.0 else self._stamp
            first = Point(time - self.start_time, np.asarray(position, dtype=float).copy(),
                          np.asarray(velocity, dtype=float).copy())
            ahead = [p for p in self._points if p.time > first.time] or self._points[-1:]  # a past stamp skips points
            self.trajectory = Trajectory(first, ahead)
            self._points = None
            self.holding = False
            first_sample = True
        else:
            first_sample = False
        if self.trajectory is None or self.holding:
            return None
        t = time - self.start_time
        n = len(self.joints)
        t_next = t + self.period
        kept_t, kept_trajectory, kept = self._ahead
        # the sample at t is the last update's at its t + period when the times meet to the bit: the same product,
        # taken rather than computed again (read only, as every sample here)
        now = kept if kept_t == t and kept_trajectory is self.trajectory else self.trajectory.sample_stacked(t)
        nxt = self.trajectory.sample_stacked(t_next)
        self._ahead = (t_next, self.trajectory, nxt)
        self.desired = (now[:n], now[n:2 * n], now[2 * n:])
        self.error = now[:n] - np.asarray(position, dtype=float)
        before_last = t_next < self.trajectory.end_time
        tol = self.tolerances
        if (before_last or first_sample) and _violates(self.error, tol.path):
            self.hold(position)
            return Outcome("aborted", PATH_TOLERANCE_VIOLATED, PATH_TEXT) if self.goal_active else None
        self.command, self.command_velocity = nxt[:n], nxt[n:2 * n]
        if before_last:
            return None
        late = t - self.trajectory.end_time
        if not _violates(self.error, tol.goal):
            self.holding = True  # keeps commanding the last point
            return Outcome("succeeded", SUCCESSFUL, SUCCESS_TEXT) if self.goal_active else None
        if tol.goal_time > 0 and late > tol.goal_time:
            self.hold(position)
            return (Outcome("aborted", GOAL_TOLERANCE_VIOLATED,
                            f"Aborted due to goal_time_tolerance exceeding by {late:f} seconds")
                    if self.goal_active else None)
        return None


def _violates(error: np.ndarray, tolerance: np.ndarray) -> bool:
    """Whether a checked joint (tolerance > 0 rad; 0: unchecked) has an error beyond its tolerance (none set:
    False at once)."""
    if not tolerance.any():
        return False
    return bool(((tolerance > 0) & (np.abs(error) > tolerance)).any())  # (the method: no dispatch wrapper)
