"""The shaper node in-process with a probe node, over real DDS: bad input, live updates, paths.

Each test has a fresh Context with the node under test and a probe in one executor, and
bounded spin loops instead of sleeps.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper, ShapeTrajectory
from shaper_nodes.core.shaping import design, modes_from_hz
from shaper_nodes.nodes.shaper import ShaperNode
from shaper_nodes.ros.conversions import mode_msg
from shaper_nodes.ros.qos import LATCHED

pytestmark = pytest.mark.integration
JOINTS = ["j1", "j2", "j3"]


class Rig:
    """Shaper node + probe node in one executor."""

    def __init__(self, ctx, **params):
        overrides = [Parameter("joint_names", value=JOINTS), Parameter("command_rate", value=100.0),
                     Parameter("shaper.family", value="zv"), Parameter("shaper.frequency_hz", value=5.0),
                     Parameter("shaper.damping_ratio", value=0.0), Parameter("error_throttle", value=0.0)]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        self.node = ShaperNode(context=ctx, parameter_overrides=overrides)
        self.probe = rclpy.create_node("probe", context=ctx)
        self.array_out, self.stream_out, self.diag, self.active = [], [], [], []
        self.probe.create_subscription(Float64MultiArray, "/forward_position_controller/commands",
                                       lambda m: self.array_out.append(np.array(m.data)), 10)
        self.probe.create_subscription(JointTrajectory, "/joint_trajectory_controller/joint_trajectory",
                                       self.stream_out.append, 10)
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.probe.create_subscription(ShaperMsg, "/shaper/active_shaper", self.active.append, LATCHED)
        self.array_in = self.probe.create_publisher(Float64MultiArray, "/shaper/commands", 10)
        self.stream_in = self.probe.create_publisher(JointTrajectory, "/shaper/joint_trajectory_stream", 10)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.probe)
        self.spin_until(lambda: self.array_in.get_subscription_count() and self.stream_in.get_subscription_count()
                        and self.active, "discovery")

    def _on_diag(self, msg):
        self.diag += [s for s in msg.status if s.name.endswith(": input")]

    def spin_until(self, cond, what, timeout=10.0):
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def settle(self, seconds=0.3):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)

    def call(self, srv_type, name, request):
        cli = self.probe.create_client(srv_type, name)
        self.spin_until(cli.service_is_ready, name)
        fut = cli.call_async(request)
        self.spin_until(fut.done, name)
        return fut.result()

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()


@pytest.fixture
def rig(ros_context):
    r = Rig(ros_context)
    yield r
    r.close()


def stream_msg(names, points):
    msg = JointTrajectory(joint_names=names)
    for t, pos in points:
        msg.points.append(JointTrajectoryPoint(positions=list(pos), time_from_start=Duration(
            sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))))
    return msg


def send_valid_array_and_expect_output(rig, value=1.0):
    n = len(rig.array_out)
    rig.array_in.publish(Float64MultiArray(data=[value] * 3))
    rig.spin_until(lambda: len(rig.array_out) > n, "shaped output of a valid message")
    assert np.all(np.isfinite(rig.array_out[-1]))


ARRAY_CASES = [
    ([1.0, math.nan, 0.0], "non_finite", "non-finite"),
    ([1.0, math.inf, 0.0], "non_finite", "non-finite"),
    ([1.0, 2.0], "wrong_size", "has 2 values, expected 3"),
    ([], "empty", "empty"),
    ([1.7e308, 0.0, 0.0], "too_large", "beyond the limit of 1e+06 in magnitude"),  # finite, overflows a sum
]


@pytest.mark.parametrize("data, kind, words", ARRAY_CASES)
def test_bad_array_is_refused_named_and_not_forwarded(rig, data, kind, words):
    send_valid_array_and_expect_output(rig, 0.0)
    before = len(rig.array_out)
    rig.array_in.publish(Float64MultiArray(data=data))
    rig.spin_until(lambda: any(s.values[0].value == kind for s in rig.diag), f"diagnostic {kind}")
    status = next(s for s in rig.diag if s.values[0].value == kind)
    assert words in status.message and "/shaper/commands" in status.message
    rig.settle()
    assert len(rig.array_out) == before  # nothing forwarded
    assert rig.node.rejections[kind] == 1
    send_valid_array_and_expect_output(rig, 1.0)  # still shapes the next valid message
    # the refused sample left no trace in the filter state: output = zv shaping of 0 -> 1
    assert rig.array_out[-1][0] == pytest.approx(0.5)


STREAM_CASES = [
    (["j1", "j2", "jX"], [(0.01, [0, 0, 0])], "unknown_joint", "unknown joint names ['jX']"),
    (["j1", "j2"], [(0.01, [0, 0])], "missing_joint", "missing joint names ['j3']"),
    (["j1", "j1", "j2", "j3"], [(0.01, [0, 0, 0, 0])], "duplicate_joint", "duplicate joint names"),
    (["j1", "j2", "j3"], [], "empty", "no points"),
    (["j1", "j2", "j3"], [(0.02, [0, 0, 0]), (0.01, [0, 0, 0])], "non_increasing_time", "not strictly increasing"),
    (["j1", "j2", "j3"], [(0.01, [0, math.nan, 0])], "non_finite", "non-finite"),
    (["j1", "j2", "j3"], [(0.01, [0, 0])], "wrong_size", "expected 3"),
]


@pytest.mark.parametrize("names, points, kind, words", STREAM_CASES)
def test_bad_trajectory_stream_is_refused_named_and_not_forwarded(rig, names, points, kind, words):
    rig.stream_in.publish(stream_msg(JOINTS, [(0.01, [0, 0, 0])]))
    rig.spin_until(lambda: rig.stream_out, "first valid stream output")
    before = len(rig.stream_out)
    rig.stream_in.publish(stream_msg(names, points))
    rig.spin_until(lambda: any(s.values[0].value == kind for s in rig.diag), f"diagnostic {kind}")
    status = next(s for s in rig.diag if s.values[0].value == kind)
    assert words in status.message
    rig.settle()
    assert len(rig.stream_out) == before
    rig.stream_in.publish(stream_msg(["j3", "j1", "j2"], [(0.02, [3.0, 1.0, 2.0])]))
    rig.spin_until(lambda: len(rig.stream_out) > before, "output after a valid message")
    out = rig.stream_out[-1]
    assert list(out.joint_names) == JOINTS
    np.testing.assert_allclose(out.points[0].positions, [0.5, 1.0, 1.5])  # reordered, zv-shaped


def test_invalid_parameters_are_refused_and_the_old_shaper_stays(rig):
    rev = rig.active[-1].revision
    for params in ([Parameter("shaper.family", value="quintic")],
                   [Parameter("shaper.frequency_hz", value=40.0)],  # above rate / 4
                   [Parameter("discretization", value="cubic")],
                   [Parameter("shaper.family", value="ei"), Parameter("shaper.vibration_tolerance", value=0.5)]):
        results = rig.node.set_parameters_atomically(params)
        assert not results.successful and results.reason
    rig.settle(0.2)
    assert rig.active[-1].revision == rev and rig.active[-1].family == "zv"
    assert rig.node.set_parameters_atomically([Parameter("shaper.family", value="zvd")]).successful
    rig.spin_until(lambda: rig.active[-1].revision == rev + 1, "new active shaper")
    assert rig.active[-1].family == "zvd" and rig.active[-1].source == "parameters"
    assert rig.node.set_parameters_atomically([Parameter("discretization", value="exact")]).successful
    rig.spin_until(lambda: rig.active[-1].revision == rev + 2, "the same shaper, discretised exactly")


def test_a_huge_finite_sample_cannot_poison_the_filter(rig):
    """One sample of 1e17 used to leave the filter's state without precision (a steady 0.3 came out as 0)."""
    send_valid_array_and_expect_output(rig, 0.0)
    rig.array_in.publish(Float64MultiArray(data=[1e17, 0.0, 0.0]))
    rig.spin_until(lambda: rig.node.rejections["too_large"] == 1, "the refusal of 1e17")
    for _ in range(60):  # longer than the shaper (zv at 5 Hz: 0.1 s, 10 samples at 100 Hz)
        send_valid_array_and_expect_output(rig, 0.3)
    assert rig.array_out[-1] == pytest.approx([0.3] * 3, abs=1e-12)


