"""The shaper's FollowJointTrajectory action in front of a controller, over real DDS.

A test controller plays joint_trajectory_controller: it serves the real
control_msgs/action/FollowJointTrajectory interface, records each goal it receives, publishes a
few feedback messages, and then succeeds, aborts with a given error, or holds the goal until it
is cancelled or released. The shaper node, the controller and a client node share one
SingleThreadedExecutor (the shaper's own run_node spins the same way); one test runs the installed
shaper_node executable as a subprocess instead. With ``action.scheduler``, a scheduler node (the real
one, in the same executor, or a fake ``~/shaper_at`` server) gives the shaper for each goal's final
pose.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint, MultiDOFJointTrajectoryPoint

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict, triangular_partition
from shaper_nodes.core.shaping.families import Mode, design
from shaper_nodes.core.shaping.fir import discretize
from shaper_nodes.core.shaping.trajectory import shape_trajectory
from shaper_nodes.nodes.scheduler import SchedulerNode
from shaper_nodes.nodes.shaper import ShaperNode
from shaper_nodes.ros.action_client import ResilientActionClient
from shaper_nodes.ros.conversions import duration_to_sec, mode_msg
from shaper_nodes.ros.shaper_client import wait_for

pytestmark = pytest.mark.integration

JOINTS = ["j1", "j2", "j3"]
RATE = 100.0
CONTROLLER = "/joint_trajectory_controller/follow_joint_trajectory"
SERVER = "/shaper/follow_joint_trajectory"
Goal, Result = FollowJointTrajectory.Goal, FollowJointTrajectory.Result
FEEDBACK_PERIOD = 0.02  # s, the test controller's "control period"


class TestController:
    """Plays joint_trajectory_controller's action server.

    ``mode``: ``"succeed"``, ``"abort"`` (with ``abort_code``, ``abort_string``), or ``"hold"``
    (until the goal is cancelled or :meth:`release` d). ``accept=False`` rejects every goal.
    """

    __test__ = False  # not a pytest class

    def __init__(self, ctx, name: str = CONTROLLER, mode: str = "succeed", feedbacks: int = 3) -> None:
        self.node = rclpy.create_node("test_controller", context=ctx)
        self.mode, self.feedbacks, self.accept = mode, feedbacks, True
        self.abort_code, self.abort_string = Result.PATH_TOLERANCE_VIOLATED, "j2 path error 0.3 rad"
        self.goals: list[Goal] = []
        self.cancels = 0
        self._hold: dict[bytes, Future] = {}
        self.server = ActionServer(self.node, FollowJointTrajectory, name, execute_callback=self._execute,
                                   goal_callback=lambda _: GoalResponse.ACCEPT if self.accept else GoalResponse.REJECT,
                                   cancel_callback=self._on_cancel)

    def _on_cancel(self, handle) -> CancelResponse:
        self.cancels += 1
        self.release(handle)
        return CancelResponse.ACCEPT

    def release(self, handle=None) -> None:
        for key, fut in self._hold.items():
            if (handle is None or key == bytes(handle.goal_id.uuid)) and not fut.done():
                fut.set_result(None)

    async def _execute(self, handle) -> Result:
        goal = handle.request
        self.goals.append(goal)
        hold = Future()
        if self.mode == "hold":  # before any wait: a cancel may come at once
            self._hold[bytes(handle.goal_id.uuid)] = hold
        for k in range(self.feedbacks):
            # one feedback per control period, as joint_trajectory_controller sends them: the first one not
            # before the goal's acceptance can have reached the client (rclpy drops earlier feedback)
            await wait_for(self.node, Future(), FEEDBACK_PERIOD)
            fb = FollowJointTrajectory.Feedback(joint_names=list(goal.trajectory.joint_names))
            fb.desired = goal.trajectory.points[k]
            fb.actual = JointTrajectoryPoint(positions=[float(k)] * len(JOINTS))
            fb.error = JointTrajectoryPoint(positions=[0.001 * k] * len(JOINTS))
            fb.multi_dof_desired = MultiDOFJointTrajectoryPoint()
            handle.publish_feedback(fb)
        if self.mode == "hold":
            await hold
        if handle.is_cancel_requested:
            handle.canceled()
            return Result(error_code=Result.SUCCESSFUL, error_string="canceled at the controller")
        if self.mode == "abort":
            handle.abort()
            return Result(error_code=self.abort_code, error_string=self.abort_string)
        handle.succeed()
        return Result(error_code=Result.SUCCESSFUL, error_string="")

    def close(self) -> None:
        self.server.destroy()
        self.node.destroy_node()


class Client:
    """Our action client: one goal, its feedback, response and result."""

    def __init__(self, rig, goal: Goal) -> None:
        self.rig, self.feedback = rig, []
        self.sent = rig.client.send_goal_async(goal, feedback_callback=lambda m: self.feedback.append(m.feedback))
        rig.spin_until(self.sent.done, "goal response")
        self.handle = self.sent.result()
        self.result = self.handle.get_result_async() if self.handle.accepted else None

    @property
    def accepted(self) -> bool:
        return self.handle.accepted

    def wait_result(self):
        self.rig.spin_until(self.result.done, "result")
        res = self.result.result()
        return res.status, res.result


class Rig:
    """Shaper node, test controller and client node in one executor."""

    def __init__(self, ctx, controller: TestController | None, **params) -> None:
        overrides = [Parameter("joint_names", value=JOINTS), Parameter("command_rate", value=RATE),
                     Parameter("shaper.family", value="zv"), Parameter("shaper.frequency_hz", value=5.0),
                     Parameter("shaper.damping_ratio", value=0.0), Parameter("error_throttle", value=0.0)]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.node = ShaperNode(context=ctx, parameter_overrides=overrides)
        self.controller = controller
        self.probe = rclpy.create_node("probe", context=ctx)
        self.client = ResilientActionClient(self.probe, FollowJointTrajectory, SERVER)
        self.diag: list = []
        self.statuses: list = []  # every status, not only the input refusals
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.ex = SingleThreadedExecutor(context=ctx)
        for n in (self.node, self.probe) + ((controller.node,) if controller else ()):
            self.ex.add_node(n)
        self.spin_until(self.client.server_is_ready, "the shaper's action server")
        if controller:
            self.spin_until(self.node._action._client.server_is_ready, "the controller's action server")
        self.spin_until(lambda: self.probe.count_publishers("/diagnostics") > 0, "diagnostics publisher")

    def _on_diag(self, msg) -> None:
        self.diag += [s for s in msg.status if s.name.endswith(": input")]
        self.statuses += msg.status

    def spin_until(self, cond, what: str, timeout: float = 10.0) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def settle(self, seconds: float = 0.3) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)

    def send(self, goal: Goal) -> Client:
        return Client(self, goal)

    def close(self) -> None:
        self.ex.shutdown()
        self.client.destroy()
        self.node.destroy_node()
        self.probe.destroy_node()
        if self.controller:
            self.controller.close()


@pytest.fixture
def controller(ros_context):
    return TestController(ros_context)


@pytest.fixture
def rig(ros_context, controller):
    r = Rig(ros_context, controller)
    yield r
    r.close()


def trajectory(names=("j2", "j1", "j3"), points=((0.0, (0, 0, 0)), (0.5, (0.5, 1.0, 0.0)), (1.0, (1.0, 2.0, -1.0)))):
    msg = JointTrajectory(joint_names=list(names))
    for t, pos in points:
        msg.points.append(JointTrajectoryPoint(positions=[float(p) for p in pos], time_from_start=Duration(
            sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))))
    return msg


def goal_of(traj: JointTrajectory, **fields) -> Goal:
    return Goal(trajectory=traj, **fields)


def times_of(traj: JointTrajectory) -> np.ndarray:
    return np.array([duration_to_sec(p.time_from_start) for p in traj.points])


def assert_valid_for_jtc(traj: JointTrajectory) -> None:
    """What joint_trajectory_controller checks, plus finiteness (which it does not check)."""
    assert list(traj.joint_names) == JOINTS
    assert len(traj.points) > 1 and np.all(np.diff(times_of(traj)) > 0)
    for p in traj.points:
        assert len(p.positions) == len(p.velocities) == len(p.accelerations) == len(JOINTS) and not len(p.effort)
        assert np.all(np.isfinite([*p.positions, *p.velocities, *p.accelerations]))
    assert list(traj.points[-1].velocities) == [0.0] * len(JOINTS)


def test_goal_reaches_the_controller_shaped_and_the_result_and_feedback_come_back(rig, controller):
    tolerances = dict(path_tolerance=[JointTolerance(name="j1", position=0.1)],
                      goal_tolerance=[JointTolerance(name="j3", position=0.01, velocity=0.02)],
                      goal_time_tolerance=Duration(sec=0, nanosec=500_000_000))
    traj = trajectory()
    client = rig.send(goal_of(traj, **tolerances))
    assert client.accepted
    status, result = client.wait_result()
    assert status == GoalStatus.STATUS_SUCCEEDED and result.error_code == Result.SUCCESSFUL

    assert len(controller.goals) == 1
    sent = controller.goals[0]
    assert_valid_for_jtc(sent.trajectory)
    # The same as shaping the input with the core directly (joint order j1 j2 j3, zv at 5 Hz).
    fir = discretize(design("zv", [Mode.from_hz(5.0, 0.0)]), RATE, "split")
    positions = np.array([[p.positions[1], p.positions[0], p.positions[2]] for p in traj.points])
    expected = shape_trajectory(times_of(traj), positions, fir, RATE)
    np.testing.assert_allclose(times_of(sent.trajectory), expected.times, atol=1e-9)
    np.testing.assert_allclose([p.positions for p in sent.trajectory.points], expected.positions, atol=1e-12)
    np.testing.assert_allclose([p.velocities for p in sent.trajectory.points], expected.velocities, atol=1e-9)
    assert times_of(sent.trajectory)[-1] == pytest.approx(1.0 + 0.1 + 1 / RATE)  # + zv duration + 1 sample
    np.testing.assert_allclose(sent.trajectory.points[-1].positions, [2.0, 1.0, -1.0], atol=1e-12)
    # Tolerances and goal_time_tolerance unchanged; nothing multi-DOF.
    assert sent.path_tolerance == tolerances["path_tolerance"]
    assert sent.goal_tolerance == tolerances["goal_tolerance"]
    assert sent.goal_time_tolerance == tolerances["goal_time_tolerance"]
    assert not sent.multi_dof_trajectory.points

    rig.spin_until(lambda: len(client.feedback) == 3, "three relayed feedback messages")
    for k, fb in enumerate(client.feedback):
        assert fb.desired == sent.trajectory.points[k] and list(fb.actual.positions) == [float(k)] * 3
    assert rig.node.forwarded["action"] == 1


def late_start_warnings(rig) -> list:
    return [s for s in rig.statuses if s.name == "shaper: action" and "not 0" in s.message]


def test_a_goal_whose_first_point_is_after_time_0_is_forwarded_with_a_warning_that_its_start_is_not_shaped(
        rig, controller):
    status, _ = rig.send(goal_of(trajectory())).wait_result()  # from time 0: no warning
    assert status == GoalStatus.STATUS_SUCCEEDED
    one_point = trajectory(points=((1.5, (1.0, 2.0, -1.0)),))  # a goal typed by hand: the whole motion
    status, _ = rig.send(goal_of(one_point)).wait_result()
    assert status == GoalStatus.STATUS_SUCCEEDED and len(controller.goals) == 2
    rig.spin_until(lambda: late_start_warnings(rig), "the warning on /diagnostics")
    (warning,) = late_start_warnings(rig)  # the goal from time 0 gave none
    assert warning.level == DiagnosticStatus.WARN
    assert warning.message.startswith("goal's first point is at 1.500 s, not 0: the whole motion is the"
                                      " controller's interpolation from the robot's state and is not shaped")
    assert "send_goal --from-current" in warning.message


def test_controller_abort_is_relayed_with_its_error(rig, controller):
    controller.mode = "abort"
    status, result = rig.send(goal_of(trajectory())).wait_result()
    assert status == GoalStatus.STATUS_ABORTED
    assert result.error_code == Result.PATH_TOLERANCE_VIOLATED and result.error_string == "j2 path error 0.3 rad"


def test_cancel_reaches_the_controller_and_the_client_sees_canceled(rig, controller):
    controller.mode = "hold"
    client = rig.send(goal_of(trajectory()))
    rig.spin_until(lambda: controller.goals and len(client.feedback) == 3, "goal at the controller, feedback")
    cancel = client.handle.cancel_goal_async()
    rig.spin_until(cancel.done, "cancel response")
    assert len(cancel.result().goals_canceling) == 1
    status, result = client.wait_result()
    assert controller.cancels == 1
    assert status == GoalStatus.STATUS_CANCELED and result.error_string == "canceled at the controller"


def test_a_new_goal_preempts_the_running_one(rig, controller):
    controller.mode = "hold"
    first = rig.send(goal_of(trajectory()))
    rig.spin_until(lambda: len(controller.goals) == 1, "first goal at the controller")
    second = rig.send(goal_of(trajectory(points=((0.0, (1, 2, -1)), (0.4, (0, 0, 0))))))
    status, _ = first.wait_result()
    assert status == GoalStatus.STATUS_CANCELED and controller.cancels == 1
    rig.spin_until(lambda: len(controller.goals) == 2, "second goal at the controller")
    controller.release()
    status, _ = second.wait_result()
    assert status == GoalStatus.STATUS_SUCCEEDED
    np.testing.assert_allclose(controller.goals[1].trajectory.points[-1].positions, [0.0, 0.0, 0.0], atol=1e-12)


INVALID = [
    (trajectory(names=("j1", "j2", "jX")), {}, "unknown_joint", "unknown joint names ['jX']"),
    (trajectory(names=("j1", "j2")), {}, "missing_joint", "missing joint names ['j3']"),
    (trajectory(points=((0.0, (0, 0, 0)), (0.5, (0, math.nan, 0)))), {}, "non_finite", "non-finite"),
    (trajectory(points=((0.0, (0, 0, 0)), (0.5, (1, 1, 1)), (0.5, (2, 2, 2)))), {}, "non_increasing_time",
     "not strictly increasing"),
    (trajectory(points=((0.0, (0, 0)),)), {}, "wrong_size", "expected 3"),
    (JointTrajectory(joint_names=JOINTS), {}, "empty", "no points"),
    (trajectory(), {"path_tolerance": [JointTolerance(name="j1", position=math.inf)]}, "non_finite",
     "path_tolerance of joint 'j1'"),
]


@pytest.mark.parametrize("traj, fields, kind, words", INVALID)
def test_invalid_goal_is_rejected_with_a_reason_and_nothing_reaches_the_controller(rig, controller, traj, fields,
                                                                                    kind, words):
    client = rig.send(goal_of(traj, **fields))
    assert not client.accepted
    rig.spin_until(lambda: any(s.values[0].value == kind for s in rig.diag), f"diagnostic {kind}")
    status = next(s for s in rig.diag if s.values[0].value == kind)
    assert words in status.message and SERVER in status.message
    assert rig.node.rejections[kind] == 1
    rig.settle(0.2)
    assert controller.goals == []
    # the next valid goal goes through
    assert rig.send(goal_of(trajectory())).wait_result()[0] == GoalStatus.STATUS_SUCCEEDED


def test_multi_dof_goal_is_rejected(rig, controller):
    goal = goal_of(trajectory())
    goal.multi_dof_trajectory.joint_names = ["base"]
    assert not rig.send(goal).accepted
    rig.spin_until(lambda: any(s.values[0].value == "unsupported" for s in rig.diag), "diagnostic unsupported")
    assert controller.goals == []


def test_goal_rejected_by_the_controller_is_aborted_with_a_reason(rig, controller):
    controller.accept = False
    status, result = rig.send(goal_of(trajectory())).wait_result()
    assert status == GoalStatus.STATUS_ABORTED and result.error_code == Result.INVALID_GOAL
    assert "rejected" in result.error_string and CONTROLLER in result.error_string


def test_absent_controller_aborts_with_a_clear_reason(ros_context):
    rig = Rig(ros_context, None, **{"action.controller": "/nobody/follow_joint_trajectory",
                                    "action.server_timeout": 0.3})
    try:
        # the result comes (wait_result's wait is bounded) and says the node gave up after its
        # server_timeout; how long that took in wall time depends on the machine's load
        status, result = rig.send(goal_of(trajectory())).wait_result()
        assert status == GoalStatus.STATUS_ABORTED and result.error_code == Result.INVALID_GOAL
        assert result.error_string == ("controller action server /nobody/follow_joint_trajectory not available"
                                       " after 0.3 s; the goal was not sent")
    finally:
        rig.close()


def test_a_controller_whose_answer_never_comes_gets_the_goal_cancelled_by_its_id(ros_context):
    """The controller accepts and runs the goal but its answer and its status are lost on the way (as a
    response is at start-up under load, and a status with it): the shaper aborts its client's goal after
    ``action.server_timeout`` and cancels the goal at the controller by the id it sent it with, which the
    controller's cancel names; it is not left running there."""
    from test_action_client import LossyHandle

    controller = TestController(ros_context, mode="hold")
    controller.server._handle = LossyHandle(controller.server._handle, lose_goal=1 << 30, lose_status=True)
    rig = Rig(ros_context, controller, **{"action.server_timeout": 2.0})
    try:
        status, result = rig.send(goal_of(trajectory())).wait_result()
        assert status == GoalStatus.STATUS_ABORTED
        assert result.error_string == f"controller {CONTROLLER} did not answer the goal request within 2 s"
        rig.spin_until(lambda: controller.cancels == 1, "the cancel at the controller")
        assert len(controller.goals) == 1
    finally:
        rig.close()


