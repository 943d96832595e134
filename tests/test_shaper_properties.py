"""Property tests of the shaper node's output on every path (issue 17): whatever finite input
arrives, in any order, with shaper changes in between, what leaves the node is finite, within the
joint limits and time-ordered, and a constant input afterwards settles the output to it.

The node is the real ``ShaperNode`` (parameters, checks, filters, message building); its
callbacks are called directly with the messages hypothesis draws, and what it would publish is
captured at its publishers, so that thousands of sequences run in seconds. The DDS transport of
the same callbacks is covered by test_shaper_node.py.
"""

from __future__ import annotations

import contextlib
import copy
import math

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from conftest import new_domain
from control_msgs.action import FollowJointTrajectory
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.srv import ShapeTrajectory
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.shaping import Mode, design
from shaper_nodes.nodes.shaper import ShaperNode

JOINTS = ["j1", "j2", "j3"]
RATE = 100.0
LOWER, UPPER = [-2.0, -1.0, -3.0], [2.0, 1.0, 3.0]
VEL, ACC = [50.0, 50.0, 50.0], [5000.0, 5000.0, 5000.0]
SETTLE = 200  # samples: longer than any shaper drawn here (at most 0.5 s = 50 samples), stages included
PROPS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

# any finite double, the extremes explicitly, and values near the limits
FINITE = st.one_of(st.floats(allow_nan=False, allow_infinity=False),
                   st.sampled_from([1.7e308, -1.7e308, 1e17, -1e17, 5e-324, -0.0, 0.0, 1e6, -1e6]),
                   st.floats(-3.5, 3.5))
NEAR = st.floats(-2.5, 2.5)
SHAPERS = st.builds(lambda fam, hz, z: design(fam, [Mode.from_hz(hz, z)]),
                    st.sampled_from(["none", "zv", "zvd", "mzv", "ei"]), st.floats(2.0, 20.0), st.floats(0.0, 0.3))


class Captured:
    """Stands for a node's publisher: keeps what would be published."""

    def __init__(self, topic: str) -> None:
        self.topic_name = topic
        self.sent: list = []

    def publish(self, msg) -> None:
        self.sent.append(msg if isinstance(msg, bytes) else copy.deepcopy(msg))  # as rclpy serializes it


@pytest.fixture(scope="module")
def node():
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=new_domain())  # (its own: other workers' tests run at once)
    overrides = [Parameter("joint_names", value=JOINTS), Parameter("command_rate", value=RATE),
                 Parameter("shaper.family", value="zv"), Parameter("shaper.frequency_hz", value=5.0),
                 Parameter("limits.position_lower", value=LOWER), Parameter("limits.position_upper", value=UPPER),
                 Parameter("limits.velocity", value=VEL), Parameter("limits.acceleration", value=ACC),
                 Parameter("error_throttle", value=3600.0)]
    n = ShaperNode(context=ctx, parameter_overrides=overrides)
    n._array_pub, n._stream_pub, n._traj_pub = Captured("array"), Captured("stream"), Captured("trajectory")
    yield n
    n.destroy_node()
    ctx.try_shutdown()


