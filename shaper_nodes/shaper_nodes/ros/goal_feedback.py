# Copyright 2026 The ros2 vibration suppression authors
# SPDX-License-Identifier: Apache-2.0
"""The feedback of chosen goals, read on a subscription of the caller's own (:class:`GoalFeedback`).

rclpy's action client drops a goal's feedback once its result is handled; a caller that needs it (calibrate: the
controller's time at the goal's start) follows the goal here, beside the action client of
:mod:`~shaper_nodes.ros.action_client` (which hands this name on).
"""

from __future__ import annotations

from typing import Any


class GoalFeedback:
    """The header stamps of the feedback of chosen goals, kept after their results arrive.

    rclpy's :class:`~rclpy.action.ActionClient` drops a goal's feedback callback as soon as the goal's
    result response is handled, and hands feedback over one message per executor wake-up: a client
    whose executor is busy (a batch of samples) can be handed the result of a short goal before any of
    its feedback, which is then discarded. A caller that needs a goal's feedback, e.g. the controller's
    time at the goal's start (the first feedback's stamp), reads it here instead: a subscription of its
    own to the action's feedback topic (``<action>/_action/feedback``, the action's interface), on the
    deep :data:`~shaper_nodes.ros.qos.FEEDBACK_QOS` queue, which keeps every stamp of the goals it
    follows until :meth:`forget`.

    Parameters
    ----------
    node : rclpy Node
        The client's node (its executor takes the feedback).
    action_type : action class
        The action's type (its feedback carries a ``header``, as FollowJointTrajectory's does).
    action_name : str
        The action's name, e.g. ``/joint_trajectory_controller/follow_joint_trajectory``.
    """

    def __init__(self, node: Any, action_type: Any, action_name: str) -> None:
        from .qos import FEEDBACK_QOS

        self._stamps: dict[bytes, list[float]] = {}
        # raw: only the goal id and the stamp are read (recordings.cdr.goal_feedback_stamp), not the whole
        # feedback (three trajectory points and the joint names) built as a message, which rclpy's action client
        # does once already for every feedback it takes
        self._sub = node.create_subscription(action_type.Impl.FeedbackMessage,
                                             action_name.rstrip("/") + "/_action/feedback", self._on_feedback,
                                             FEEDBACK_QOS, raw=True)

    def _on_feedback(self, raw: bytes) -> None:
        from shaper_nodes.recordings.cdr import goal_feedback_stamp

        goal, stamp = goal_feedback_stamp(raw)
        stamps = self._stamps.get(goal)
        if stamps is not None:
            stamps.append(stamp)

    def new_goal(self) -> tuple[Any, list[float]]:
        """A new goal id (a unique_identifier_msgs/UUID, to give ``send_goal_async`` as ``goal_uuid``) whose
        stamps are kept from now on, and the list they are appended to, in arrival order."""
        import uuid

        from unique_identifier_msgs.msg import UUID

        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        return goal_id, self._stamps.setdefault(bytes(goal_id.uuid), [])

    def forget(self, goal_id: Any) -> None:
        """Stop keeping goal ``goal_id``'s stamps."""
        self._stamps.pop(bytes(goal_id.uuid), None)