def test_installed_shaper_node_forwards_goals(start_node, ros_context):
    shaper = start_node("shaper_nodes", "shaper_node", {"joint_names": JOINTS, "command_rate": RATE,
                                                          "shaper.family": "zvd", "shaper.frequency_hz": 4.0,
                                                          "shaper.damping_ratio": 0.0})
    controller = TestController(ros_context)
    probe = rclpy.create_node("probe", context=ros_context)
    client = ResilientActionClient(probe, FollowJointTrajectory, SERVER)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(controller.node)
    ex.add_node(probe)
    try:
        end = time.monotonic() + 30
        while not client.server_is_ready():
            assert time.monotonic() < end and shaper.running(), "shaper_node's action server did not appear"
            ex.spin_once(timeout_sec=0.05)
        sent = client.send_goal_async(goal_of(trajectory()))
        ex.spin_until_future_complete(sent, timeout_sec=10)
        assert sent.result().accepted
        result = sent.result().get_result_async()
        ex.spin_until_future_complete(result, timeout_sec=10)
        assert result.result().status == GoalStatus.STATUS_SUCCEEDED
        assert_valid_for_jtc(controller.goals[0].trajectory)
        assert times_of(controller.goals[0].trajectory)[-1] == pytest.approx(1.0 + 0.25 + 1 / RATE)  # zvd 4 Hz
    finally:
        ex.shutdown()
        client.destroy()
        probe.destroy_node()
        controller.close()