def test_set_shaper_service_validates_and_policy_applies(rig):
    req = SetShaper.Request(shaper=ShaperMsg(family="custom", amplitudes=[0.6, 0.6], times=[0.0, 0.1], source="user"))
    resp = rig.call(SetShaper, "/shaper/set_shaper", req)
    assert not resp.success and "sum to 1" in resp.message and resp.active.family == "zv"
    # finite, summing to 1, but amplifying 1999 times: refused unless shaper.max_gain allows it
    req = SetShaper.Request(shaper=ShaperMsg(family="custom", amplitudes=[1000.0, -999.0], times=[0.0, 0.1],
                                             source="user"))
    resp = rig.call(SetShaper, "/shaper/set_shaper", req)
    assert not resp.success and "gain sum |A| = 1999 exceeds max_gain 1" in resp.message
    assert resp.active.family == "zv"
    req = SetShaper.Request(shaper=ShaperMsg(family="zvd", source="intruder",
                                             design_modes=[mode_msg(20.0 / (2 * math.pi), 0.1)]))
    resp = rig.call(SetShaper, "/shaper/set_shaper", req)
    assert not resp.success and "update policy" in resp.message
    req.shaper.source = "learner"
    resp = rig.call(SetShaper, "/shaper/set_shaper", req)
    assert resp.success and resp.active.family == "zvd" and resp.active.source == "learner"
    got = rig.call(GetShaper, "/shaper/get_shaper", GetShaper.Request())
    assert got.active.revision == resp.active.revision and got.command_rate == 100.0
    assert sum(got.fir_taps) == pytest.approx(1.0)
    # a late joiner still gets the active shaper (latched)
    late = []
    rig.probe.create_subscription(ShaperMsg, "/shaper/active_shaper", late.append, LATCHED)
    rig.spin_until(lambda: late, "latched active shaper")
    assert late[-1].revision == resp.active.revision


