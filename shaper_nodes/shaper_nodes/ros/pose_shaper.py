"""A whole trajectory shaped for the modes at its final pose, by the scheduler's ``~/shaper_at``.

For a point-to-point move the residual vibration is that of the modes at the pose where the move
ends, so a whole trajectory (a FollowJointTrajectory goal) is best shaped for them, not for the
pose the robot is at when the goal arrives. The shaper node's parameter ``action.scheduler``
names a scheduler node; :class:`PoseShaperClient` then, for each goal:

1. asks ``<scheduler>/shaper_at`` (shaper_msgs/ShaperAt) for the shaper at the trajectory's final
   point (its joint names and the last point's positions), naming the move by its first point
   (``start``: the scheduler applies a per-move learned correction to it), waiting at most ``timeout`` s of wall
   time for the service and its reply together;
2. checks the answer as the shaper node checks any shaper: a family design is designed again from
   its family, modes and parameters (as the shaper node designs the scheduler's ``set_shaper``
   requests), a custom one (the learner's corrected ZV) is taken as its impulses within the
   node's gain bound ``shaper.max_gain``; at most ``MAX_IMPULSES`` impulses; not shorter than one
   command period;
3. shapes the trajectory with it, through the node's one whole-trajectory path (the same
   validation as every goal).

If any step fails (scheduler absent, no answer in time, pose refused, shaper refused, shaped goal
invalid) the goal keeps the trajectory shaped with the active shaper, and a warning on the log and
``/diagnostics`` (kind ``pose_shaper``) says why. The active shaper is never changed here. Either way the
answer (:class:`Reshaped`) says what the goal was shaped with, and why, for the node's ``~/shaped_goals``
(shaper_msgs/ShapedGoal: the per-move learners refuse a cycle whose goal fell back).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import ShapedGoal
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.shaping import Shaper, ShaperError
from shaper_nodes.core.shaping.policy import PolicyError, check_design

from .conversions import shaper_from_msg
from .diagnostics import WARN, Diagnostics
from .shaper_client import ServiceClient

#: shaper_msgs/ShapedGoal's ways a goal was shaped
SCHEDULED, FALLBACK, ACTIVE = ShapedGoal.SCHEDULED, ShapedGoal.FALLBACK, ShapedGoal.ACTIVE


@dataclass(frozen=True)
class Reshaped:
    """What a goal was shaped with: ``trajectory`` shaped for its final pose (None: the one shaped with the active
    shaper at its request stays), ``shaped_with`` (:data:`SCHEDULED`, :data:`FALLBACK`, :data:`ACTIVE`), ``detail``
    (the scheduler's summary, or why it fell back) and the scheduler's ``shaper`` (None: the active one)."""

    trajectory: JointTrajectory | None
    shaped_with: int
    detail: str = ""
    shaper: Shaper | None = None


@dataclass(frozen=True)
class PoseAnswer:
    """The shaper for a pose, or None and why not; ``message`` is the scheduler's summary."""

    shaper: Shaper | None
    message: str


def final_pose(trajectory: JointTrajectory) -> JointState:
    """The trajectory's final point as a pose: its joint names and the last point's positions."""
    last = trajectory.points[-1].positions if trajectory.points else []
    return JointState(name=list(trajectory.joint_names), position=[float(x) for x in last])


def first_pose(trajectory: JointTrajectory) -> JointState:
    """The trajectory's first point as a pose (the move's start, for ``ShaperAt.start``)."""
    first = trajectory.points[0].positions if trajectory.points else []
    return JointState(name=list(trajectory.joint_names), position=[float(x) for x in first])


class PoseShaperClient:
    """Shapes whole trajectories for their final pose with a scheduler's shaper (module docstring).

    Parameters
    ----------
    node : Node
        The shaper node.
    scheduler : str
        Fully qualified name of the scheduler node (``/scheduler``).
    timeout : float
        Longest wait for the scheduler's service and its reply together, s (wall time).
    shape : callable
        ``(JointTrajectory, Shaper) -> JointTrajectory``: the node's whole-trajectory shaping with
        an explicit shaper; raises ``ValueError`` (``InputError``, ``ShaperError``) when it cannot.
    diagnostics : Diagnostics
        Where fallbacks are reported (WARN, kind ``pose_shaper``).
    max_gain : callable returning float
        The node's gain bound for custom shapers (read at each goal: a dynamic parameter).
    rate : float
        The node's command rate, Hz.
    """

    def __init__(self, node: Node, scheduler: str, timeout: float,
                 shape: Callable[[JointTrajectory, Shaper], JointTrajectory], diagnostics: Diagnostics, *,
                 max_gain: Callable[[], float], rate: float) -> None:
        self._log = node.get_logger().get_child("action_scheduler")
        self._client = ServiceClient(node, ShaperAt, f"{scheduler.rstrip('/')}/shaper_at", float(timeout))
        self._timeout = float(timeout)
        self._shape = shape
        self._diagnostics = diagnostics
        self._max_gain = max_gain
        self._rate = float(rate)
        self.shaped = 0     # goals shaped with the scheduler's shaper
        self.fallbacks = 0  # goals shaped with the active shaper instead

    @property
    def srv_name(self) -> str:
        return self._client.srv_name

    def service_is_ready(self) -> bool:
        return self._client.service_is_ready()

    def destroy(self) -> None:
        self._client.destroy()

    async def shaper_at(self, pose: JointState, start: JointState | None = None) -> PoseAnswer:
        """The scheduler's shaper for ``pose`` (of the move from ``start``, if given), checked as this node
        checks shapers (or None, why)."""
        req = ShaperAt.Request(pose=pose) if start is None else ShaperAt.Request(pose=pose, start=start)
        answer = await self._client.call(req, self._timeout, total=True)
        if answer.response is None:
            return PoseAnswer(None, f"no answer from the scheduler: {answer.error}")
        resp = answer.response
        if not resp.success:
            return PoseAnswer(None, f"{self.srv_name} refused the final pose: {resp.message}")
        msg = copy.deepcopy(resp.shaper)
        family = msg.family.strip().lower()
        if family not in ("", "custom"):  # a family design: designed here, as a scheduled set_shaper is
            msg.amplitudes, msg.times = [], []
        try:
            shaper = shaper_from_msg(msg, self._max_gain())
            check_design(shaper, self._rate)  # the check every path that sets a shaper makes
        except (ShaperError, PolicyError, ValueError) as err:
            return PoseAnswer(None, f"the shaper of {self.srv_name} ({resp.shaper.family}) is refused here: {err}")
        except Exception as err:  # a design that fails otherwise: the goal falls back, the node runs on
            return PoseAnswer(None, f"the shaper of {self.srv_name} ({resp.shaper.family}) failed to design here:"
                                    f" {type(err).__name__}: {err}")
        return PoseAnswer(shaper, resp.message)

    async def __call__(self, trajectory: JointTrajectory) -> Reshaped:
        """``trajectory`` shaped for its final pose, or no trajectory (then the caller keeps the trajectory
        shaped with the active shaper; the reason has been reported, and is in the answer's ``detail``)."""
        answer = await self.shaper_at(final_pose(trajectory), first_pose(trajectory))
        why = answer.message
        if answer.shaper is not None:
            try:
                shaped = self._shape(trajectory, answer.shaper)
            except ValueError as err:
                why = f"the goal shaped with the shaper of {self.srv_name} is refused: {err}"
            else:
                self.shaped += 1
                s = answer.shaper
                self._log.info(f"goal shaped for its final pose: {len(s)} impulses, {s.duration * 1e3:.1f} ms"
                               f" ({answer.message})")
                return Reshaped(shaped, SCHEDULED, answer.message, s)
        self.fallbacks += 1
        self._diagnostics.report("pose_shaper", WARN, f"goal shaped with the active shaper, not for its final"
                                 f" pose: {why}", values=[("service", self.srv_name)])
        return Reshaped(None, FALLBACK, why)
