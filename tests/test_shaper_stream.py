"""The shaper's streamed inputs on their lean node and thread (``stream_executor``), over real DDS.

The streamed inputs are taken by a second node of the shaper's process, ``<name>_stream``, spun on a
thread of its own; their topics are still the shaper's (``~/commands`` is ``/<name>/commands``), a
renamed node (``-r __node:=NAME``) renames them with it, and its side nodes keep names of their own.
Both set-ups shape exactly what the FIR core gives offline.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

from shaper_nodes.core.shaping import Mode, StreamingShaper, design, discretize
from shaper_nodes.nodes.shaper import ShaperNode

pytestmark = pytest.mark.integration
JOINTS = ["j1", "j2", "j3"]
RATE = 100.0
TIMEOUT = 60.0


def params(**extra: object) -> list[Parameter]:
    base = {"joint_names": JOINTS, "command_rate": RATE, "shaper.family": "zvd", "shaper.frequency_hz": 5.0,
            "shaper.damping_ratio": 0.05, **extra}
    return [Parameter(k, value=v) for k, v in base.items()]


def spin_until(ex: SingleThreadedExecutor, cond, what: str) -> None:
    end = time.monotonic() + TIMEOUT
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        ex.spin_once(timeout_sec=0.02)


def shape_over_dds(ctx, node: ShaperNode, in_topic: str, samples: np.ndarray) -> np.ndarray:
    """Send ``samples`` one at a time (each after the previous one's output: no loss, no reordering) and
    return the outputs."""
    probe = rclpy.create_node("stream_probe", context=ctx)
    out: list[np.ndarray] = []
    probe.create_subscription(Float64MultiArray, "/forward_position_controller/commands",
                              lambda m: out.append(np.array(m.data)), 100)
    pub = probe.create_publisher(Float64MultiArray, in_topic, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    try:
        spin_until(ex, lambda: pub.get_subscription_count() >= 1 and probe.count_publishers(
            "/forward_position_controller/commands") >= 1, "discovery")
        for k, row in enumerate(samples):
            pub.publish(Float64MultiArray(data=row.tolist()))
            spin_until(ex, lambda k=k: len(out) > k, f"the output of sample {k}")
    finally:
        ex.shutdown()
        probe.destroy_node()
    return np.vstack(out)


@pytest.mark.parametrize("stream_executor", ["thread", "take", "node"])
def test_both_stream_executors_shape_exactly_what_the_core_gives(ros_context, stream_executor):
    node = ShaperNode(context=ros_context, parameter_overrides=params(stream_executor=stream_executor))
    try:
        steps = np.repeat([[0.0, 0.0, 0.0], [0.5, -0.2, 0.1], [0.2, 0.3, -0.4]], 30, axis=0)
        got = shape_over_dds(ros_context, node, "/shaper/commands", steps)
        fir = discretize(design("zvd", [Mode.from_hz(5.0, 0.05)]), RATE)
        want = StreamingShaper(fir, len(JOINTS)).process(steps)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        streamed = node.get_node_names()
        if stream_executor != "node":
            assert "shaper_stream" in streamed
        else:
            assert "shaper_stream" not in streamed
        assert node.forwarded["array"] == len(steps)
    finally:
        node.destroy_node()


def test_a_renamed_shaper_renames_its_streamed_inputs_and_its_side_nodes_keep_their_own_names(domain_id):
    """``--ros-args -r __node:=left_arm_shaper``: the input is /left_arm_shaper/commands, one node has that
    name (the graph watch finds no duplicate), and the side nodes are left_arm_shaper_stream and
    left_arm_shaper_trajectories."""
    ctx = rclpy.context.Context()
    rclpy.init(args=["shaper_node", "--ros-args", "-r", "__node:=left_arm_shaper"], context=ctx, domain_id=domain_id)
    node = ShaperNode(context=ctx, parameter_overrides=params())
    try:
        assert node.get_fully_qualified_name() == "/left_arm_shaper"
        got = shape_over_dds(ctx, node, "/left_arm_shaper/commands", np.zeros((3, len(JOINTS))))
        assert got.shape == (3, len(JOINTS))
        names = node.get_node_names()
        assert names.count("left_arm_shaper") == 1
        assert {"left_arm_shaper_stream", "left_arm_shaper_trajectories"} <= set(names)
        assert not [f for f in node.graph.look() if f.kind == "duplicate_name"]
    finally:
        node.destroy_node()
        ctx.try_shutdown()


def test_stream_stamps_go_out_normalised_and_never_back(ros_context):
    """A header stamp or a time_from_start with nanosec >= 1e9 goes out normalised; a non-zero stamp
    earlier than the last accepted one is refused with the reason (diagnostics) and not forwarded;
    zero (start now) always passes."""
    from builtin_interfaces.msg import Duration, Time
    from diagnostic_msgs.msg import DiagnosticArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    node = ShaperNode(context=ros_context, parameter_overrides=params())
    probe = rclpy.create_node("stamp_probe", context=ros_context)
    out: list[JointTrajectory] = []
    refusals: list[str] = []
    probe.create_subscription(JointTrajectory, "/joint_trajectory_controller/joint_trajectory", out.append, 10)
    probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: refusals.extend(
        s.message for s in m.status if s.values and s.values[0].value == "non_increasing_time"), 10)
    pub = probe.create_publisher(JointTrajectory, "/shaper/joint_trajectory_stream", 10)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(probe)

    def send(sec: int, nanosec: int, t_sec: int = 0, t_nanosec: int = 10_000_000) -> None:
        msg = JointTrajectory(joint_names=JOINTS)
        msg.header.stamp = Time(sec=sec, nanosec=nanosec)
        msg.points.append(JointTrajectoryPoint(positions=[0.1] * 3, time_from_start=Duration(sec=t_sec,
                                                                                             nanosec=t_nanosec)))
        pub.publish(msg)

    try:
        spin_until(ex, lambda: pub.get_subscription_count() >= 1 and probe.count_publishers(
            "/joint_trajectory_controller/joint_trajectory") >= 1, "discovery")
        send(5, 4_000_000_000, 0, 1_500_000_000)
        spin_until(ex, lambda: len(out) == 1, "the first output")
        assert (out[0].header.stamp.sec, out[0].header.stamp.nanosec) == (9, 0)
        tfs = out[0].points[0].time_from_start
        assert (tfs.sec, tfs.nanosec) == (1, 500_000_000)
        send(8, 0)  # before 9 s: refused
        spin_until(ex, lambda: refusals, "the refusal of a stamp that goes back")
        assert "header stamp 8.000000000 s is before the last accepted one, 9.000000000 s" in refusals[0]
        send(0, 0)  # now: passes
        spin_until(ex, lambda: len(out) == 2, "the output of a zero stamp")
        send(9, 1)
        spin_until(ex, lambda: len(out) == 3, "the output of a later stamp")
        assert [(m.header.stamp.sec, m.header.stamp.nanosec) for m in out] == [(9, 0), (0, 0), (9, 1)]
        assert node.rejections["non_increasing_time"] == 1
    finally:
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()
