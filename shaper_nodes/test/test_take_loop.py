"""The take loop's use of rclpy internals (pinned to the locked rclpy), and what it refuses to serve."""

from __future__ import annotations

import contextlib
import importlib.metadata
import inspect
import queue
import threading
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.event_handler import EventHandler, SubscriptionEventCallbacks
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM
from std_msgs.msg import Float64MultiArray

from shaper_nodes.ros.take_loop import EVENT_HANDLE, INTERNALS, TakeLoop

#: the rclpy the loop was written and measured against (requirements.lock)
LOCKED_RCLPY = "7.1.6"


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx, domain_id=199)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_the_rclpy_internals_the_take_loop_uses_are_there(context):
    """Fails by name when rclpy changes what ros/take_loop.py relies on (then read it again)."""
    version = importlib.metadata.version("ros-rclpy")
    assert version == LOCKED_RCLPY, f"rclpy {version}, the take loop was checked against {LOCKED_RCLPY}"
    for name in INTERNALS:
        assert hasattr(_rclpy, name), f"rclpy's implementation has no {name}"
    for method in ("clear_entities", "add_subscription", "add_guard_condition", "add_event", "is_ready", "wait",
                   "get_ready_entities", "destroy_when_not_in_use"):
        assert hasattr(_rclpy.WaitSet, method), f"_rclpy.WaitSet has no {method}"
    assert hasattr(_rclpy.GuardCondition, "trigger_guard_condition")
    assert hasattr(_rclpy.Subscription, "take_message"), "_rclpy.Subscription has no take_message"
    assert {"MessageOnly", "WithMessageInfo"} <= set(Subscription.CallbackType.__members__)
    node = Node("take_probe", context=context)
    try:
        sub = node.create_subscription(Float64MultiArray, "take_probe", lambda m, i: None, 1, raw=True)
        assert sub._callback_type is Subscription.CallbackType.WithMessageInfo
        handlers = [w for w in node.waitables if type(w) is EventHandler]
        assert handlers, "a subscription has no rclpy EventHandler any more"
        assert all(hasattr(w, EVENT_HANDLE) and hasattr(w, "_event_index") for w in handlers), \
            f"rclpy's EventHandler keeps its handle elsewhere than {EVENT_HANDLE} or has no _event_index"
        assert sub.handle.take_message(Float64MultiArray, True) is None  # nothing sent: None, not a tuple
        ws = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, context.handle)
        ws.clear_entities()
        ws.add_subscription(sub.handle)
        gc = _rclpy.GuardCondition(context.handle)
        ws.add_guard_condition(gc)
        gc.trigger_guard_condition()
        ws.wait(-1)  # the guard condition wakes it
        assert gc.pointer in ws.get_ready_entities("guard_condition")
        assert sub.handle.pointer not in ws.get_ready_entities("subscription")
    finally:
        node.destroy_node()
    assert "raw" in inspect.signature(Node.create_subscription).parameters


def test_a_node_with_more_than_subscriptions_is_refused_by_name(context):
    node = Node("take_probe", context=context)
    try:
        node.create_timer(1.0, lambda: None)
        with pytest.raises(ValueError, match="subscriptions only; node take_probe has timers"):
            TakeLoop(node, "loop")
    finally:
        node.destroy_node()


def test_the_loop_stops_when_asked_with_nothing_received(context):
    node = Node("take_probe", context=context, start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
    try:
        node.create_subscription(Float64MultiArray, "take_probe", lambda m: None, 1)
        loop = TakeLoop(node, "loop").start()
        assert loop.running
        loop.stop(timeout=10.0)
        assert not loop.running
        assert loop.taken == {"/take_probe": 0}
    finally:
        node.destroy_node()


def test_a_shutdown_of_the_context_ends_the_loop(context):
    node = Node("take_probe", context=context, start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
    node.create_subscription(Float64MultiArray, "take_probe", lambda m: None, 1)
    loop = TakeLoop(node, "loop").start()
    context.try_shutdown()
    loop.join(10.0)  # a state: the thread's end, with a generous bound
    assert not loop.running, "the take loop kept waiting after its context was shut down"


def test_a_qos_event_of_a_subscription_is_served_by_the_loop(context):
    """The event handlers the loop adds and checks by their handles still get their events: a best-effort
    publisher on a reliable subscription's topic (over real DDS) reaches the subscription's incompatible-QoS
    callback, and the messages of a compatible publisher still reach the message callback."""
    node = Node("take_probe", context=context, start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
    events: queue.Queue = queue.Queue()
    got: queue.Queue = queue.Queue()
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Float64MultiArray, "take_probe", got.put, reliable,
                             event_callbacks=SubscriptionEventCallbacks(incompatible_qos=events.put))
    loop = TakeLoop(node, "loop").start()
    peer = Node("take_peer", context=context)
    try:
        peer.create_publisher(Float64MultiArray, "take_probe",
                              QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        info = events.get(timeout=30.0)  # a state: the event, with a generous bound
        assert info.total_count >= 1
        pub = peer.create_publisher(Float64MultiArray, "take_probe", reliable)
        deadline = time.monotonic() + 30.0
        while got.empty() and time.monotonic() < deadline:  # until matched: publish, wait for a message (a state)
            pub.publish(Float64MultiArray(data=[1.0, 2.0]))
            with contextlib.suppress(queue.Empty):
                got.put(got.get(timeout=0.2))
        assert list(got.get(timeout=1.0).data) == [1.0, 2.0]
        assert loop.running
    finally:
        loop.stop(timeout=10.0)
        peer.destroy_node()
        node.destroy_node()


def test_a_qos_event_is_served_while_messages_flow(context):
    """An incompatible-QoS event on one subscription reaches its callback while another subscription gets a
    message every millisecond (the loop waking for messages), and the messages keep coming (a guard for any
    change that takes the event handlers off the per-message path)."""
    node = Node("take_probe", context=context, start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
    events: queue.Queue = queue.Queue()
    got: list = []
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Float64MultiArray, "take_flow", got.append, reliable)
    node.create_subscription(Float64MultiArray, "take_probe", lambda m: None, reliable,
                             event_callbacks=SubscriptionEventCallbacks(incompatible_qos=events.put))
    loop = TakeLoop(node, "loop").start()
    peer = Node("take_peer", context=context)
    stop = threading.Event()
    flow = peer.create_publisher(Float64MultiArray, "take_flow", reliable)

    def publish() -> None:
        while not stop.wait(0.001):
            flow.publish(Float64MultiArray(data=[1.0]))

    sender = threading.Thread(target=publish, daemon=True)
    sender.start()
    try:
        deadline = time.monotonic() + 30.0
        while len(got) < 200 and time.monotonic() < deadline:  # a state: the flow matched and running
            time.sleep(0.01)
        assert len(got) >= 200, "the flowing subscription got no messages"
        peer.create_publisher(Float64MultiArray, "take_probe",
                              QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        info = events.get(timeout=30.0)  # a state: the event, with a generous bound
        assert info.total_count >= 1
        before = len(got)
        deadline = time.monotonic() + 30.0
        while len(got) < before + 100 and time.monotonic() < deadline:  # a state: more messages
            time.sleep(0.01)
        assert len(got) >= before + 100 and loop.running
    finally:
        stop.set()
        sender.join(10.0)
        loop.stop(timeout=10.0)
        peer.destroy_node()
        node.destroy_node()