def test_live_change_mid_motion_is_bumpless(rig):
    outputs = []
    ramp = np.concatenate([np.linspace(0, 1, 60), np.ones(60)])
    for k, v in enumerate(ramp):
        if k == 30:
            assert rig.node.set_parameters([Parameter("shaper.family", value="zvd")])[0].successful
        n = len(rig.array_out)
        rig.array_in.publish(Float64MultiArray(data=[v] * 3))
        rig.spin_until(lambda n=n: len(rig.array_out) > n, "output")
        outputs.append(rig.array_out[-1][0])
    steps = np.abs(np.diff(outputs))
    assert steps.max() <= 2 * (1 / 59) + 1e-12
    assert outputs[-1] == pytest.approx(1.0, abs=1e-12)


def test_whole_trajectory_service(rig):
    traj = stream_msg(["j2", "j1", "j3"], [(0.5, [0, 0, 0]), (1.0, [0.5, 1.0, 0.0]), (1.5, [1.0, 2.0, 0.0])])
    resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=traj))
    assert resp.success, resp.message
    out = resp.shaped
    assert list(out.joint_names) == JOINTS
    t = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in out.points]
    assert np.all(np.diff(t) > 0) and t[-1] >= 1.5 + 0.1 - 1e-9  # longer by the zv duration (0.1 s)
    last = out.points[-1]
    np.testing.assert_allclose(last.positions, [2.0, 1.0, 0.0], atol=1e-12)
    assert list(last.velocities) == [0.0] * 3 and list(last.accelerations) == [0.0] * 3
    assert all(np.all(np.isfinite(p.positions)) and len(p.velocities) == 3 for p in out.points)
    bad = stream_msg(JOINTS, [(1.0, [0, 0, 0]), (1.0, [1, 1, 1])])
    resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=bad))
    assert not resp.success and "not strictly increasing" in resp.message


