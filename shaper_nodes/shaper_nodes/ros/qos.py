"""The suite's QoS profiles, chosen on purpose and defined once.

LATCHED
    RELIABLE + TRANSIENT_LOCAL, depth 1: state that a late joiner must get (the active shaper,
    the mode estimate). Subscribers use the same profile.
IMU_QOS
    The accelerometer stream: best effort as sensors publish, volatile, but a deep queue (5000
    samples): a node that computes between callbacks (identification, learning) must not drop
    the samples that arrive meanwhile, and with the default sensor-data depth (5) a busy machine
    drops samples and the measured residual depends on the load.
SERVICE_QOS, ACTION_QOS
    Every service and action server of the suite: reliable, volatile, KEEP_ALL, on the request reader
    and the reply writer alike. rclpy's default for services is KEEP_LAST 10: a burst of calls beyond
    10 waiting requests was dropped by the middleware and their callers waited for ever (20 of 2000
    ``shaper_at`` calls, 11 of 1000 cancels answered). A deeper KEEP_LAST is no cure: with KEEP_LAST
    1000, 1500 calls sent at once got no answer at all (measured, Fast DDS 2.14). With KEEP_ALL the
    middleware keeps every request until the node takes it, within its resource limits, past which
    reliable flow control makes the callers' writers wait instead of dropping: 4000 calls from 8
    callers at once were all answered (``tests/test_service_queues.py`` sends 2000). Every handler
    does bounded work and answers at once, so the queue drains at the handler's rate. A caller's own
    client must hold its burst (rclpy's client default is KEEP_LAST 10: its writer drops the oldest
    unacknowledged request beyond 10). ``ACTION_QOS`` gives the same profile to an action server's
    goal, cancel and result services (keyword arguments of ``rclpy.action.ActionServer``).
FEEDBACK_QOS
    An action's feedback, on the server's writer (in ``ACTION_QOS``) and on every client's reader
    (``ACTION_CLIENT_QOS``): reliable, KEEP_LAST 1000. rclpy's default is KEEP_LAST 10, and a client
    that reads a goal's start from its first feedback (calibrate) lost it: a simulator in lockstep runs
    a goal at several times real time, 20 feedbacks a simulated second, while the client's executor is
    busy with a batch of samples, and the oldest of 10 were dropped; calibrate then took a start up to
    0.6 s late and waited for samples past the end of the motion (the walkthrough failed 3 in 5 runs at
    load 20). 1000 is 50 s of feedback at the controller's 20 Hz.
NoDefaultQosEvents
    A node mixin: its publishers and subscriptions carry no QoS event handlers but those asked for. rclpy gives
    each two by default (incompatible QoS, incompatible type: a warning when such a peer shows), and every one is
    a waitable the executor adds to its wait set at every wake-up. For the nodes that stand in for a robot or
    drive a test (the sim plant, the conductor): the peer's side (the shaper, the scheduler, ...) keeps its
    handlers and warns. The sim plant of seed 004's scheduler case: 20 % less CPU per run (testing.md).
"""

from __future__ import annotations

from typing import Any

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
IMU_QOS = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.VOLATILE)

#: the depth a KEEP_ALL profile carries (rclpy needs one; the middleware's resource limits bound the queue)
SERVICE_DEPTH = 1000
SERVICE_QOS = QoSProfile(depth=SERVICE_DEPTH, history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
FEEDBACK_QOS = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
_ACTION_SERVICES = {"goal_service_qos_profile": SERVICE_QOS, "result_service_qos_profile": SERVICE_QOS,
                    "cancel_service_qos_profile": SERVICE_QOS}
ACTION_QOS = {**_ACTION_SERVICES, "feedback_pub_qos_profile": FEEDBACK_QOS}
#: the same for an action client's goal, cancel and result services and its feedback (keyword arguments of
#: ActionClient; ResilientActionClient takes them by default)
ACTION_CLIENT_QOS = {**_ACTION_SERVICES, "feedback_sub_qos_profile": FEEDBACK_QOS}
#: the shaper node's ``~/shaped_goals`` (ros/shaped_goals.py), publisher and subscribers: latched, the last 16 goals
#: (the proxy holds at most 16 at once), so a subscriber that matches late still gets the goals under way
SHAPED_GOALS_QOS = QoSProfile(depth=16, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)

__all__ = ["ACTION_CLIENT_QOS", "ACTION_QOS", "FEEDBACK_QOS", "IMU_QOS", "LATCHED", "SERVICE_DEPTH", "SERVICE_QOS",
           "SHAPED_GOALS_QOS", "NoDefaultQosEvents"]


class NoDefaultQosEvents:
    """Mix into a :class:`rclpy.node.Node` subclass (before ``Node``): ``create_publisher`` and
    ``create_subscription`` without rclpy's default QoS event handlers, unless ``event_callbacks`` is given."""

    def create_publisher(self, *args: Any, **kwargs: Any) -> Any:
        kwargs.setdefault("event_callbacks", PublisherEventCallbacks(use_default_callbacks=False))
        return super().create_publisher(*args, **kwargs)  # type: ignore[misc]

    def create_subscription(self, *args: Any, **kwargs: Any) -> Any:
        kwargs.setdefault("event_callbacks", SubscriptionEventCallbacks(use_default_callbacks=False))
        return super().create_subscription(*args, **kwargs)  # type: ignore[misc]