def test_cancel_before_the_goal_reached_the_controller(ros_context):
    rig = Rig(ros_context, None, **{"action.controller": "/nobody/follow_joint_trajectory",
                                    "action.server_timeout": 30.0})
    try:
        client = rig.send(goal_of(trajectory()))
        rig.settle(0.2)  # waiting for the absent controller
        cancel = client.handle.cancel_goal_async()
        status, result = client.wait_result()
        assert cancel.done() and len(cancel.result().goals_canceling) == 1
        assert status == GoalStatus.STATUS_CANCELED
        assert result.error_string == "canceled before it was sent to the controller"
    finally:
        rig.close()


# ------------------------------------------------------------------ shaping for the final pose (action.scheduler)
#: a rule base over j1 (rad): modes of 4, 6 and 8 Hz at j1 = 0, 1, 2 rad, interpolated directly
POSE_POINTS, POSE_HZ, POSE_ZETA = (0.0, 1.0, 2.0), (4.0, 6.0, 8.0), 0.02


def pose_rule_base() -> dict:
    rules = {}
    for k, (mf, hz) in enumerate(zip(triangular_partition(POSE_POINTS), POSE_HZ, strict=True)):
        rules[f"r{k}"] = {"membership": ["triangular"], "membership_params": [mf.a, mf.b, mf.c],
                          "natural_frequency": [2 * math.pi * hz], "damping_ratio": [POSE_ZETA]}
    return {"premises": ["j1"], "rules": rules}


