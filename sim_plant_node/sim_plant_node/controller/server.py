"""joint_trajectory_controller's ROS interfaces in front of the simulated arm.

Serves ``control_msgs/action/FollowJointTrajectory`` and subscribes the ``JointTrajectory`` topic
as the controller does (names from the sim plant node's ``topics.jtc_action`` and
``topics.jtc_topic``), with the behaviour of :mod:`sim_plant_node.arm.jtc`. The node steps the
controller once per period (:meth:`ControllerServer.update`) and applies its command.

Where rclpy differs from rclcpp_action: a goal preempted by a new one cannot go from executing
to canceled without a cancel request in rclpy, so it ends **aborted** with the controller's
preemption result (INVALID_GOAL, "Current goal cancelled due to new incoming action.").
Feedback goes out at ``action_monitor_rate`` (20 Hz) of simulated time, as the controller's
monitor timer sends it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.qos import ACTION_QOS

from .jtc import (
    INVALID_GOAL,
    PREEMPT_TEXT,
    JointTrajectoryController,
    Outcome,
    RawPoint,
    Tolerances,
    TrajectoryRefused,
    goal_tolerances,
    validate,
)

ACTION_MONITOR_RATE = 20.0  # Hz, the controller's default
Result = FollowJointTrajectory.Result


def raw_points(msg: JointTrajectory) -> list[RawPoint]:
    """The message's points as plain values."""
    return [RawPoint(stamp_to_sec(p.time_from_start), list(p.positions), list(p.velocities), list(p.accelerations),
                     list(p.effort)) for p in msg.points]


