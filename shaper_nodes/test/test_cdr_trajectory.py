"""JointTrajectory CDR: read as rclpy reads it, written byte-equal to rclpy's serialization, refused when malformed.

The padding rule is test_cdr.py's: the bytes that only align the next field are left out of the
comparison (Fast CDR leaves its buffer's old contents there; ours are zero), and serialize_message's
size estimate may end a few bytes after the written data.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.recordings.cdr_arrays import CdrError
from shaper_nodes.recordings.cdr_trajectory import (
    POINT_FIELDS,
    JointTrajectoryCodec,
    TooManyNames,
    TooManyPoints,
    Trajectory,
    decode_joint_trajectory,
)

# names of every length mod 4 (each string's end sets the alignment of what follows), and non-ASCII
NAME_SETS = [[], ["j"], ["ab"], ["abc"], ["abcd"], [f"joint_{i}" for i in range(7)],
             ["a", "bb", "ccc", "dddd", "eeeee", "gelenk_ü"], [f"j{i}" for i in range(1, 7)]]
FRAMES = ["", "b", "base_link", "wörld"]


def _msg(rng: np.random.Generator, names: list[str], frame: str, npoints: int, counts: tuple[int, ...] | None = None,
         stamp: tuple[int, int] = (12, 345)) -> JointTrajectory:
    """A message whose points carry each field with ``counts`` values (random per point when None)."""
    msg = JointTrajectory(joint_names=names)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    for _ in range(npoints):
        c = counts if counts is not None else tuple(int(v) for v in rng.integers(0, 8, 4))
        pt = JointTrajectoryPoint(time_from_start=Duration(sec=int(rng.integers(-5, 5)),
                                                           nanosec=int(rng.integers(0, 2**32))))
        for f, n in zip(POINT_FIELDS, c, strict=True):
            setattr(pt, f, (rng.normal(0.0, 10.0, n) * 10.0 ** rng.integers(-300, 300, n)).tolist())
        msg.points.append(pt)
    return msg


def _equal(got: Trajectory, msg: JointTrajectory) -> None:
    assert (got.stamp.sec, got.stamp.nanosec) == (msg.header.stamp.sec, msg.header.stamp.nanosec)
    assert got.frame_id == msg.header.frame_id
    assert list(got.joint_names) == list(msg.joint_names)
    assert len(got.points) == len(msg.points)
    for p, q in zip(got.points, msg.points, strict=True):
        for f in POINT_FIELDS:
            assert list(getattr(p, f)) == getattr(q, f).tolist()  # every bit of the doubles
        assert (p.time_from_start.sec, p.time_from_start.nanosec) == (q.time_from_start.sec, q.time_from_start.nanosec)


def _same_bytes(codec: JointTrajectoryCodec, data: bytes, reference: bytes, points: int) -> None:
    """``data`` (just written by ``codec``) equals ``reference`` outside the padding; its padding zero. (Fast
    DDS's size estimate counts up to 8 bytes of alignment for every sequence of doubles, empty or not.)"""
    assert len(data) <= len(reference) <= len(data) + 8 + 32 * points
    ref, got = bytearray(reference[:len(data)]), bytearray(data)
    assert codec.last_layout is not None
    for start, end in codec.last_layout.padding:
        assert 0 < end - start < 8
        assert got[start:end] == bytes(end - start)
        ref[start:end] = bytes(end - start)
    assert got == ref


@pytest.mark.parametrize("names", NAME_SETS, ids=lambda n: f"{len(n)}names-{sum(map(len, n))}chars")
def test_read_as_rclpy_reads_and_written_as_rclpy_writes(names: list[str]) -> None:
    rng = np.random.default_rng(len(names) * 7 + sum(map(len, names)))
    codec, writer = JointTrajectoryCodec(), JointTrajectoryCodec()
    for frame, npoints in itertools.product(FRAMES, (0, 1, 2, 5)):
        for counts in (None, (0, 0, 0, 0), (len(names),) * 4, (len(names), 0, len(names), 0)):
            msg = _msg(rng, names, frame, npoints, counts, stamp=(int(rng.integers(-2**31, 2**31)),
                                                                  int(rng.integers(0, 2**32))))
            raw = serialize_message(msg)
            _equal(decode_joint_trajectory(raw), msg)
            _equal(codec.decode(raw), msg)  # the names parsed, or taken from the previous message
            got = codec.decode(raw)
            fields = {f: [list(getattr(p, f)) for p in got.points] for f in POINT_FIELDS
                      if any(getattr(p, f) for p in got.points)}
            data = writer.encode((got.stamp.sec, got.stamp.nanosec), got.frame_id, got.joint_names,
                                 [(p.time_from_start.sec, p.time_from_start.nanosec) for p in got.points], fields)
            _same_bytes(writer, data, raw, npoints)
            assert deserialize_message(data, JointTrajectory) == msg
            _equal(decode_joint_trajectory(data), msg)


def test_the_codec_reads_a_new_layout_after_a_known_one() -> None:
    """Names, frame and point layouts change from message to message: each read as rclpy reads it."""
    rng = np.random.default_rng(34)
    codec = JointTrajectoryCodec()
    for k in range(300):
        names = NAME_SETS[int(rng.integers(len(NAME_SETS)))]
        msg = _msg(rng, names, FRAMES[k % len(FRAMES)], int(rng.integers(0, 4)))
        _equal(codec.decode(serialize_message(msg)), msg)


def test_padding_bytes_are_not_read() -> None:
    """Whatever the padding holds (Fast CDR leaves old bytes there), the message reads the same."""
    msg = JointTrajectory(joint_names=["a", "bb"])  # frame_id "" (5 bytes): padding before the names' count
    msg.points.append(JointTrajectoryPoint(positions=[1.0, 2.0], velocities=[3.0, 4.0],
                                           time_from_start=Duration(sec=1, nanosec=5)))
    writer = JointTrajectoryCodec()
    data = bytearray(writer.encode((0, 0), "", ["a", "bb"], [(1, 5)], {"positions": [[1.0, 2.0]],
                                                                        "velocities": [[3.0, 4.0]]}))
    assert writer.last_layout is not None and writer.last_layout.padding
    for start, end in writer.last_layout.padding:
        data[start:end] = b"\xa5" * (end - start)
    for decode in (decode_joint_trajectory, JointTrajectoryCodec().decode):
        _equal(decode(bytes(data)), msg)


def _one_line(err: CdrError) -> str:
    text = str(err)
    assert text and "\n" not in text
    return text


def test_every_truncation_is_refused_with_the_reason() -> None:
    rng = np.random.default_rng(5)
    raw = serialize_message(_msg(rng, ["ab", "c", "joint_3"], "base", 3, (3, 3, 0, 3)))
    end = len(JointTrajectoryCodec().encode((0, 0), "base", ["ab", "c", "joint_3"], [(0, 0)] * 3,
                                            {"positions": [[0.0] * 3] * 3, "velocities": [[0.0] * 3] * 3,
                                             "effort": [[0.0] * 3] * 3}))
    known = JointTrajectoryCodec()
    known.decode(raw)  # names known to the codec: a shorter message must not take its shortcut
    for n in range(end):
        for decode in (decode_joint_trajectory, known.decode):
            with pytest.raises(CdrError) as err:
                decode(raw[:n])
            text = _one_line(err.value)
            assert any(w in text for w in ("truncated", "past its end", "encapsulation", "does not fit")), text


@pytest.mark.parametrize(("raw", "words"), [
    (b"", "encapsulation none"),
    (b"\x00\x00\x00\x00" + bytes(20), "not a little-endian"),  # big-endian CDR
    (b"\x00\x03\x00\x00" + bytes(20), "not a little-endian"),  # parameter list
    (b"\x00\x01\x00\x00" + bytes(8) + bytes(4) + bytes(8), "frame_id: a string of length 0"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x02\x00\x00\x00ab" + bytes(10), "frame_id does not end with its NUL"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x03\x00\x00\x00a\x00\x00" + bytes(9), "a NUL before its end"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x02\x00\x00\x00\xff\x00" + bytes(10), "not UTF-8"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + b"\xff\xff\xff\x7f" + bytes(8),
     "joint names at byte 24 do not fit"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + b"\x01\x00\x00\x00\x32\x00\x00\x00ab"
     + bytes(6), "joint name 0: a string of length 50"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + bytes(4) + b"\x00\x00\x00\x10"
     + bytes(24), "points at byte 28 do not fit"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + bytes(4) + b"\x01\x00\x00\x00"
     + b"\x09\x00\x00\x00" + bytes(20), "point 0 positions, 9 doubles"),
])
def test_malformed_buffers_are_refused_with_the_reason(raw: bytes, words: str) -> None:
    for decode in (decode_joint_trajectory, JointTrajectoryCodec().decode):
        with pytest.raises(CdrError, match=words) as err:
            decode(raw)
        _one_line(err.value)


def test_too_many_points_or_names_are_refused_before_any_is_read() -> None:
    raw = serialize_message(JointTrajectory(joint_names=["a", "b"], points=[JointTrajectoryPoint()] * 4))
    assert len(decode_joint_trajectory(raw, max_points=4, max_names=2).points) == 4
    for decode in (decode_joint_trajectory, JointTrajectoryCodec().decode):
        with pytest.raises(TooManyPoints, match="4 points exceed the limit of 3"):
            decode(raw, max_points=3)
        with pytest.raises(TooManyNames, match="2 joint names exceed the limit of 1") as err:
            decode(raw, max_names=1)
        assert err.value.count == 2


def test_corrupted_bytes_are_read_or_refused_never_crash() -> None:
    """Any few bytes changed in a valid message: a CdrError, or a reading whose values fit in the buffer."""
    rng = np.random.default_rng(34)
    raw = serialize_message(_msg(rng, ["a", "bb", "ccc"], "base", 3, (3, 3, 0, 1)))
    codec = JointTrajectoryCodec()
    read = refused = 0
    for _ in range(3000):
        bad = bytearray(raw)
        for i in rng.integers(0, len(raw), rng.integers(1, 4)):
            bad[i] = int(rng.integers(0, 256))
        cut = bytes(bad[:int(rng.integers(len(raw) // 2, len(raw) + 1))]) if rng.random() < 0.2 else bytes(bad)
        for decode in (decode_joint_trajectory, codec.decode):
            try:
                got = decode(cut, max_points=1000)
            except CdrError as err:
                _one_line(err)
                refused += 1
            else:
                values = sum(len(getattr(p, f)) for p in got.points for f in POINT_FIELDS)
                assert 8 * values + 24 * len(got.points) <= len(cut)
                read += 1
    assert read and refused


def test_encode_refuses_what_is_not_a_trajectory() -> None:
    codec = JointTrajectoryCodec()
    with pytest.raises(ValueError, match="not fields"):
        codec.encode((0, 0), "", ["a"], [(0, 0)], {"jerks": [[1.0]]})
    with pytest.raises(ValueError, match="one row per point"):
        codec.encode((0, 0), "", ["a"], [(0, 0), (0, 1)], {"positions": [[1.0]]})
    with pytest.raises(ValueError, match="NUL"):
        codec.encode((0, 0), "", ["a\x00b"], [(0, 0)], {"positions": [[1.0]]})
