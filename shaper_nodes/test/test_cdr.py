"""The pre-serialized Imu, JointState and Clock are byte-equal to rclpy's serialization and read back equal.

Fast CDR leaves its buffer's old contents in the bytes that only pad for alignment (seen: an Imu with
frame_id 'tool0' had non-zero bytes after the string's NUL), so those bytes, which our serializer
names and zeroes, are left out of the comparison; every other byte must be equal. serialize_message
returns Fast DDS's size estimate, which aligns each empty sequence of doubles to 8 as if it had
elements (seen: JointState with an empty effort, 4 or 8 more bytes that nothing wrote): those trailing
bytes are allowed, up to 8 per empty sequence, and left out too.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState

from shaper_nodes.recordings.cdr import (
    IMU_FIELDS,
    ImuCdr,
    JointStateCdr,
    SerializedMessage,
    clock_cdr,
    goal_feedback_stamp,
    stamp_parts,
)

STAMPS = [(0, 0), (1, 999_999_999), (-3, 5), (2_147_483_647, 123)]
# frame ids of every length mod 8 (the doubles after the header are aligned to 8), and non-ASCII
FRAMES = ["", "a", "ab", "abc", "tool0", "flange", "tool0_12", "imu_link9", "werkzeug_ü"]


def _same(cdr: SerializedMessage, reference: bytes, empty_sequences: int = 0) -> None:
    """``cdr``'s bytes equal ``reference`` outside its padding; its padding bytes zero."""
    data = bytearray(cdr.data())
    assert len(data) <= len(reference) <= len(data) + 8 * empty_sequences
    ref = bytearray(reference[:len(data)])
    for start, end in cdr.padding:
        assert 0 < end - start < 8
        assert data[start:end] == bytes(end - start)
        ref[start:end] = bytes(end - start)
    assert data == ref


def _imu(frame_id: str, rng: np.random.Generator) -> tuple[Imu, ImuCdr]:
    msg, cdr = Imu(), ImuCdr(frame_id)
    msg.header.frame_id = frame_id
    for name, count in IMU_FIELDS:
        values = rng.normal(0.0, 50.0, count)
        values[0] = -abs(values[0])  # a negative value in every field
        getattr(cdr, name)[:] = values
        if name.endswith("covariance"):
            setattr(msg, name, values.tolist())
        else:
            sub = getattr(msg, name)
            for axis, v in zip("xyzw", values.tolist(), strict=False):
                setattr(sub, axis, v)
    return msg, cdr


@pytest.mark.parametrize("frame_id", FRAMES)
def test_imu_equals_rclpy(frame_id: str) -> None:
    rng = np.random.default_rng(len(frame_id))
    msg, cdr = _imu(frame_id, rng)
    _same(ImuCdr(frame_id), serialize_message(Imu(header=msg.header.__class__(frame_id=frame_id))))
    for sec, nanosec in STAMPS:
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        cdr.set_stamp(sec, nanosec)
        _same(cdr, serialize_message(msg))
        assert deserialize_message(cdr.data(), Imu) == msg


@pytest.mark.parametrize("names", [[], ["j"], ["joint_1", "joint_2"], [f"shoulder_{i}" for i in range(6)],
                                   ["a", "bb", "ccc", "dddd", "eeeee", "ffffff", "g"]])
@pytest.mark.parametrize("frame_id", ["", "base", "base_link"])
@pytest.mark.parametrize("sizes", [(6, 6, 6), (6, 6, 0), (1, 0, 0), (0, 0, 0), (3, 2, 7)])
def test_joint_state_equals_rclpy(names: list[str], frame_id: str, sizes: tuple[int, int, int]) -> None:
    rng = np.random.default_rng(sum(sizes) + len(names))
    cdr = JointStateCdr(names, *sizes, frame_id=frame_id)
    msg = JointState(name=names)
    msg.header.frame_id = frame_id
    _same(cdr, serialize_message(JointState(name=names, position=[0.0] * sizes[0],
                                                      velocity=[0.0] * sizes[1], effort=[0.0] * sizes[2],
                                                      header=msg.header)), sizes.count(0))
    for sec, nanosec in STAMPS:
        values = [rng.normal(0.0, 3.0, n) * np.where(np.arange(n) % 2, -1.0, 1.0) for n in sizes]
        for field, v in zip(("position", "velocity", "effort"), values, strict=True):
            getattr(cdr, field)[:] = v
            setattr(msg, field, v.tolist())
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        cdr.set_stamp(sec, nanosec)
        _same(cdr, serialize_message(msg), sizes.count(0))
        back = deserialize_message(cdr.data(), JointState)
        assert back == msg
        assert back.position.tolist() == values[0].tolist()  # every bit of the doubles


@pytest.mark.parametrize("stamp", STAMPS)
def test_clock_equals_rclpy(stamp: tuple[int, int]) -> None:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = stamp
    assert clock_cdr(*stamp) == serialize_message(msg)
    assert deserialize_message(clock_cdr(*stamp), Clock) == msg


@pytest.mark.parametrize("stamp", STAMPS)
def test_goal_feedback_stamp_reads_rclpys_feedback_message(stamp: tuple[int, int]) -> None:
    """The goal id and the header stamp of a FollowJointTrajectory FeedbackMessage as rclpy serializes it (joint
    names, three points filled), and of the same in big-endian CDR (the fields swapped by hand)."""
    import struct
    import uuid

    from control_msgs.action import FollowJointTrajectory

    msg = FollowJointTrajectory.Impl.FeedbackMessage()
    goal = uuid.uuid4().bytes
    msg.goal_id.uuid = list(goal)
    fb = msg.feedback
    fb.header.stamp.sec, fb.header.stamp.nanosec = stamp
    fb.header.frame_id = "base_link"
    fb.joint_names = [f"joint_{i}" for i in range(6)]
    for point in (fb.desired, fb.actual, fb.error):
        point.positions = [0.1 * i for i in range(6)]
        point.velocities = [0.2] * 6
    raw = serialize_message(msg)
    assert goal_feedback_stamp(raw) == (goal, stamp[0] + 1e-9 * stamp[1])
    big = bytearray(raw[:28])
    big[1] = 0  # CDR_BE
    big[20:28] = struct.pack(">iI", *stamp)
    assert goal_feedback_stamp(bytes(big)) == (goal, stamp[0] + 1e-9 * stamp[1])


def test_data_is_a_snapshot_and_stamp_parts_round_to_the_nanosecond() -> None:
    cdr = ImuCdr("tool0")
    cdr.linear_acceleration[:] = [1.0, 2.0, 3.0]
    before = cdr.data()
    cdr.linear_acceleration[0] = -9.81
    assert deserialize_message(before, Imu).linear_acceleration.x == 1.0
    assert deserialize_message(cdr.data(), Imu).linear_acceleration.x == -9.81
    assert stamp_parts(1.0000000004) == (1, 0)
    assert stamp_parts(2.5) == (2, 500_000_000)
    assert stamp_parts(0.002 * 1501) == (3, 2_000_000)
    assert not math.isnan(cdr.linear_acceleration_covariance.sum())
