"""Simulated time (``use_sim_time``) taken on a thread of its own, not on the node's executor.

rclpy's ``TimeSource`` subscribes the node itself to ``/clock`` (KEEP_LAST 1, best effort), so every
``/clock`` message wakes the node's executor, which builds its wait set again over every entity of the
node (its services, timers, subscriptions and their QoS event handlers) to serve one clock tick. The sim
plant in lockstep publishes ``/clock`` after every 1 ms step, several thousand a second when it runs faster
than real time: a node with sim time that had nothing else to do spent most of a core on its wait set
(the shaper node 20 CPU s of the demo's 56 s calibration; docs/results/benchmarks.md, "Issue 34,
session 23").

:class:`ClockOnSide` moves that subscription to a lean side node served by a
:class:`~.take_loop.TakeLoop` (one wait set of one subscription, built once), which hands each message to
the node's own ``TimeSource.clock_callback``: the node's clocks get the same times in the same order,
from another thread. This is rclcpp's default (``NodeOptions::use_clock_thread``). A ROS-time timer of
the node still wakes its executor when it is due: rcl triggers the timer's guard condition from the clock's
jump callback when the new time passes the timer's next call, whichever thread sets the time.

``TimeSource`` keeps the subscription in an attribute (``_clock_sub``), makes it in a method
(``_subscribe_to_clock_topic``) that turning ``use_sim_time`` on at run time calls again, and keeps its
clocks and the last time in ``_associated_clocks`` and ``_last_time_set``; all rclpy internals (locked
rclpy 7.1.6), checked by name in ``tests/test_sim_clock.py``.
"""

from __future__ import annotations

from typing import Any

from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock

from shaper_nodes.recordings.cdr import time_ns

from .side_node import SideNode

#: the rclpy internals of ``TimeSource`` used here (checked by the test named in the module docstring)
INTERNALS = ("_clock_sub", "_subscribe_to_clock_topic", "_associated_clocks", "_last_time_set")
#: rclpy's own QoS for ``/clock`` (``TimeSource._subscribe_to_clock_topic``)
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


class ClockOnSide:
    """``node``'s ``/clock`` subscription on a lean side node ``<node>_clock`` (module docstring); made when
    ``use_sim_time`` is on, now or later; :meth:`close` before the node is destroyed."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.side: SideNode | None = None
        source: Any = node._time_source
        self._source = source
        source._subscribe_to_clock_topic = self._subscribe  # use_sim_time turned on later comes here
        if source._clock_sub is not None:  # made by the node's constructor: moved
            node.destroy_subscription(source._clock_sub)
            source._clock_sub = None
            self._subscribe()

    def _subscribe(self) -> None:
        if self.side is not None:
            return
        side = SideNode(self.node, "clock", take=True)
        side.node.create_subscription(Clock, "/clock", self._on_clock, CLOCK_QOS, raw=True)
        self.side = side.start()

    def _on_clock(self, raw: bytes) -> None:
        """``TimeSource.clock_callback`` on the serialized message: the time kept, and set on every clock."""
        t = Time(nanoseconds=time_ns(raw), clock_type=ClockType.ROS_TIME)
        source = self._source
        source._last_time_set = t
        for clock in tuple(source._associated_clocks):  # (a clock attached meanwhile by another thread)
            clock.set_ros_time_override(t)

    def close(self) -> None:
        """Stop the side node's loop and destroy it (once)."""
        if self.side is not None:
            side, self.side = self.side, None
            side.close()
