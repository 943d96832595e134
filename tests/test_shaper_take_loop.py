"""The shaper's streamed inputs served by the take loop (``stream_executor: take``), over real DDS.

A burst published without waiting comes back complete and in order, shaped exactly as the FIR core
shapes it offline (the loop drains every waiting message of a wake-up in arrival order); bytes that are
not a Float64MultiArray are refused with the reason (diagnostics) and the next sample is shaped as if they
had not come; the stream topic's JointTrajectory goes through the same loop; and destroying the node stops
the loop's thread, after which nothing more is published.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.shaping import Mode, StreamingShaper, design, discretize
from shaper_nodes.nodes.shaper import ShaperNode

pytestmark = pytest.mark.integration
JOINTS = ["j1", "j2", "j3"]
RATE = 100.0
TIMEOUT = 60.0
OUT = "/forward_position_controller/commands"


def make_node(ctx) -> ShaperNode:
    base = {"joint_names": JOINTS, "command_rate": RATE, "shaper.family": "zvd", "shaper.frequency_hz": 5.0,
            "shaper.damping_ratio": 0.05, "stream_executor": "take", "queue_depth": 1000}
    return ShaperNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in base.items()])


def core(samples: np.ndarray) -> np.ndarray:
    fir = discretize(design("zvd", [Mode.from_hz(5.0, 0.05)]), RATE)
    return StreamingShaper(fir, len(JOINTS)).process(samples)


class Probe:
    """The test's node, spun with the shaper's main node on one executor thread of the test."""

    def __init__(self, ctx, node: ShaperNode) -> None:
        self.node = rclpy.create_node("take_probe", context=ctx)
        self.out: list[np.ndarray] = []
        self.refusals: list[str] = []
        self.node.create_subscription(Float64MultiArray, OUT, lambda m: self.out.append(np.array(m.data)), 1000)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.refusals.extend(
            s.message for s in m.status if s.message.startswith("refused")), 100)
        self.pub = self.node.create_publisher(Float64MultiArray, "/shaper/commands", 1000)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(node)
        self.ex.add_node(self.node)

    def until(self, cond, what: str) -> None:
        end = time.monotonic() + TIMEOUT
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def discovered(self) -> None:
        self.until(lambda: self.pub.get_subscription_count() >= 1 and self.node.count_publishers(OUT) >= 1,
                   "discovery")

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()


def test_a_burst_comes_back_complete_in_order_and_exact(ros_context):
    node = make_node(ros_context)
    probe = Probe(ros_context, node)
    try:
        assert "shaper_stream" in node.get_node_names()
        probe.discovered()
        rng = np.random.default_rng(3)
        samples = np.repeat(rng.uniform(-1, 1, (20, len(JOINTS))), 25, axis=0)  # 500 samples, steps
        for row in samples:  # no waiting between them: the loop takes several per wake-up
            probe.pub.publish(Float64MultiArray(data=row.tolist()))
        probe.until(lambda: len(probe.out) >= len(samples), f"{len(samples)} outputs")
        np.testing.assert_allclose(np.vstack(probe.out), core(samples), rtol=0, atol=1e-12)
        assert node.forwarded["array"] == len(samples)
    finally:
        probe.close()
        node.destroy_node()


def test_malformed_bytes_are_refused_with_the_reason_and_the_stream_goes_on(ros_context):
    node = make_node(ros_context)
    probe = Probe(ros_context, node)
    try:
        probe.discovered()
        samples = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9]])
        probe.pub.publish(Float64MultiArray(data=samples[0].tolist()))
        probe.until(lambda: len(probe.out) >= 1, "the first output")
        probe.pub.publish(b"\x00\x01\x00\x00\x05")  # a little-endian CDR header and one byte: truncated
        probe.until(lambda: node.rejections["malformed"] >= 1, "the refusal")
        for row in samples[1:]:
            probe.pub.publish(Float64MultiArray(data=row.tolist()))
        probe.until(lambda: len(probe.out) >= 3 and probe.refusals, "the next outputs and the diagnostics")
        np.testing.assert_allclose(np.vstack(probe.out), core(samples), rtol=0, atol=1e-12)
        assert any("malformed" in r and "/shaper/commands" in r for r in probe.refusals), probe.refusals
        assert node.forwarded["array"] == 3
    finally:
        probe.close()
        node.destroy_node()


def test_the_stream_topic_goes_through_the_loop_too(ros_context):
    node = make_node(ros_context)
    probe = Probe(ros_context, node)
    out: list[JointTrajectory] = []
    probe.node.create_subscription(JointTrajectory, "/joint_trajectory_controller/joint_trajectory", out.append, 10)
    pub = probe.node.create_publisher(JointTrajectory, "/shaper/joint_trajectory_stream", 10)
    try:
        probe.until(lambda: pub.get_subscription_count() >= 1, "the stream topic's discovery")
        msg = JointTrajectory(joint_names=list(reversed(JOINTS)),
                              points=[JointTrajectoryPoint(positions=[0.3, 0.2, 0.1])])
        pub.publish(msg)
        probe.until(lambda: out, "the shaped point")
        assert list(out[0].joint_names) == JOINTS
        np.testing.assert_allclose(out[0].points[0].positions, core(np.array([[0.1, 0.2, 0.3]]))[0], atol=1e-12)
        pub.publish(JointTrajectory(joint_names=["nope"], points=[JointTrajectoryPoint(positions=[0.0])]))
        probe.until(lambda: sum(node.rejections.values()) >= 1, "the refusal of an unknown joint")
        assert node.forwarded["stream"] == 1
    finally:
        probe.close()
        node.destroy_node()


def test_destroying_the_node_stops_the_loop_and_nothing_more_is_published(ros_context):
    node = make_node(ros_context)
    probe = Probe(ros_context, node)
    try:
        probe.discovered()
        probe.pub.publish(Float64MultiArray(data=[0.0, 0.0, 0.0]))
        probe.until(lambda: len(probe.out) >= 1, "the first output")
        loops = [t for t in threading.enumerate() if t.name == "shaper_stream executor"]
        assert len(loops) == 1 and loops[0].is_alive()
        probe.ex.remove_node(node)
        node.destroy_node()
        assert not loops[0].is_alive(), "the take loop's thread outlived its node"
        before = len(probe.out)
        probe.pub.publish(Float64MultiArray(data=[1.0, 1.0, 1.0]))
        probe.until(lambda: probe.pub.get_subscription_count() == 0, "the input's subscription gone")
        probe.ex.spin_once(timeout_sec=0.2)
        assert len(probe.out) == before
    finally:
        probe.close()