def modes_of(msg):
    """(frequency rad/s, damping ratio) of each design mode (the message holds Hz)."""
    return [(pytest.approx(2 * math.pi * m.frequency_hz, rel=1e-12), m.damping_ratio) for m in msg.design_modes]


def test_several_modes_from_parameters_give_the_convolved_shaper_and_change_live(ros_context):
    rig = Rig(ros_context, **{"shaper.frequencies_hz": [2.0, 7.0], "shaper.damping_ratios": [0.0, 0.05]})
    try:
        active = rig.active[-1]
        expected = design("zv", modes_from_hz([2.0, 7.0], [0.0, 0.05]))  # zv per mode, convolved
        assert active.family == "zv" and len(active.times) == 4 == len(expected)
        assert modes_of(active) == [(2 * math.pi * 2.0, 0.0), (2 * math.pi * 7.0, 0.05)]
        np.testing.assert_allclose(active.times, expected.times, rtol=1e-12)
        np.testing.assert_allclose(active.amplitudes, expected.amplitudes, rtol=1e-12)
        send_valid_array_and_expect_output(rig, 0.0)
        send_valid_array_and_expect_output(rig, 1.0)  # the streaming path uses it: the first impulse now
        assert rig.array_out[-1][0] == pytest.approx(expected.amplitudes[0], rel=1e-12)

        # live, both lists at once: three modes, like any shaper.* change (source parameters, a revision)
        rev = active.revision
        assert rig.node.set_parameters_atomically([Parameter("shaper.frequencies_hz", value=[2.0, 7.0, 11.0]),
                                                   Parameter("shaper.damping_ratios", value=[0.0, 0.05, 0.1])
                                                   ]).successful
        rig.spin_until(lambda: rig.active[-1].revision == rev + 1, "the three-mode shaper")
        assert len(rig.active[-1].design_modes) == 3 and len(rig.active[-1].times) == 8
        assert rig.active[-1].source == "parameters"

        # refused with a reason, the old shaper stays
        for params, words in (
                ([Parameter("shaper.frequencies_hz", value=[2.0, 7.0])],
                 "shaper.frequencies_hz / shaper.damping_ratios: 2 frequencies but 3 damping ratios"),
                ([Parameter("shaper.frequencies_hz", value=[2.0, 7.0, 30.0])],
                 "shaper.frequencies_hz 30 Hz is too high for command_rate 100 Hz"),
                ([Parameter("shaper.damping_ratios", value=[0.0, 0.05, 1.2])],
                 "mode 2 (11.0 Hz, damping ratio 1.2): damping ratio must be in [0, 0.95]"),
                ([Parameter("shaper.frequencies_hz", value=[1.0] * 9), Parameter("shaper.damping_ratios",
                                                                                 value=[0.0] * 9)],
                 "9 modes exceed the limit of 8")):
            result = rig.node.set_parameters_atomically(params)
            assert not result.successful and words in result.reason, result.reason
        rig.settle(0.2)
        assert rig.active[-1].revision == rev + 1

        # both emptied: back to shaper.frequency_hz and shaper.damping_ratio (5 Hz, 0)
        empty = Parameter.Type.DOUBLE_ARRAY
        assert rig.node.set_parameters_atomically([Parameter("shaper.frequencies_hz", empty, []),
                                                   Parameter("shaper.damping_ratios", empty, [])]).successful
        rig.spin_until(lambda: rig.active[-1].revision == rev + 2, "the single-mode shaper")
        assert modes_of(rig.active[-1]) == [(2 * math.pi * 5.0, 0.0)]
    finally:
        rig.close()


def test_a_node_started_with_mode_lists_of_different_lengths_says_so(ros_context):
    with pytest.raises(ValueError, match="2 frequencies but 1 damping ratios: give one damping ratio per frequency"):
        ShaperNode(context=ros_context, parameter_overrides=[
            Parameter("joint_names", value=JOINTS), Parameter("shaper.family", value="zv"),
            Parameter("shaper.frequencies_hz", value=[2.0, 7.0]), Parameter("shaper.damping_ratios", value=[0.0])])


