"""The simulated arm behind the joint_trajectory_controller emulation, over its real interfaces.

The sim plant node runs ``plant.model: arm`` in lockstep; a client speaks
``control_msgs/action/FollowJointTrajectory`` and the ``JointTrajectory`` topic to it as MoveIt
would, and reads ``/joint_states`` and the flange ``sensor_msgs/Imu``.
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
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.ros.action_client import ResilientActionClient
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import STREAM_QOS
from sim_plant_node.arm.description import JOINT_NAMES

ACTION = "/joint_trajectory_controller/follow_joint_trajectory"
TOPIC = "/joint_trajectory_controller/joint_trajectory"
HOME = [0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0]
Goal, Result = FollowJointTrajectory.Goal, FollowJointTrajectory.Result


def duration(t: float) -> Duration:
    return Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))


def point(t: float, positions, velocities=None, **fields) -> JointTrajectoryPoint:
    p = JointTrajectoryPoint(positions=[float(x) for x in positions], time_from_start=duration(t))
    if velocities is not None:
        p.velocities = [float(v) for v in velocities]
    for name, value in fields.items():
        setattr(p, name, value)
    return p


def move(target, seconds: float = 1.0, hold: float = 0.5, names=JOINT_NAMES) -> JointTrajectory:
    """A move to ``target`` with zero velocity at both points, then a hold (the residual window)."""
    return JointTrajectory(joint_names=list(names), points=[point(seconds, target, [0.0] * 6),
                                                            point(seconds + hold, target, [0.0] * 6)])


class Client:
    """A MoveIt-like client: action client, trajectory publisher, joint state and IMU readers."""

    def __init__(self, ctx) -> None:
        self.node = rclpy.create_node("arm_client", context=ctx)
        self.action = ResilientActionClient(self.node, FollowJointTrajectory, ACTION)
        self.topic = self.node.create_publisher(JointTrajectory, TOPIC, 10)
        self.states: list[JointState] = []
        self.imu: list[Imu] = []
        # as deep as the lockstep plant's writer (a client 100 behind it dropped the move's joint states and kept the
        # idle ones, every 0.1 s of wall time at rest with the same stamp)
        self.node.create_subscription(JointState, "/joint_states", self.states.append, STREAM_QOS)
        self.node.create_subscription(Imu, "/tip_imu", self.imu.append, qos_profile_sensor_data)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)

    def spin_until(self, cond, what: str, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def wait_ready(self, sim) -> None:
        self.spin_until(lambda: self.action.server_is_ready() or not sim.running(), "the controller's action server")
        assert sim.running(), "the sim plant node exited"

    def send(self, goal: Goal, feedback=None):
        future = self.action.send_goal_async(goal, feedback_callback=feedback)
        self.spin_until(future.done, "the goal response")
        return future.result()

    def result(self, handle):
        future = handle.get_result_async()
        self.spin_until(future.done, "the result")
        return future.result()

    def position(self) -> np.ndarray:
        return np.array(self.states[-1].position)

    def close(self) -> None:
        self.ex.shutdown()
        self.action.destroy()
        self.node.destroy_node()


@pytest.fixture
def arm(start_node, ros_context):
    sim = start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME})
    client = Client(ros_context)
    client.wait_ready(sim)
    yield sim, client
    client.close()


def _log_has(sim, text: str) -> bool:
    return text in sim.log_path.read_text(errors="replace")


BAD = {
    "too few joints": (lambda t: t.joint_names.pop(),
                       "Joints on incoming trajectory don't match the controller joints."),
    "no points": (lambda t: t.points.clear(), "Empty trajectory received."),
    "ended in the past": (lambda t: setattr(t.header, "stamp", sec_to_time(1e-3)),
                          "that ends in the past"),
    "unknown joint": (lambda t: t.joint_names.__setitem__(5, "gripper_joint"),
                      "Incoming joint gripper_joint doesn't match the controller's joints."),
    "moving at the end": (lambda t: t.points[-1].velocities.__setitem__(2, 0.2),
                          "Velocity of last trajectory point of joint elbow_joint is not zero: 0.200000000000000"),
    "time not increasing": (lambda t: setattr(t.points[1], "time_from_start", duration(1.0)),
                            "Time between points 0 and 1 is not strictly increasing, it is 1.000000 and 1.000000"),
    "positions size": (lambda t: t.points[0].positions.pop(),
                       "Mismatch between joint_names size (6) and positions (5) at point #0."),
    "velocities size": (lambda t: t.points[1].velocities.pop(),
                        "Mismatch between joint_names size (6) and velocities (5) at point #1."),
    "effort": (lambda t: setattr(t.points[0], "effort", [1.0] * 6),
               "Trajectories with effort fields are currently not supported."),
    "not finite": (lambda t: t.points[0].positions.__setitem__(1, float("nan")), "Non-finite positions at point #0"),
}


def test_invalid_goals_are_rejected_with_the_controllers_reasons(arm):
    """Each class of invalid goal is rejected (no result), the reason logged in the controller's words."""
    sim, client = arm
    # 2 s of simulated time pass, so that a stamp of 1 ms ends in the past
    assert client.result(client.send(Goal(trajectory=move(HOME, 1.0, 1.0)))).status == GoalStatus.STATUS_SUCCEEDED
    for name, (spoil, reason) in BAD.items():
        traj = move(HOME)
        traj.joint_names = list(traj.joint_names)
        spoil(traj)
        handle = client.send(Goal(trajectory=traj))
        assert not handle.accepted, name
        client.spin_until(lambda r=reason: _log_has(sim, r), f"the log of the refusal '{name}'", timeout=30)
    # what the controller would accept still is
    handle = client.send(Goal(trajectory=move(HOME, 0.2, 0.1)))
    assert handle.accepted
    assert client.result(handle).status == GoalStatus.STATUS_SUCCEEDED


