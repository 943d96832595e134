"""A draining subscription (ros/lockstep_reader.subscribe_draining) over real DDS: a burst published while the
reader does not spin is taken whole at its next wake-up, in order, each message once; a batch bound splits it
into wake-ups; the message info comes along when asked; a callback that destroys the subscription ends the batch.
Polled (the default): the subscription is out of the executor's wait set and the node's poll timer takes the
queue, in order, each message once, several subscriptions on one timer; ``poll=0`` wakes the executor per batch.
"""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu

from shaper_nodes.recordings.cdr_sensors import decode_imu
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import STREAM_QOS, OutOfWaitSet, subscribe_draining

pytestmark = pytest.mark.integration

BURST = 500


class _Rig:
    """A writer node and a reader node on one executor; the reader's callback records stamps and wake-ups."""

    def __init__(self, context, topic: str) -> None:
        self.writer = rclpy.create_node("burst_writer", context=context)
        self.reader = rclpy.create_node("burst_reader", context=context)
        self.pub = self.writer.create_publisher(Imu, topic, STREAM_QOS)
        self.ex = SingleThreadedExecutor(context=context)
        for n in (self.writer, self.reader):
            self.ex.add_node(n)

    def spin_until(self, done, what: str, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def burst(self, sub) -> list[int]:
        """Publish BURST samples (stamps k ms) while nothing spins; return once the reader acknowledged them all
        (reliable: they sit in its queue, none taken yet). Returns their stamps in ms."""
        self.spin_until(lambda: self.pub.get_subscription_count() and sub.get_publisher_count(), "discovery")
        stamps = [k * 1e-3 for k in range(1, BURST + 1)]
        msg = Imu()
        for k, t in enumerate(stamps):
            msg.header.stamp = sec_to_time(t)
            msg.linear_acceleration.z = float(k)
            self.pub.publish(serialize_message(msg))
        assert self.pub.wait_for_all_acked(Duration(seconds=60)), "the reader did not acknowledge the burst"
        return list(range(1, BURST + 1))

    def close(self) -> None:
        self.ex.shutdown()
        self.writer.destroy_node()
        self.reader.destroy_node()


def _count_wake_ups(sub, wakes: list[int], got: list) -> None:
    """Wrap the callback rclpy calls once per wake-up so that ``wakes`` gets ``len(got)`` at each."""
    callback = sub.callback

    def counted(*args):
        wakes.append(len(got))
        callback(*args)
    sub.callback = counted


def test_a_burst_is_taken_at_one_wake_up_in_order_once(ros_context):
    rig = _Rig(ros_context, "/drain_burst")
    got: list[tuple[float, float]] = []
    wakes: list[int] = []  # the number of samples taken before each wake-up's first

    def on_imu(raw: bytes) -> None:
        t, a = decode_imu(raw)
        got.append((t, a[2]))

    sub = subscribe_draining(rig.reader, Imu, "/drain_burst", on_imu, STREAM_QOS, poll=0)
    _count_wake_ups(sub, wakes, got)
    try:
        stamps = rig.burst(sub)
        rig.spin_until(lambda: len(got) >= BURST, "the burst")
        assert [round(t * 1e3) for t, _ in got] == stamps  # every sample once, in order
        assert [z for _, z in got] == [float(k) for k in range(BURST)]
        assert wakes == [0]  # the whole queue at the first wake-up
        rig.ex.spin_once(timeout_sec=0.1)
        assert len(got) == BURST
    finally:
        rig.close()


def test_a_batch_bound_splits_the_burst_into_wake_ups(ros_context):
    rig = _Rig(ros_context, "/drain_batches")
    got: list[float] = []
    wakes: list[int] = []

    sub = subscribe_draining(rig.reader, Imu, "/drain_batches", lambda raw: got.append(decode_imu(raw)[0]),
                             STREAM_QOS, batch=120, poll=0)
    _count_wake_ups(sub, wakes, got)
    try:
        stamps = rig.burst(sub)
        rig.spin_until(lambda: len(got) >= BURST, "the burst")
        assert [round(t * 1e3) for t in got] == stamps
        assert wakes == [0, 120, 240, 360, 480]
    finally:
        rig.close()


@pytest.mark.parametrize("poll", [0.0, 0.005])
def test_the_message_info_comes_with_each_message(ros_context, poll):
    rig = _Rig(ros_context, "/drain_info")
    got: list[tuple[float, int]] = []
    sub = subscribe_draining(rig.reader, Imu, "/drain_info",
                             lambda raw, info: got.append((decode_imu(raw)[0], info["received_timestamp"])),
                             STREAM_QOS, info=True, poll=poll)
    try:
        stamps = rig.burst(sub)
        rig.spin_until(lambda: len(got) >= BURST, "the burst")
        assert [round(t * 1e3) for t, _ in got] == stamps
        received = [r for _, r in got]
        assert all(r > 0 for r in received) and received == sorted(received)
    finally:
        rig.close()


@pytest.mark.parametrize("poll", [0.0, 0.005])
def test_a_callback_that_destroys_the_subscription_ends_the_batch(ros_context, poll):
    rig = _Rig(ros_context, "/drain_destroy")
    got: list[float] = []
    subs = []

    def on_imu(raw: bytes) -> None:
        got.append(decode_imu(raw)[0])
        if len(got) == 10:
            rig.reader.destroy_subscription(subs[0])

    subs.append(subscribe_draining(rig.reader, Imu, "/drain_destroy", on_imu, STREAM_QOS, poll=poll))
    try:
        rig.burst(subs[0])
        rig.spin_until(lambda: len(got) >= 10, "the first samples")
        for _ in range(5):
            rig.ex.spin_once(timeout_sec=0.02)
        assert len(got) == 10
    finally:
        rig.close()


def test_a_batch_below_one_is_refused(ros_context):
    node = rclpy.create_node("drain_refused", context=ros_context)
    try:
        with pytest.raises(ValueError, match="batch must be at least 1, got 0"):
            subscribe_draining(node, Imu, "/x", lambda raw: None, STREAM_QOS, batch=0)
        with pytest.raises(ValueError, match=r"poll must be in \[0, 1\] s, got -0.1"):
            subscribe_draining(node, Imu, "/x", lambda raw: None, STREAM_QOS, poll=-0.1)
        with pytest.raises(ValueError, match="a polled subscription has a callback group of its own"):
            subscribe_draining(node, Imu, "/x", lambda raw: None, STREAM_QOS, callback_group=OutOfWaitSet())
    finally:
        node.destroy_node()


def test_polled_subscriptions_are_out_of_the_wait_set_and_taken_by_one_timer(ros_context):
    """Two polled streams on one reader: the executor never waits on them (no wake-up per message), the node has
    one poll timer for both, and each burst is taken whole, in order, each sample once."""
    rig = _Rig(ros_context, "/drain_poll_a")
    pub_b = rig.writer.create_publisher(Imu, "/drain_poll_b", STREAM_QOS)
    got: dict[str, list[float]] = {"a": [], "b": []}
    timers_before = len(list(rig.reader.timers))
    sub_a = subscribe_draining(rig.reader, Imu, "/drain_poll_a", lambda raw: got["a"].append(decode_imu(raw)[0]),
                               STREAM_QOS)
    sub_b = subscribe_draining(rig.reader, Imu, "/drain_poll_b", lambda raw: got["b"].append(decode_imu(raw)[0]),
                               STREAM_QOS)
    try:
        assert len(list(rig.reader.timers)) == timers_before + 1  # one poll timer for the node
        assert not rig.ex.can_execute(sub_a) and not rig.ex.can_execute(sub_b)  # left out of the wait set
        stamps = rig.burst(sub_a)
        rig.spin_until(lambda: pub_b.get_subscription_count() and sub_b.get_publisher_count(), "discovery of b")
        msg = Imu()
        for k in range(1, BURST + 1):
            msg.header.stamp = sec_to_time(k * 1e-3)
            pub_b.publish(serialize_message(msg))
        rig.spin_until(lambda: len(got["a"]) >= BURST and len(got["b"]) >= BURST, "both bursts")
        for name in ("a", "b"):
            assert [round(t * 1e3) for t in got[name]] == stamps  # every sample once, in order
        rig.ex.spin_once(timeout_sec=0.05)
        assert len(got["a"]) == len(got["b"]) == BURST
    finally:
        rig.close()