# ----------------------------------------------------------------------------- output invariants (issue 17)
LIMITS = {"limits.position_lower": [-1.0, -1.0, -1.0], "limits.position_upper": [1.0, 1.0, 1.0]}


def test_no_streamed_command_passes_the_position_limits_and_a_refused_one_leaves_no_trace(ros_context):
    rig = Rig(ros_context, **LIMITS)
    try:
        send_valid_array_and_expect_output(rig, 0.0)
        before = len(rig.array_out)
        # 3 is within limits.max_abs_value but beyond the joint limit: refused before the filter (its first
        # impulse, 1.5, would pass too; a smaller first impulse would pass, and pull every later output out)
        rig.array_in.publish(Float64MultiArray(data=[3.0, 0.0, 0.0]))
        rig.spin_until(lambda: any(s.values[0].value == "beyond_limits" for s in rig.diag),
                       "the refusal of a command beyond limits on /diagnostics")
        status = next(s for s in rig.diag if s.values[0].value == "beyond_limits")
        assert "the command would pass the position limit of joint 'j1': 3 beyond 1" in status.message
        rig.settle(0.2)
        assert len(rig.array_out) == before
        # the refused sample never reached the filter: a step 0 -> 0.8 is zv-shaped from 0
        send_valid_array_and_expect_output(rig, 0.8)
        assert rig.array_out[-1][0] == pytest.approx(0.4)
        # the stream path too, with the reason
        rig.stream_in.publish(stream_msg(JOINTS, [(0.01, [0.0, 0.0, 0.0])]))
        rig.spin_until(lambda: rig.stream_out, "stream output")
        rig.stream_in.publish(stream_msg(JOINTS, [(0.02, [0.0, -2.5, 0.0])]))
        rig.spin_until(lambda: rig.node.rejections["beyond_limits"] == 2, "the stream's refusal")
        # whole trajectories: positions, and velocities against limits.velocity
        traj = stream_msg(JOINTS, [(0.0, [0, 0, 0]), (1.0, [1.2, 0, 0])])
        resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=traj))
        assert not resp.success and "position limit of joint 'j1'" in resp.message and "t = " in resp.message
    finally:
        rig.close()


def test_whole_trajectories_within_velocity_and_acceleration_limits(ros_context):
    rig = Rig(ros_context, **{"limits.velocity": [2.0, 2.0, 2.0], "limits.acceleration": [50.0, 50.0, 50.0]})
    try:
        slow = stream_msg(JOINTS, [(0.0, [0, 0, 0]), (2.0, [1.0, 0.5, 0.0])])
        resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=slow))
        assert resp.success, resp.message
        vel = np.array([p.velocities for p in resp.shaped.points])
        acc = np.array([p.accelerations for p in resp.shaped.points])
        assert np.abs(vel).max() <= 2.0 and np.abs(acc).max() <= 50.0
        fast = stream_msg(JOINTS, [(0.0, [0, 0, 0]), (0.2, [1.0, 0.0, 0.0])])  # 1 rad in 0.2 s: 5+ rad/s
        resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=fast))
        assert not resp.success and "velocity limit of joint 'j1'" in resp.message, resp.message
        assert rig.node.rejections["beyond_limits"] == 1
    finally:
        rig.close()


URDF = """<robot name="three">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-0.5" upper="0.5" velocity="3.0" effort="10"/></joint>
  <joint name="j2" type="continuous"><parent link="l1"/><child link="l2"/><limit velocity="1.0" effort="10"/></joint>
  <joint name="j3" type="prismatic"><parent link="l2"/><child link="l3"/>
    <limit lower="0" upper="0.3" velocity="0.2" effort="10"/></joint>
</robot>"""


