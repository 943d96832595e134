"""Simulated time off the node's executor (ros/sim_clock.py, ros/side_node.py's follow_parent_time), over DDS in
one process: the node's clock follows /clock while its executor does not spin, a ROS-time timer still fires when
/clock passes it, use_sim_time turned on at run time, a side node's clock with its parent's."""

from __future__ import annotations

import importlib.metadata
import time

import pytest
import rclpy.context
from rclpy.clock import ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.time_source import TimeSource
from rosgraph_msgs.msg import Clock

from shaper_nodes.ros.side_node import SideNode
from shaper_nodes.ros.sim_clock import INTERNALS, ClockOnSide

#: the rclpy ros/sim_clock.py was written against (requirements.lock)
LOCKED_RCLPY = "7.1.6"
WAIT = 60.0  # s: generous, a busy machine's discovery


def test_the_rclpy_internals_sim_clock_uses_are_there():
    """Fails by name when rclpy changes what ros/sim_clock.py relies on (then read it again)."""
    version = importlib.metadata.version("ros-rclpy")
    assert version == LOCKED_RCLPY, f"rclpy {version}, ros/sim_clock.py was checked against {LOCKED_RCLPY}"
    source = TimeSource()
    for name in INTERNALS:
        assert hasattr(source, name), f"rclpy's TimeSource has no {name}"


def _sim_node(ctx, name: str, sim: bool = True) -> Node:
    return Node(name, context=ctx, parameter_overrides=[Parameter("use_sim_time", value=sim)])


def _clock_topics(node: Node) -> list[str]:
    return [s.topic_name for s in node.subscriptions if s.topic_name == "/clock"]


def _publish_until(pub, stamp_s: float, done, timeout: float = WAIT, spin=None) -> None:
    """Publish /clock at ``stamp_s`` (s, or ns as an int above 1e12; again every 10 ms: best effort, the first may
    go before discovery) until ``done()`` or the timeout; ``spin()`` runs between the messages if given."""
    msg = Clock()
    ns = stamp_s if isinstance(stamp_s, int) and stamp_s > 10**12 else int(round(stamp_s * 1e9))
    msg.clock.sec, msg.clock.nanosec = divmod(ns, 1_000_000_000)
    end = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < end, f"/clock at {stamp_s} s not seen in {timeout} s"
        pub.publish(msg)
        if spin is not None:
            spin()
        else:
            time.sleep(0.01)


def test_the_clock_follows_clock_with_the_executor_idle(ros_context):
    node = _sim_node(ros_context, "clocked")
    clock = ClockOnSide(node)
    sender = Node("clock_sender", context=ros_context)
    try:
        assert _clock_topics(node) == [], "the node kept its own /clock subscription"
        assert clock.side is not None and _clock_topics(clock.side.node) == ["/clock"]
        assert clock.side.node.get_name() == "clocked_clock"
        pub = sender.create_publisher(Clock, "/clock", 10)
        # nobody spins `node`: the side node's loop sets its clock
        for t in (12.5, 13.0, 20.25):
            _publish_until(pub, t, lambda t=t: node.get_clock().now().nanoseconds == int(t * 1e9))
        big = 1_764_460_800_123_456_789  # a wall-clock-like time, to the ns
        _publish_until(pub, big, lambda: node.get_clock().now().nanoseconds == big)
        assert node.get_clock().clock_type == ClockType.ROS_TIME and node.get_clock().ros_time_is_active
    finally:
        clock.close()
        sender.destroy_node()
        node.destroy_node()
    assert clock.side is None


def test_a_ros_time_timer_fires_when_clock_passes_it(ros_context):
    """The executor waits on the node alone (no /clock on it); a timer of 1 s of sim time fires once /clock
    has passed it (rcl's jump callback triggers the timer's guard condition from the clock's thread)."""
    node = _sim_node(ros_context, "timed")
    clock = ClockOnSide(node)
    sender = Node("clock_sender", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    fired: list[int] = []
    try:
        pub = sender.create_publisher(Clock, "/clock", 10)
        _publish_until(pub, 100.0, lambda: node.get_clock().now().nanoseconds == 100_000_000_000)
        node.create_timer(1.0, lambda: fired.append(node.get_clock().now().nanoseconds))
        executor.spin_once(timeout_sec=0.05)
        assert fired == [], "the timer fired before sim time reached it"
        _publish_until(pub, 101.5, lambda: bool(fired), spin=lambda: executor.spin_once(timeout_sec=0.01))
        assert fired[0] >= 101_000_000_000
    finally:
        executor.shutdown()
        clock.close()
        sender.destroy_node()
        node.destroy_node()


def test_use_sim_time_turned_on_at_run_time_takes_clock_on_the_side(ros_context):
    node = _sim_node(ros_context, "later", sim=False)
    clock = ClockOnSide(node)
    sender = Node("clock_sender", context=ros_context)
    try:
        assert clock.side is None and _clock_topics(node) == []
        node.set_parameters([Parameter("use_sim_time", value=True)])
        assert _clock_topics(node) == [], "turning use_sim_time on subscribed the node itself"
        assert clock.side is not None
        pub = sender.create_publisher(Clock, "/clock", 10)
        _publish_until(pub, 7.0, lambda: node.get_clock().now().nanoseconds == 7_000_000_000)
        node.set_parameters([Parameter("use_sim_time", value=False)])
        assert not node.get_clock().ros_time_is_active
        assert node.get_clock().now().nanoseconds > 1_000_000_000 * 1_000_000  # the system clock again
    finally:
        clock.close()
        sender.destroy_node()
        node.destroy_node()


def test_a_side_node_keeps_its_parents_time_without_a_clock_subscription(domain_id):
    """A side node that is not lean takes the process's ``-p use_sim_time:=true``; its clock is set with its
    parent's, from the parent's one /clock subscription."""
    ctx = rclpy.context.Context()
    rclpy.init(args=["node", "--ros-args", "-p", "use_sim_time:=true"], context=ctx, domain_id=domain_id)
    parent = Node("parent", context=ctx)
    clock = ClockOnSide(parent)
    side = SideNode(parent, "work")
    sender = Node("clock_sender", context=ctx)
    try:
        assert side.node.get_parameter("use_sim_time").value is True
        assert _clock_topics(side.node) == [] and _clock_topics(parent) == []
        assert clock.side is not None and _clock_topics(clock.side.node) == ["/clock"]
        pub = sender.create_publisher(Clock, "/clock", 10)
        _publish_until(pub, 3.25, lambda: side.node.get_clock().now().nanoseconds == 3_250_000_000)
        assert side.node.get_clock().ros_time_is_active
    finally:
        side.close()
        clock.close()
        sender.destroy_node()
        parent.destroy_node()
        ctx.try_shutdown()


@pytest.mark.parametrize("sim", [False, True])
def test_a_side_node_of_a_parent_on_the_system_clock_is_left_alone(ros_context, sim):
    parent = _sim_node(ros_context, "plain", sim=False)
    side = SideNode(parent, "work")
    try:
        if sim:
            side.node.set_parameters([Parameter("use_sim_time", value=True)])
            assert _clock_topics(side.node) == ["/clock"], "a side node on sim time of its own lost its /clock"
        else:
            assert _clock_topics(side.node) == []
    finally:
        side.close()
        parent.destroy_node()
