"""The arm's payload changed at run time over DDS, as a robot owner changes it (``ros2 param set``).

The sim plant node runs ``plant.model: arm`` in lockstep. A client excites the arm at the home pose
through the controller's ``FollowJointTrajectory`` (a small quick move, then a hold), reads the
flange IMU's free decay and identifies its lowest mode with the suite's identification; then it sets
``arm.payload_mass`` through the node's parameter service and does the same again. Physics says: a
heavier payload at the tool lowers the lowest mode, to where modal analysis of the arm with that
payload puts it; out-of-range payloads are refused with a reason and change nothing.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from conftest import call_answered
from control_msgs.action import FollowJointTrajectory
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.identification import identify
from shaper_nodes.ros.conversions import time_to_sec
from sim_plant_node.arm.description import JOINT_NAMES, ArmSpec
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.modal import lowest

HOME = [0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0]
#: the excitation: shoulder_lift and elbow 10 mrad in 0.1 s, then a hold whose free decay is identified
STEP = np.array([0.0, 0.01, 0.01, 0.0, 0.0, 0.0])
MOVE, HOLD, SKIP = 0.1, 2.5, 0.3  # s: the move, the hold after it, the start of the hold left out


def _duration(t: float) -> Duration:
    return Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))


class Client:
    """The controller's action, the node's parameter services and the flange IMU (reliable, lossless)."""

    def __init__(self, ctx) -> None:
        self.node = rclpy.create_node("payload_client", context=ctx)
        self.action = ActionClient(self.node, FollowJointTrajectory,
                                   "/joint_trajectory_controller/follow_joint_trajectory")
        self.set_cli = self.node.create_client(SetParameters, "/sim_plant/set_parameters")
        self.get_cli = self.node.create_client(GetParameters, "/sim_plant/get_parameters")
        self.imu: list[tuple[float, tuple[float, float, float]]] = []
        qos = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(Imu, "/tip_imu", self._on_imu, qos)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)

    def _on_imu(self, m: Imu) -> None:
        a = m.linear_acceleration
        self.imu.append((time_to_sec(m.header.stamp), (a.x, a.y, a.z)))

    def spin_until(self, cond, what: str, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def call(self, cli, request, what: str):
        """The node's answer, the request sent again while none comes (a get, or a set of the same values)."""
        return call_answered(self.ex, cli, request, what, timeout=60.0)

    def set_payload(self, **values: float):
        req = SetParameters.Request(parameters=[Parameter(f"arm.payload_{k}", value=v).to_parameter_msg()
                                                for k, v in values.items()])
        (result,) = self.call(self.set_cli, req, "set_parameters").results
        return result

    def payload(self) -> tuple[float, float]:
        resp = self.call(self.get_cli, GetParameters.Request(names=["arm.payload_mass", "arm.payload_offset"]),
                         "get_parameters")
        return resp.values[0].double_value, resp.values[1].double_value

    def lowest_mode(self, expected_hz: float) -> tuple[float, float]:
        """Excite the arm (out by STEP, hold, back, hold) and identify the free decay after each move: the
        mode (Hz, damping ratio) nearest ``expected_hz`` averaged over the two decays."""
        self.spin_until(self.action.server_is_ready, "the controller's action server")
        fits = []
        for target in (np.array(HOME) + STEP, np.array(HOME)):
            stamps: list[float] = []
            pts = [JointTrajectoryPoint(positions=target.tolist(), velocities=[0.0] * 6, time_from_start=_duration(t))
                   for t in (MOVE, MOVE + HOLD)]
            goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES), points=pts))
            sent = self.action.send_goal_async(goal, feedback_callback=lambda m, s=stamps: s.append(
                time_to_sec(m.feedback.header.stamp)))
            self.spin_until(sent.done, "the goal's answer")
            handle = sent.result()
            assert handle.accepted
            result = handle.get_result_async()
            self.spin_until(result.done, "the goal's result", timeout=120.0)
            assert result.result().status == GoalStatus.STATUS_SUCCEEDED
            start = min(stamps)
            end = start + MOVE + HOLD
            self.spin_until(lambda e=end: self.imu and self.imu[-1][0] >= e - 0.01, "the IMU samples of the hold")
            t = np.array([s for s, _ in self.imu])
            a = np.array([v for _, v in self.imu])
            sel = (t > start + MOVE + SKIP) & (t <= end)
            assert sel.sum() > 1000  # 1 kHz over the hold, nothing lost
            found = identify(t[sel], a[sel], max_modes=3)
            fits.append(min(found, key=lambda f: abs(f.omega / (2 * math.pi) - expected_hz)))
        return (float(np.mean([f.omega for f in fits])) / (2 * math.pi), float(np.mean([f.zeta for f in fits])))

    def close(self) -> None:
        self.ex.shutdown()
        self.action.destroy()
        self.node.destroy_node()


def test_a_heavier_payload_set_at_run_time_lowers_the_arms_lowest_mode_as_physics_says(start_node, ros_context):
    sim = start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME})
    client = Client(ros_context)
    try:
        assert client.payload() == (2.0, 0.08)  # the default: gripper and part
        expected = {m: lowest(ArmModel(ArmSpec(payload_mass=m)), np.array(HOME)) for m in (2.0, 4.5)}
        assert expected[4.5].hz < 0.9 * expected[2.0].hz  # modal analysis: 9.96 -> about 8.5 Hz
        before = client.lowest_mode(expected[2.0].hz)

        # refused, with the reason, and nothing changes
        for bad in (-1.0, 25.0, math.nan, math.inf):
            result = client.set_payload(mass=bad)
            assert not result.successful, bad
            assert "payload_mass" in result.reason or "payload mass" in result.reason, result.reason
        assert not client.set_payload(offset=-0.01).successful
        assert client.payload() == (2.0, 0.08)

        result = client.set_payload(mass=4.5)  # ros2 param set /sim_plant arm.payload_mass 4.5
        assert result.successful, result.reason
        assert client.payload() == (4.5, 0.08)
        client.spin_until(lambda: "payload 4.5 kg" in sim.log_path.read_text(errors="replace"),
                          "the node's log of the new payload")
        after = client.lowest_mode(expected[4.5].hz)
    finally:
        client.close()
    # each identified from the flange IMU within 2 % of modal analysis with its payload (damping within 20 %)
    assert before[0] == pytest.approx(expected[2.0].hz, rel=0.02)
    assert after[0] == pytest.approx(expected[4.5].hz, rel=0.02)
    assert before[1] == pytest.approx(expected[2.0].zeta, rel=0.2)
    assert after[1] == pytest.approx(expected[4.5].zeta, rel=0.2)
    # and lower by the ratio physics says
    assert after[0] / before[0] == pytest.approx(expected[4.5].hz / expected[2.0].hz, rel=0.02)
    assert sim.running()