def test_limits_from_a_urdf_and_the_tighter_of_urdf_and_parameters(ros_context, tmp_path):
    path = tmp_path / "three.urdf"
    path.write_text(URDF)
    rig = Rig(ros_context, **{"limits.urdf_file": str(path), "limits.position_upper": [0.4, 10.0, 10.0]})
    try:
        lim = rig.node.limits
        np.testing.assert_array_equal(lim.upper, [0.4, 10.0, 0.3])  # j1, j2 (continuous): the parameter is tighter
        np.testing.assert_array_equal(lim.lower, [-0.5, -np.inf, 0.0])
        np.testing.assert_array_equal(lim.velocity, [3.0, 1.0, 0.2])
        send_valid_array_and_expect_output(rig, 0.0)
        rig.array_in.publish(Float64MultiArray(data=[0.0, 0.0, -0.1]))  # j3 below its URDF lower limit
        rig.spin_until(lambda: rig.node.rejections["beyond_limits"] == 1, "the URDF's limit")
    finally:
        rig.close()
    bad = tmp_path / "two.urdf"
    bad.write_text(URDF.replace('name="j3"', 'name="j9"'))
    with pytest.raises(ValueError, match="joint 'j3' is not in the URDF"):
        ShaperNode(context=ros_context, parameter_overrides=[Parameter("joint_names", value=JOINTS),
                                                             Parameter("limits.urdf_file", value=str(bad))])


def test_an_unrepresentable_time_is_refused_not_wrapped(rig):
    traj = JointTrajectory(joint_names=JOINTS, points=[JointTrajectoryPoint(
        positions=[0.0, 0.0, 0.0], time_from_start=Duration(sec=2**31 - 1, nanosec=999_999_999))])
    resp = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=traj))
    assert not resp.success and "a builtin_interfaces/Duration holds" in resp.message
    ok = stream_msg(JOINTS, [(0.5, [0, 0, 0]), (1.0, [0.1, 0.1, 0.1])])
    assert rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=ok)).success


def stream_with(points, fields):
    msg = JointTrajectory(joint_names=JOINTS)
    for t, values in points:
        p = JointTrajectoryPoint(time_from_start=Duration(sec=int(t), nanosec=int(round((t % 1) * 1e9))))
        for f, v in zip(fields, values, strict=True):
            setattr(p, f, list(v))
        msg.points.append(p)
    return msg


def test_the_stream_follows_the_fields_that_arrive(rig):
    """Positions only, then positions and velocities (as MoveIt Servo streams), then positions only:
    every message is shaped; a field that appears starts at its first value."""
    pos_only = ("positions",)
    both = ("positions", "velocities")
    for k, (fields, values) in enumerate([(pos_only, ([0.0] * 3,)), (pos_only, ([0.0] * 3,)),
                                          (both, ([0.2] * 3, [0.4] * 3)), (both, ([0.2] * 3, [0.4] * 3)),
                                          (pos_only, ([0.2] * 3,))]):
        n = len(rig.stream_out)
        rig.stream_in.publish(stream_with([(0.01 * (k + 1), values)], fields))
        rig.spin_until(lambda n=n: len(rig.stream_out) > n, f"stream output {k}")
        out = rig.stream_out[-1].points[0]
        assert len(out.velocities) == (3 if "velocities" in fields else 0)
        if k == 2:
            assert out.positions[0] == pytest.approx(0.1)  # zv: half the step now
            assert list(out.velocities) == pytest.approx([0.4] * 3)  # starts at its first value
    assert rig.node.rejections["inconsistent_fields"] == 0


def summary(rig_diag):
    return [s for s in rig_diag if s.name.endswith(": shaper")]


