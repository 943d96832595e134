"""The shaper node's ``~/shaped_goals``: what each FollowJointTrajectory goal was shaped with (shaper_msgs/ShapedGoal).

One message per goal the node's proxy sends on to the controller, published just before it is sent: the goal's id
and acceptance stamp, how it was shaped (for its final pose by the scheduler, or with the active shaper as a
fallback, or with the active shaper as configured), the detail (the scheduler's summary, or why it fell back),
the move (its joints, first and last points) and the shaper (the scheduler's impulses, or the active shaper with
its source and revision). RELIABLE, TRANSIENT_LOCAL, depth 16 (``qos.SHAPED_GOALS_QOS``): a learner whose
subscription matches late still gets the goals of the cycles under way. The per-move learners read it
(:mod:`shaper_nodes.core.learning.goal_shaping`) and refuse to learn from a cycle whose goal fell back.
"""

from __future__ import annotations

from collections.abc import Callable

from action_msgs.msg import GoalInfo
from rclpy.action.server import ServerGoalHandle
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import ShapedGoal
from shaper_msgs.msg import Shaper as ShaperMsg

from .conversions import shaper_to_msg
from .pose_shaper import ACTIVE, Reshaped
from .qos import SHAPED_GOALS_QOS

__all__ = ["ShapedGoals", "shaped_goal_msg"]


def shaped_goal_msg(trajectory: JointTrajectory, info: GoalInfo, reshaped: Reshaped | None,
                    active: ShaperMsg) -> ShapedGoal:
    """The record of a goal whose request's trajectory is ``trajectory`` (the move), shaped as ``reshaped`` says
    (None: with the active shaper, the node having no scheduler), ``active`` being the active shaper's message."""
    how = reshaped if reshaped is not None else Reshaped(None, ACTIVE)
    points = trajectory.points
    msg = ShapedGoal(goal_info=info, shaped_with=how.shaped_with, detail=how.detail,
                     joint_names=list(trajectory.joint_names),
                     start_positions=[float(x) for x in points[0].positions] if points else [],
                     goal_positions=[float(x) for x in points[-1].positions] if points else [])
    msg.shaper = active if how.shaper is None else shaper_to_msg(how.shaper, "scheduler", 0)
    return msg


class ShapedGoals:
    """Publishes ``~/shaped_goals`` of ``node`` (module docstring); ``active`` gives the active shaper's message."""

    def __init__(self, node: Node, active: Callable[[], ShaperMsg]) -> None:
        self._node = node
        self._active = active
        self._pub = node.create_publisher(ShapedGoal, "~/shaped_goals", SHAPED_GOALS_QOS)
        self.topic_name = self._pub.topic_name

    def tell(self, handle: ServerGoalHandle, reshaped: Reshaped | None) -> None:
        """The proxy's ``on_sending``: the record of the goal of ``handle``, shaped as ``reshaped`` says."""
        # rclpy keeps the goal's GoalInfo (id and acceptance stamp) private; the id alone if it ever moves
        info = getattr(handle, "_goal_info", None)
        if not isinstance(info, GoalInfo):
            info = GoalInfo(goal_id=handle.goal_id)
        msg = shaped_goal_msg(handle.request.trajectory, info, reshaped, self._active())
        msg.header.stamp = self._node.get_clock().now().to_msg()
        self._pub.publish(msg)
