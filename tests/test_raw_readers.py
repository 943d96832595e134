"""A raw reader of the arm's streams (the identifier, in-process) over real DDS: bytes that are not the message are
dropped without stopping the node, and the next good sample is taken, its stamp acknowledged."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu, JointState

from shaper_nodes.nodes.identifier import IdentifierNode
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import STREAM_QOS

pytestmark = pytest.mark.integration


def test_the_identifier_drops_bytes_that_are_not_the_message_and_takes_the_next(ros_context):
    node = IdentifierNode(context=ros_context, parameter_overrides=[Parameter("topics.imu_reliable", value=True)])
    probe = rclpy.create_node("probe", context=ros_context)
    imu_pub = probe.create_publisher(Imu, "/tip_imu", STREAM_QOS)
    js_pub = probe.create_publisher(JointState, "/joint_states", STREAM_QOS)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (node, probe):
        ex.add_node(n)

    def spin_until(done, what: str, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            ex.spin_once(timeout_sec=0.02)  # a callback that raised would raise here

    try:
        spin_until(lambda: imu_pub.get_subscription_count() and js_pub.get_subscription_count(), "discovery")
        imu, js = Imu(), JointState(name=["a", "b"], position=[0.1, 0.2])
        imu.header.stamp = js.header.stamp = sec_to_time(0.5)
        imu.linear_acceleration.z = 9.81
        good_imu, good_js = serialize_message(imu), serialize_message(js)
        big_endian = bytes([0, 0]) + good_imu[2:]
        for bad in (good_imu[:30], big_endian):  # cut in the covariances; another encoding
            imu_pub.publish(bad)
        js_pub.publish(good_js[:-30])  # the positions cut
        assert node.lockstep.processed is None
        imu.header.stamp = js.header.stamp = sec_to_time(1.0)
        imu_pub.publish(serialize_message(imu))
        js_pub.publish(serialize_message(js))
        # the good samples come after the bad ones on the same reliable writers: once they are taken, the bad
        # ones were read and dropped, and the node went on
        gaps = node.lockstep.gaps
        spin_until(lambda: gaps["/tip_imu"].samples and gaps["/joint_states"].samples, "the good samples")
        for topic in ("/tip_imu", "/joint_states"):  # one sample taken on each, the good one
            assert (gaps[topic].samples, gaps[topic].last) == (1, 1.0), topic
        assert node.lockstep.processed == 1.0
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()