def test_valid_goal_reaches_its_goal_tolerance_with_feedback(arm):
    _sim, client = arm
    target = [0.4, -1.3, 1.2, -1.4, -1.57, 0.3]
    goal = Goal(trajectory=move(target, 1.5, 1.0),
                goal_tolerance=[JointTolerance(name=j, position=0.002) for j in JOINT_NAMES],
                goal_time_tolerance=duration(2.0))
    feedback = []
    handle = client.send(goal, feedback.append)
    assert handle.accepted
    res = client.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED
    assert (res.result.error_code, res.result.error_string) == (Result.SUCCESSFUL, "Goal successfully reached!")
    client.spin_until(lambda: np.all(np.abs(client.position() - target) < 0.002), "joint states at the goal")
    # 20 Hz of simulated time over 2.5 s. The client takes one feedback message per wake-up of its executor, so a
    # plant in lockstep may send its result while most of the feedback still waits in the client's queue (1000 deep):
    # wait for it (a state, not a time; the server that sends fewer than 20 fails here as it failed the count)
    client.spin_until(lambda: len(feedback) >= 20, "20 feedback messages (20 Hz of simulated time over 2.5 s)")
    fb = feedback[-1].feedback
    assert list(fb.joint_names) == list(JOINT_NAMES) and len(fb.actual.positions) == 6
    # the IMU felt the move: specific force with gravity, and something on top of it during the move
    norms = np.array([math.dist((0, 0, 0), (m.linear_acceleration.x, m.linear_acceleration.y,
                                            m.linear_acceleration.z)) for m in client.imu])
    assert np.median(norms) == pytest.approx(9.81, rel=0.05)
    assert norms.max() > 9.9


def test_path_tolerance_violation_aborts_and_holds(arm):
    _sim, client = arm
    goal = Goal(trajectory=move([0.5, *HOME[1:]], 0.3, 0.2),
                path_tolerance=[JointTolerance(name=j, position=1e-5) for j in JOINT_NAMES])
    res = client.result(client.send(goal))
    assert res.status == GoalStatus.STATUS_ABORTED
    assert (res.result.error_code, res.result.error_string) == (Result.PATH_TOLERANCE_VIOLATED,
                                                               "Aborted due to path tolerance violation")