def test_drops_and_gaps_of_the_stream_are_reported(ros_context):
    rig = Rig(ros_context, queue_depth=5, diagnostics_period=0.2)
    statuses = []
    rig.probe.create_subscription(DiagnosticArray, "/diagnostics",
                                  lambda m: statuses.extend(s for s in m.status if s.name.endswith(": shaper")), 50)
    try:
        send_valid_array_and_expect_output(rig, 0.0)
        before = len(rig.array_out)
        with rig.node.stream_lock:  # the stream stalls (at most one sample taken): its queue of 5 overflows
            for _ in range(60):
                rig.array_in.publish(Float64MultiArray(data=[0.0] * 3))

        def drops():
            for s in reversed(statuses):
                kv = {k.key: k.value for k in s.values}
                if int(kv.get("input.array.total_drops", 0)) > 0:
                    return s, kv
            return None

        rig.spin_until(drops, "a summary with the dropped samples", timeout=20.0)
        status, _ = drops()
        assert status.level == DiagnosticStatus.WARN and "dropped" in status.message
        # every sample of the burst is accounted for: shaped, or counted as dropped
        rig.spin_until(lambda: len(rig.array_out) - before + rig.node.watched("array").total_drops == 60,
                       "every sample shaped or counted as dropped")
        assert rig.node.watched("array").total_drops >= 40  # the queue kept about its last 5
    finally:
        rig.close()


def test_arrivals_the_main_thread_did_not_watch_in_time_are_reported(ros_context):
    """The streaming path only keeps each message's info; the main thread passes it through the rate
    watch. Arrivals pushed out of the bounded queue before it did are counted and reported (WARN)."""
    rig = Rig(ros_context, diagnostics_period=3600.0)  # no summary but the one asked for below
    statuses = []
    rig.probe.create_subscription(DiagnosticArray, "/diagnostics",
                                  lambda m: statuses.extend(s for s in m.status if s.name.endswith(": shaper")), 50)
    try:
        node, extra = rig.node, 100
        for i in range(node._arrivals_max + extra):  # as the stream thread would, with no spin between
            node._arrived("array", {"source_timestamp": 10**7 * (i + 1), "received_timestamp": 10**7 * (i + 1),
                                    "publication_sequence_number": i + 1})
        node._publish_summary()
        rig.spin_until(lambda: statuses, "the summary")
        kv = {k.key: k.value for k in statuses[-1].values}
        assert kv["input.array.unwatched"] == str(extra)
        assert statuses[-1].level == DiagnosticStatus.WARN and "not watched" in statuses[-1].message
        assert kv["input.array.messages"] == str(node._arrivals_max)  # the ones kept went through the watch
        assert kv["input.array.drops"] == "0"  # the last ones kept are consecutive
    finally:
        rig.close()


def test_whole_trajectory_topic_is_shaped_in_the_worker_process(rig):
    """The trajectory topic: taken as bytes, shaped in the worker process, published as bytes; the same
    trajectory as the service gives, and a bad one refused with its reason."""
    traj_in = rig.probe.create_publisher(JointTrajectory, "/shaper/joint_trajectory", 10)
    rig.spin_until(lambda: traj_in.get_subscription_count() >= 1, "the trajectory topic's subscription")
    traj = stream_msg(["j2", "j1", "j3"], [(0.5, [0, 0, 0]), (1.0, [0.5, 1.0, 0.0]), (1.5, [1.0, 2.0, 0.0])])
    traj_in.publish(traj)
    rig.spin_until(lambda: any(len(m.points) > 10 for m in rig.stream_out), "the shaped trajectory", timeout=30.0)
    out = next(m for m in rig.stream_out if len(m.points) > 10)
    via_service = rig.call(ShapeTrajectory, "/shaper/shape_trajectory", ShapeTrajectory.Request(trajectory=traj))
    assert via_service.success and list(out.joint_names) == JOINTS
    assert [p.time_from_start for p in out.points] == [p.time_from_start for p in via_service.shaped.points]
    np.testing.assert_array_equal([p.positions for p in out.points], [p.positions for p in via_service.shaped.points])
    assert rig.node.forwarded["trajectory"] == 1
    traj_in.publish(stream_msg(JOINTS, [(1.0, [0, 0, 0]), (1.0, [1, 1, 1])]))
    rig.spin_until(lambda: any(s.values[0].value == "non_increasing_time" for s in rig.diag), "the refusal",
                   timeout=30.0)
    status = next(s for s in rig.diag if s.values[0].value == "non_increasing_time")
    assert "/shaper/joint_trajectory" in status.message and "not strictly increasing" in status.message
