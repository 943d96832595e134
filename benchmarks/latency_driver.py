"""The latency bench's driver: an rclpy node that publishes on a node's input, paced by the wall clock, and
time-stamps the replies on its output (driver -> node -> driver, two hops; :mod:`benchmarks.latency`).

Sends are paced by a wall-clock loop in a thread of their own (absolute deadlines ``t0 + k / rate`` with
``time.sleep``; when more than one period late the schedule is re-anchored rather than bursting), stamped
with :func:`time.perf_counter_ns` just before ``publish``; replies are stamped on entry to the subscription
callback (the caller's thread spins the driver in a ``SingleThreadedExecutor``, :func:`spin_until`). The
sequence number of each message travels in ``layout.data_offset`` (:mod:`benchmarks.latency_replies`).
:mod:`benchmarks.streaming_gap` drives the shaper with it too.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import rclpy.context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from .echo_node import DEPTH

__all__ = ["REPLY_DEPTH", "Driver", "spin_until"]

#: QoS depth of the driver's reply subscription
REPLY_DEPTH = 1000


class Driver(Node):
    """Publishes on the node's input, time-stamps the replies on its output.

    Parameters
    ----------
    in_topic, out_topic : str
        The node's input (the driver publishes there) and output (the driver listens there).
    context : rclpy.context.Context
        The context of this measurement.
    """

    def __init__(self, in_topic: str, out_topic: str, context: rclpy.context.Context,
                 name: str = "bench_driver") -> None:
        super().__init__(name, context=context)
        self.in_topic, self.out_topic = in_topic, out_topic
        self.pub = self.create_publisher(Float64MultiArray, in_topic, DEPTH)
        # a deep queue on the measuring side, so that the driver itself never drops a reply
        self.create_subscription(Float64MultiArray, out_topic, self._on_reply, REPLY_DEPTH)
        self.replies: list[tuple[int, int, object]] = []

    def _on_reply(self, msg: Float64MultiArray) -> None:
        self.replies.append((time.perf_counter_ns(), msg.layout.data_offset, msg.data))

    def discovered(self) -> bool:
        """Whether the node's subscription and publisher are both seen."""
        return self.pub.get_subscription_count() >= 1 and self.count_publishers(self.out_topic) >= 1

    def send_paced(self, rows: np.ndarray, rate: float, stamps: np.ndarray | None = None,
                   stop: threading.Event | None = None, first_seq: int = 0) -> int:
        """Publish the rows of ``rows`` one per period (wall clock), cycling until ``stop`` if given.

        Parameters
        ----------
        rows : ndarray, shape (n, joints)
            Data to send, in order.
        rate : float
            Send rate, Hz.
        stamps : ndarray of int64, shape (n,), optional
            Receives the :func:`time.perf_counter_ns` stamp taken just before each publish.
        stop : threading.Event, optional
            If given, keep sending (cycling through ``rows``) until it is set.
        first_seq : int
            If > 0, row ``i`` is sent with ``layout.data_offset = first_seq + i``; else with 0.

        Returns
        -------
        int
            Number of messages sent.
        """
        period = round(1e9 / rate)
        msg = Float64MultiArray()
        lists = rows.tolist()
        deadline = time.perf_counter_ns()
        i = 0
        while (i < len(lists)) if stop is None else not stop.is_set():
            msg.data = lists[i % len(lists)]
            msg.layout.data_offset = first_seq + i if first_seq > 0 else 0
            now = time.perf_counter_ns()
            if now < deadline:
                time.sleep((deadline - now) * 1e-9)
            elif now - deadline > period:
                deadline = now  # more than a period late: re-anchor instead of bursting
            t = time.perf_counter_ns()
            self.pub.publish(msg)
            if stamps is not None:
                stamps[i] = t
            deadline += period
            i += 1
        return i


def spin_until(executor: SingleThreadedExecutor, done: Callable[[], bool], timeout: float,
               check: Callable[[], None] | None = None) -> bool:
    """Spin ``executor`` until ``done()`` (True), or for at most ``timeout`` s (False); ``check()`` is called
    before every spin (it may raise, e.g. when a node under test has died)."""
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            return False
        if check is not None:
            check()
        executor.spin_once(timeout_sec=0.02)
    return True