def test_goal_time_exceeded_aborts_with_the_overshoot(arm):
    _sim, client = arm
    goal = Goal(trajectory=move([0.3, *HOME[1:]], 0.3, 0.02),
                goal_tolerance=[JointTolerance(name=j, position=1e-9) for j in JOINT_NAMES],
                goal_time_tolerance=duration(0.05))
    res = client.result(client.send(goal))
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.error_code == Result.GOAL_TOLERANCE_VIOLATED
    assert res.result.error_string.startswith("Aborted due to goal_time_tolerance exceeding by 0.05")


def test_a_new_goal_preempts_the_running_one(arm):
    _sim, client = arm
    first = client.send(Goal(trajectory=move([1.0, *HOME[1:]], 30.0, 1.0)))
    assert first.accepted
    client.spin_until(lambda: len(client.states) > 10, "the first goal to run")
    target = [0.2, *HOME[1:]]
    second = client.send(Goal(trajectory=move(target, 0.5, 0.3)))
    assert second.accepted
    res1 = client.result(first)
    assert res1.status == GoalStatus.STATUS_ABORTED  # rclpy: no canceled without a cancel request
    assert (res1.result.error_code, res1.result.error_string) == (
        Result.INVALID_GOAL, "Current goal cancelled due to new incoming action.")
    assert client.result(second).status == GoalStatus.STATUS_SUCCEEDED
    client.spin_until(lambda: abs(client.position()[0] - 0.2) < 1e-3, "the second goal's pose")


def test_cancel_holds_where_the_arm_is(arm):
    _sim, client = arm
    handle = client.send(Goal(trajectory=move([1.0, *HOME[1:]], 20.0, 1.0)))
    client.spin_until(lambda: len(client.states) > 50, "the goal to run")
    cancel = handle.cancel_goal_async()
    client.spin_until(cancel.done, "the cancel response")
    res = client.result(handle)
    assert res.status == GoalStatus.STATUS_CANCELED
    reached = max(m.position[0] for m in client.states)
    assert 0.0 < reached < 0.5  # it moved, and stopped on the way, far from the goal


def test_trajectory_topic_moves_the_arm(arm):
    _sim, client = arm
    client.spin_until(lambda: client.node.count_subscribers(TOPIC) > 0, "the controller's trajectory subscription")
    target = [-0.3, -1.4, 1.4, -1.5, -1.57, 0.0]
    client.topic.publish(move(target, 0.5, 0.2))
    client.spin_until(lambda: client.states and np.all(np.abs(client.position() - target) < 1e-3),
                      "joint states at the topic trajectory's end")


def test_joint_states_as_encoders_report_them(start_node, ros_context):
    """Motor-side positions quantised to the encoder's resolution, velocities and torques, at 500 Hz."""
    sim = start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME,
                                                     "joint_states.resolution": 1e-3,
                                                     "joint_states.noise_stddev": 2e-4})
    client = Client(ros_context)
    try:
        client.wait_ready(sim)
        res = client.result(client.send(Goal(trajectory=move([0.3, *HOME[1:]], 0.5, 0.2))))
        assert res.status == GoalStatus.STATUS_SUCCEEDED
        client.spin_until(lambda: len(client.states) >= 300, "the joint states of the move")
        positions = np.array([m.position for m in client.states])
        np.testing.assert_allclose(positions / 1e-3, np.round(positions / 1e-3), atol=1e-6)
        assert len(np.unique(positions[:, 0])) > 10  # it moved, in steps of the resolution
        m = client.states[-1]
        assert list(m.name) == list(JOINT_NAMES) and len(m.velocity) == 6 and len(m.effort) == 6
        stamps = np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in client.states])
        assert np.median(np.diff(np.sort(stamps))) == pytest.approx(1 / 500.0)
        assert abs(m.effort[1]) > 10.0  # the shoulder holds the arm against gravity, N m
    finally:
        client.close()
