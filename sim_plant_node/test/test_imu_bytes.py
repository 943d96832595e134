"""The sim plant's accelerometer written as bytes in place (node/sensors.Sensors.publish_imu) is the Imu message the
node built before: rclpy reads back the same message, and the bytes are rclpy's ``serialize_message`` outside the
padding, with and without noise, bias and a gyro, and across a live change of the sensor settings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu

from shaper_nodes.core.cycles import CycleMonitor
from shaper_nodes.recordings.cdr import ImuCdr, stamp_parts
from sim_plant_node.node.parameters import ImuParams, JointStatesParams
from sim_plant_node.node.sensors import Sensors


class _Reference:
    """The Imu message object as the node built it before (sensors.py before the bytes), its noise drawn from its
    own generator seeded alike, in the same order."""

    def __init__(self, imu: ImuParams) -> None:
        self.rng = np.random.default_rng(int(imu.seed))
        self.msg = Imu()
        self.msg.orientation_covariance[0] = -1.0
        self.msg.header.frame_id = str(imu.frame_id)
        self.gyro_sigma: float | None = None
        self.take(imu)

    def take(self, imu: ImuParams) -> None:
        self.bias, self.gyro_bias = np.asarray(imu.bias, float)[:3], np.asarray(imu.gyro_bias, float)[:3]
        self.sigma, self.gsigma = float(imu.noise_stddev), float(imu.gyro_noise_stddev)

    def __call__(self, t: float, acc: np.ndarray, rate: np.ndarray | None) -> Imu:
        acc = acc + self.bias
        if self.sigma > 0:
            acc += self.rng.normal(0.0, self.sigma, 3)
        imu = self.msg
        imu.header.stamp.sec, imu.header.stamp.nanosec = stamp_parts(t)
        if rate is None:
            imu.angular_velocity_covariance[0] = -1.0
        else:
            rate = rate + self.gyro_bias
            if self.gsigma > 0:
                rate = rate + self.rng.normal(0.0, self.gsigma, 3)
            imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z = rate.tolist()
            if self.gsigma != self.gyro_sigma:
                s2 = self.gsigma**2
                imu.angular_velocity_covariance = [s2, 0.0, 0.0, 0.0, s2, 0.0, 0.0, 0.0, s2]
                self.gyro_sigma = self.gsigma
        imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = acc.tolist()
        imu.linear_acceleration_covariance[0] = imu.linear_acceleration_covariance[4] = \
            imu.linear_acceleration_covariance[8] = self.sigma**2
        return imu


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def publish(self, data: bytes) -> None:
        assert isinstance(data, bytes)
        self.sent.append(data)


def _same_outside_padding(frame: str, data: bytes, reference: bytes) -> None:
    ref = bytearray(reference[:len(data)])
    for start, end in ImuCdr(frame).padding:
        ref[start:end] = data[start:end]
    assert bytes(ref) == data
    assert len(reference) == len(data)


@pytest.mark.parametrize("frame", ["tool0", "", "imu", "a_frame_of_eight"])
@pytest.mark.parametrize("noisy", [False, True])
def test_the_bytes_are_the_message_the_node_built(frame: str, noisy: bool) -> None:
    imu = ImuParams(frame_id=frame, seed=7, noise_stddev=0.05 if noisy else 0.0, bias=(0.1, -0.2, 0.3),
                    gyro_noise_stddev=0.01 if noisy else 0.0, gyro_bias=(0.0, 0.02, -0.01) if noisy else (0.0,) * 3)
    pub = _Publisher()
    sensors = Sensors(["j1", "j2"], imu, JointStatesParams(), pub, CycleMonitor(0.01))
    reference = _Reference(imu)
    rng = np.random.default_rng(3)
    for k in range(300):
        t = k / 1000.0 + (1e-10 if k % 7 == 3 else 0.0)
        acc = rng.normal(0.0, 5.0, 3)
        rate = None if k < 20 else rng.normal(0.0, 1.0, 3)  # (a 1-D plant has no gyro; the arm has)
        if k % 50 == 10:  # the extremes of a float64
            acc[k % 3] = -np.finfo(float).max / 2
        if k == 150:  # a live change of the sensor settings (on_set_parameters)
            imu = dataclasses.replace(imu, noise_stddev=0.2, gyro_noise_stddev=0.0 if noisy else 0.3)
            sensors.changed(imu, JointStatesParams())
            reference.take(imu)
        sensors.publish_imu(t, acc.copy(), None if rate is None else rate.copy())
        expected = reference(t, acc, rate)
        data = pub.sent[-1]
        assert deserialize_message(data, Imu) == expected, k
        _same_outside_padding(frame, data, serialize_message(expected))