def pose_scheduler(ctx) -> SchedulerNode:
    spec = pose_rule_base()
    params = {"premises": spec["premises"], "rule_names": list(spec["rules"]), "interpolation": "modes",
              "family": "zvd", "error_throttle": 0.0}
    for name, rule in spec["rules"].items():  # the node takes Hz where the core's spec has rad/s
        params.update({f"rules.{name}.{k}": v for k, v in rule.items() if k != "natural_frequency"})
        params[f"rules.{name}.frequency_hz"] = [w / (2 * math.pi) for w in rule["natural_frequency"]]
    return SchedulerNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def core_shaped(traj: JointTrajectory, shaper):
    """``traj`` (joints j2, j1, j3) shaped by the core with ``shaper``, in the node's order j1, j2, j3."""
    positions = np.array([[p.positions[1], p.positions[0], p.positions[2]] for p in traj.points])
    return shape_trajectory(times_of(traj), positions, discretize(shaper, RATE, "split"), RATE)


ACTIVE = design("zv", [Mode.from_hz(5.0, 0.0)])  # the Rig's active shaper
ENDS_AT_1_5 = trajectory(points=((0.0, (0, 0, 0)), (0.5, (0.5, 1.0, 0.0)), (1.0, (1.0, 1.5, -1.0))))  # j1 -> 1.5