class ControllerServer:
    """The action server and topic of the controller emulation, owned by the sim plant node.

    Parameters
    ----------
    node : Node
        The sim plant node (its executor runs the callbacks).
    controller : JointTrajectoryController
        The emulated controller.
    now : callable
        The node's time, s (simulated in lockstep).
    measured : callable
        Measured (position, velocity) of the joints, rad and rad/s.
    busy : callable
        Why the controller cannot take a trajectory now (a task drives the joints), or None.
    action, topic : str
        Names of the action and the trajectory topic.
    on_trajectory : callable, optional
        Called after the controller took a trajectory (from the action or the topic): the node steps from then on.
    before_feedback : callable, optional
        Called before each feedback message goes out (the node writes the periods' states it keeps first).
    """

    def __init__(self, node: Node, controller: JointTrajectoryController, now: Callable[[], float],
                 measured: Callable[[], tuple[np.ndarray, np.ndarray]], busy: Callable[[], str | None],
                 action: str, topic: str, on_trajectory: Callable[[], None] | None = None,
                 before_feedback: Callable[[], None] | None = None) -> None:
        self.node = node
        self._on_trajectory = on_trajectory
        self._before_feedback = before_feedback
        self.controller = controller
        self._now = now
        self._measured = measured
        self._busy = busy
        self._log = node.get_logger().get_child("joint_trajectory_controller")
        self._active: tuple[Any, Future] | None = None  # (goal handle, outcome future)
        self._futures: dict[bytes, Future] = {}  # goal id -> its outcome, until its execute callback takes it
        self._next_feedback = 0.0
        self.refused: list[str] = []  # the reasons of refused trajectories, newest last
        self.server = ActionServer(node, FollowJointTrajectory, action, execute_callback=self._execute,
                                   goal_callback=self._on_goal, handle_accepted_callback=self._on_accepted,
                                   cancel_callback=self._on_cancel, **ACTION_QOS)
        node.create_subscription(JointTrajectory, topic, self._on_topic, 10)

    # ------------------------------------------------------------------ validation
    def _check(self, msg: JointTrajectory) -> str | None:
        busy = self._busy()
        if busy is not None:
            return busy
        try:
            validate(self.controller.joints, list(msg.joint_names), raw_points(msg), stamp_to_sec(msg.header.stamp),
                     self._now())
        except TrajectoryRefused as err:
            return str(err)
        return None

    def _refuse(self, reason: str) -> None:
        self.refused.append(reason)
        del self.refused[:-20]
        self._log.error(reason)

    def _on_goal(self, goal: Any) -> GoalResponse:
        self._log.info("Received new action goal")
        reason = self._check(goal.trajectory)
        if reason is not None:
            self._refuse(reason)
            return GoalResponse.REJECT
        self._log.info("Accepted new action goal")
        return GoalResponse.ACCEPT

    def _on_topic(self, msg: JointTrajectory) -> None:
        reason = self._check(msg)
        if reason is not None:
            self._refuse(reason)
            return
        self.controller.accept(list(msg.joint_names), raw_points(msg), stamp_to_sec(msg.header.stamp))
        self._took()

    def _took(self) -> None:
        if self._on_trajectory is not None:
            self._on_trajectory()

    def _on_accepted(self, handle: Any) -> None:
        if self._active is not None:  # preemption
            self._active[1].set_result(Outcome("aborted", INVALID_GOAL, PREEMPT_TEXT))
            self._active = None
        goal = handle.request
        tolerances, problem = goal_tolerances(
            self.controller.defaults, self.controller.joints,
            [(t.name, t.position) for t in goal.path_tolerance], [(t.name, t.position) for t in goal.goal_tolerance],
            stamp_to_sec(goal.goal_time_tolerance))
        if problem is not None:
            self._log.error(problem)
        self.controller.accept(list(goal.trajectory.joint_names), raw_points(goal.trajectory),
                               stamp_to_sec(goal.trajectory.header.stamp))
        self.controller.start_goal(tolerances)
        self._active = (handle, Future())
        self._futures[bytes(handle.goal_id.uuid)] = self._active[1]
        self._next_feedback = self._now()
        handle.execute()
        self._took()

    def _on_cancel(self, handle: Any) -> CancelResponse:
        self._log.info("Got request to cancel goal")
        if self._active is not None and bytes(self._active[0].goal_id.uuid) == bytes(handle.goal_id.uuid):
            self._log.info("Canceling active action goal because cancel callback received.")
            self._finish(Outcome("canceled", 0, ""))
            self.controller.hold(self._measured()[0])
        return CancelResponse.ACCEPT

    async def _execute(self, handle: Any) -> Any:
        future = self._futures.pop(bytes(handle.goal_id.uuid), None)
        outcome = await future if future is not None else Outcome("aborted", INVALID_GOAL, PREEMPT_TEXT)
        if outcome.status == "succeeded":
            handle.succeed()
            self._log.info("Goal reached, success!")
        elif outcome.status == "canceled" and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
            if outcome.code != INVALID_GOAL:
                self._log.warning(outcome.text)
        return Result(error_code=outcome.code, error_string=outcome.text)

    def _finish(self, outcome: Outcome) -> None:
        if self._active is not None:
            self._active[1].set_result(outcome)
            self._active = None
        self.controller.end_goal()

    # ------------------------------------------------------------------ stepping
    def update(self, t: float) -> None:
        """One controller period at time ``t``: new command, goal outcome, feedback."""
        position, velocity = self._measured()
        outcome = self.controller.update(t, position, velocity)
        if outcome is not None:
            self._finish(outcome)
        elif self._active is not None and t >= self._next_feedback:
            self._next_feedback = t + 1.0 / ACTION_MONITOR_RATE
            self._feedback(t, position, velocity)

    def _feedback(self, t: float, position: np.ndarray, velocity: np.ndarray) -> None:
        assert self._active is not None
        c = self.controller
        fb = FollowJointTrajectory.Feedback(joint_names=list(c.joints))
        fb.header.stamp = sec_to_time(t)
        fb.desired = JointTrajectoryPoint(positions=c.desired[0].tolist(), velocities=c.desired[1].tolist(),
                                          accelerations=c.desired[2].tolist())
        fb.actual = JointTrajectoryPoint(positions=position.tolist(), velocities=velocity.tolist())
        fb.error = JointTrajectoryPoint(positions=c.error.tolist(), velocities=(c.desired[1] - velocity).tolist())
        if self._before_feedback is not None:
            self._before_feedback()
        self._active[0].publish_feedback(fb)

    @property
    def running(self) -> bool:
        """A trajectory is executing or a goal waits for its outcome."""
        return self.controller.running or self._active is not None

    def close(self) -> None:
        self.server.destroy()


def tolerances_from(joints: tuple[str, ...], trajectory: list[float], goal: list[float], goal_time: float
                    ) -> Tolerances:
    """The default tolerances from the node's parameters (one value for all joints or one per joint)."""
    n = len(joints)

    def per_joint(values: list[float], name: str) -> np.ndarray:
        v = np.asarray(values, dtype=float).ravel()
        if v.size == 1:
            v = np.full(n, v[0])
        if v.size != n or not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ValueError(f"{name} needs 1 or {n} finite values >= 0 (rad, 0: unchecked), got {list(values)}")
        return v

    if not (np.isfinite(goal_time) and goal_time >= 0):
        raise ValueError(f"controller.constraints.goal_time must be finite and >= 0 s, got {goal_time!r}")
    return Tolerances(per_joint(trajectory, "controller.constraints.trajectory"),
                      per_joint(goal, "controller.constraints.goal"), float(goal_time))