def duration(t: float) -> Duration:
    ns = int(round(t * 1e9))
    return Duration(sec=ns // 10**9, nanosec=ns % 10**9)


def sec(d: Duration) -> float:
    return d.sec + 1e-9 * d.nanosec


def check_positions(values) -> None:
    p = np.asarray(values, dtype=float)
    assert np.all(np.isfinite(p))
    assert np.all(p >= np.array(LOWER) - 1e-12) and np.all(p <= np.array(UPPER) + 1e-12)


def check_whole(out: JointTrajectory) -> None:
    assert list(out.joint_names) == JOINTS
    t = np.array([sec(p.time_from_start) for p in out.points])
    assert t.size >= 1 and np.all(np.diff(t) > 0) and t[0] >= 0.0
    assert all(0 <= p.time_from_start.sec < 2**31 and 0 <= p.time_from_start.nanosec < 10**9 for p in out.points)
    for p in out.points:
        check_positions(p.positions)
        assert np.all(np.isfinite(p.velocities)) and np.all(np.abs(p.velocities) <= np.array(VEL))
        assert np.all(np.isfinite(p.accelerations)) and np.all(np.abs(p.accelerations) <= np.array(ACC))


# one step of a sequence: a sample on the array path, a stream message, a whole trajectory on one of
# the three whole paths, or a shaper change (service source, or a re-timing source)
ARRAY = st.tuples(st.just("array"), st.lists(FINITE, min_size=3, max_size=3))
STREAM = st.tuples(st.just("stream"), st.lists(st.lists(FINITE, min_size=3, max_size=3), min_size=1, max_size=3),
                   st.booleans())
WHOLE = st.tuples(st.just("whole"), st.sampled_from(["topic", "service", "action"]),
                  st.lists(st.tuples(st.floats(0.0, 30.0), st.lists(NEAR, min_size=3, max_size=3)),
                           min_size=1, max_size=6))
CHANGE = st.tuples(st.just("change"), SHAPERS)
STEPS = st.lists(st.one_of(ARRAY, STREAM, WHOLE, CHANGE), max_size=40)


def send_array(node: ShaperNode, data) -> None:
    """A sample on the array path, as its raw subscription gives it (serialized)."""
    node._on_array(serialize_message(Float64MultiArray(data=list(data))), None)


def array_data(sent: bytes) -> np.ndarray:
    """The data of what the array path published (serialized bytes)."""
    return deserialize_message(sent, Float64MultiArray).data


def run_step(node: ShaperNode, step, k: int) -> None:
    kind = step[0]
    if kind == "array":
        send_array(node, step[1])
    elif kind == "stream":
        rows, with_vel = step[1], step[2]
        msg = JointTrajectory(joint_names=JOINTS)
        for i, row in enumerate(rows):
            pt = JointTrajectoryPoint(positions=row, time_from_start=duration(0.01 * (k * 4 + i + 1)))
            if with_vel:
                pt.velocities = [0.0, 0.1, -0.1]
            msg.points.append(pt)
        node._on_stream(serialize_message(msg), None)  # as its raw subscription gives it
    elif kind == "whole":
        path, pts = step[1], sorted(step[2])
        msg = JointTrajectory(joint_names=JOINTS,
                              points=[JointTrajectoryPoint(positions=p, time_from_start=duration(t)) for t, p in pts])
        if path == "topic":  # as the raw subscription gives it, shaped in the worker process
            node._on_trajectory(serialize_message(msg))
        elif path == "service":
            resp = node._on_shape_trajectory(ShapeTrajectory.Request(trajectory=msg), ShapeTrajectory.Response())
            if resp.success:
                check_whole(resp.shaped)
        else:
            with contextlib.suppress(InputError):  # refused: the goal would be rejected, nothing sent
                check_whole(node._action.shaped_goal(FollowJointTrajectory.Goal(trajectory=msg)).trajectory)
    else:
        node.request(step[1], "service")


@PROPS
@given(steps=STEPS, final=st.lists(st.floats(-0.9, 0.9), min_size=3, max_size=3))
@example(steps=[("array", [-1.7e308, 0.0, 0.0]), ("array", [1.7e308, 0.0, 0.0])], final=[0.3, 0.3, 0.3])
@example(steps=[("array", [1e17, 0.0, 0.0]), ("change", design("zvd", [Mode.from_hz(4.0, 0.1)])),
                ("array", [0.3, 0.3, 0.3])], final=[0.3, 0.3, 0.3])
@example(steps=[("whole", "topic", [(0.0, [0.0, 0.0, 0.0]), (1.0, [1.0, 0.5, 1.0])]),
                ("whole", "service", [(2**31 - 1.0, [0.0, 0.0, 0.0])])], final=[0.0, 0.0, 0.0])
def test_every_path_passes_on_only_finite_in_limit_time_ordered_output_and_settles(node, steps, final):
    for pub in (node._array_pub, node._stream_pub, node._traj_pub):
        pub.sent.clear()
    for k, step in enumerate(steps):
        run_step(node, step, k)
    for msg in node._array_pub.sent:
        check_positions(array_data(msg))
    for data in node._stream_pub.sent:
        msg = deserialize_message(data, JointTrajectory)
        t = [sec(p.time_from_start) for p in msg.points]
        assert np.all(np.diff(t) > 0)
        for p in msg.points:
            check_positions(p.positions)
            v = np.asarray(p.velocities)
            assert v.size == 0 or (np.all(np.isfinite(v)) and np.all(np.abs(v) <= np.array(VEL)))
    for data in node._traj_pub.sent:
        check_whole(deserialize_message(data, JointTrajectory))
    # a constant input afterwards: the output settles to it exactly (to rounding), whatever came before
    node._array_pub.sent.clear()
    for _ in range(SETTLE):
        send_array(node, final)
    assert len(node._array_pub.sent) == SETTLE  # every sample of it shaped and passed on
    scale = max(1.0, *(abs(x) for x in final))
    np.testing.assert_allclose(array_data(node._array_pub.sent[-1]), final, rtol=0, atol=1e-9 * scale)


def test_the_node_is_alive_and_shaping_after_every_refusal(node):
    """Each class of refusal once, then a valid sample is still shaped (the property above draws them at
    random; here each is named)."""
    node._array_pub.sent.clear()
    bad = [[math.nan, 0, 0], [math.inf, 0, 0], [1.7e308, 0, 0], [500.0, 0, 0], [0, 0], []]
    for data in bad:
        send_array(node, data)
    for raw in (b"", b"\x00\x01\x00\x00\x00", serialize_message(Float64MultiArray(data=[0.1] * 3))[:-1]):
        node._on_array(raw, None)  # bytes that are not a Float64MultiArray (truncated, no header)
    assert not node._array_pub.sent
    assert {"non_finite", "too_large", "beyond_limits", "wrong_size", "empty", "malformed"} <= set(node.rejections)
    send_array(node, [0.1, 0.1, 0.1])
    assert len(node._array_pub.sent) == 1 and np.all(np.isfinite(array_data(node._array_pub.sent[0])))