def assert_forwarded_as(controller, k: int, expected) -> None:
    sent = controller.goals[k].trajectory
    assert_valid_for_jtc(sent)
    np.testing.assert_allclose(times_of(sent), expected.times, atol=1e-9)
    np.testing.assert_allclose([p.positions for p in sent.points], expected.positions, atol=1e-12)
    np.testing.assert_allclose([p.velocities for p in sent.points], expected.velocities, atol=1e-9)


def pose_warning(rig, words: str):
    return next((s for s in rig.statuses if s.name == "shaper: pose_shaper" and words in s.message), None)


def test_a_goal_is_shaped_for_the_modes_at_its_final_pose(ros_context, controller):
    rig = Rig(ros_context, controller, **{"action.scheduler": "/scheduler"})
    sched = pose_scheduler(ros_context)
    rig.ex.add_node(sched)
    try:
        rig.spin_until(rig.node.pose_shaper.service_is_ready, "the scheduler's shaper_at")
        status, _ = rig.send(goal_of(ENDS_AT_1_5)).wait_result()
        assert status == GoalStatus.STATUS_SUCCEEDED
        # the scheduler's shaper at j1 = 1.5 (the final point), from the core: zvd on the mode
        # interpolated halfway between 6 and 8 Hz
        _, at_end = Scheduler(rule_base_from_dict(pose_rule_base()), "modes", "zvd").at([1.5])
        assert at_end.family == "zvd" and at_end.modes[0].hz == pytest.approx(7.0, rel=1e-12)
        expected = core_shaped(ENDS_AT_1_5, at_end)
        assert_forwarded_as(controller, 0, expected)
        sent = times_of(controller.goals[0].trajectory)
        assert sent[-1] != pytest.approx(core_shaped(ENDS_AT_1_5, ACTIVE).times[-1], abs=1e-3)  # not the active one
        assert sent[-1] - 1.0 == pytest.approx(at_end.duration, abs=2 / RATE)  # longer by the zvd's duration
        assert (rig.node.pose_shaper.shaped, rig.node.pose_shaper.fallbacks) == (1, 0)
        # the active (streaming) shaper is not changed, and the scheduler sent nothing to the node
        assert rig.node.active_msg().revision == 1 and rig.node.active_msg().family == "zv"
        assert sched.sent == 0
    finally:
        sched.destroy_node()
        rig.close()


