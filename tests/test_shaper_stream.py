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


@pytest.mark.parametrize("stream_executor", ["thread", "node"])
def test_both_stream_executors_shape_exactly_what_the_core_gives(ros_context, stream_executor):
    node = ShaperNode(context=ros_context, parameter_overrides=params(stream_executor=stream_executor))
    try:
        steps = np.repeat([[0.0, 0.0, 0.0], [0.5, -0.2, 0.1], [0.2, 0.3, -0.4]], 30, axis=0)
        got = shape_over_dds(ros_context, node, "/shaper/commands", steps)
        fir = discretize(design("zvd", [Mode.from_hz(5.0, 0.05)]), RATE)
        want = StreamingShaper(fir, len(JOINTS)).process(steps)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        streamed = node.get_node_names()
        if stream_executor == "thread":
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