def test_without_the_scheduler_the_goal_is_shaped_with_the_active_shaper_and_a_warning_says_why(ros_context,
                                                                                                controller):
    rig = Rig(ros_context, controller, **{"action.scheduler": "/nobody", "action.server_timeout": 0.5})
    try:
        status, result = rig.send(goal_of(ENDS_AT_1_5)).wait_result()
        assert status == GoalStatus.STATUS_SUCCEEDED and result.error_code == Result.SUCCESSFUL
        assert_forwarded_as(controller, 0, core_shaped(ENDS_AT_1_5, ACTIVE))
        rig.spin_until(lambda: pose_warning(rig, "service /nobody/shaper_at not available within 0.5 s"),
                       "the warning on /diagnostics")
        warning = pose_warning(rig, "not available")
        assert warning.level == DiagnosticStatus.WARN
        assert warning.message.startswith("goal shaped with the active shaper, not for its final pose")
        assert (rig.node.pose_shaper.shaped, rig.node.pose_shaper.fallbacks) == (0, 1)
    finally:
        rig.close()


class FakeScheduler:
    """A ``/fake/shaper_at`` that answers as told: a response, or never (``None``)."""

    def __init__(self, ctx, response) -> None:
        self.node = rclpy.create_node("fake", context=ctx)
        self.response = response
        self.poses: list = []
        self._never = Future()
        self.node.create_service(ShaperAt, "~/shaper_at", self._on_request, callback_group=ReentrantCallbackGroup())

    async def _on_request(self, request, response):
        self.poses.append(request.pose)
        if self.response is None:
            await self._never
        return self.response


@pytest.mark.parametrize("answer, words", [
    (ShaperAt.Response(success=False, message="no rule fires at j1 = 1.5"),
     "/fake/shaper_at refused the final pose: no rule fires at j1 = 1.5"),
    (ShaperAt.Response(success=True, shaper=ShaperMsg(family="custom", amplitudes=[2.0, -1.0], times=[0.0, 0.1])),
     "is refused here: the impulses amplify: their gain sum |A| = 3 exceeds max_gain 1"),
    (ShaperAt.Response(success=True, shaper=ShaperMsg(family="zv", design_modes=[mode_msg(1000.0, 0.0)])),
     "is refused here: shaper duration 0.5 ms is shorter than one command period (10 ms)"),
    (ShaperAt.Response(success=True, shaper=ShaperMsg(family="zv", design_modes=[mode_msg(30.0, 0.0)])),
     "is refused here: design mode 30 Hz is too high for command_rate 100 Hz (must be below rate / 4 = 25 Hz)"),
    (ShaperAt.Response(success=True, shaper=ShaperMsg(family="custom", amplitudes=[1.0 / 1001] * 1001,
                                                      times=[k * 1e-3 for k in range(1001)])),
     "is refused here: 1001 impulses exceed the limit of 1000"),
    (None, "no answer from the scheduler: /fake/shaper_at did not answer within 0.5 s"),
], ids=["refused", "gain", "too_short", "above_rate_over_4", "too_many_impulses", "no_answer"])
def test_a_refused_pose_or_shaper_falls_back_to_the_active_shaper_with_a_warning(ros_context, controller, answer,
                                                                                  words):
    rig = Rig(ros_context, controller, **{"action.scheduler": "/fake", "action.server_timeout": 0.5})
    fake = FakeScheduler(ros_context, answer)
    rig.ex.add_node(fake.node)
    try:
        rig.spin_until(rig.node.pose_shaper.service_is_ready, "the fake shaper_at")
        status, _ = rig.send(goal_of(ENDS_AT_1_5)).wait_result()
        assert status == GoalStatus.STATUS_SUCCEEDED
        assert_forwarded_as(controller, 0, core_shaped(ENDS_AT_1_5, ACTIVE))
        rig.spin_until(lambda: pose_warning(rig, words), f"the warning {words!r}")
        # the request named the goal's joints and its final positions
        assert list(fake.poses[0].name) == ["j2", "j1", "j3"] and list(fake.poses[0].position) == [1.0, 1.5, -1.0]
        assert (rig.node.pose_shaper.shaped, rig.node.pose_shaper.fallbacks) == (0, 1)
    finally:
        fake.node.destroy_node()
        rig.close()
