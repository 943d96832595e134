"""The shaper node's stream topic on serialized messages (ros/raw_stream.py RawTrajectories) answers as the
message path does.

The message path is what the node did before on message objects (trajectory_arrays, the stamp and the
durations normalised, CommandStream.shape_points, trajectory_msg with the input's header); the raw path
must give the bytes rclpy serializes for that answer (outside the padding bytes), refuse what it refuses
with the same kind and text, and refuse malformed bytes with the reason before any filter: the stream
goes on from where it was.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.checks import MAX_JOINT_NAMES, InputError
from shaper_nodes.core.shaping import Mode, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.stream import NS, CommandStream, normal_stamp
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
from shaper_nodes.ros.conversions import trajectory_arrays, trajectory_msg
from shaper_nodes.ros.raw_stream import RawTrajectories

RATE = 1000.0
ZVD = discretize(design("zvd", [Mode.from_hz(8.0, 0.05)]), RATE)


def _stream(names: tuple[str, ...]) -> CommandStream:
    n = len(names)
    return CommandStream(ZVD, JointLimits.from_lists(names, [-2.0] * n, [2.0] * n, ()), max_abs=1e6)


def _message_path(stream: CommandStream, names: tuple[str, ...], msg: JointTrajectory) -> JointTrajectory:
    """The node's stream callback on message objects, as it was before the raw path."""
    times, fields = trajectory_arrays(msg, names, require_times=False, limit=stream.max_abs)
    stamp = msg.header.stamp
    stamp.sec, stamp.nanosec = normal_stamp(stamp.sec, stamp.nanosec)
    durations = [p.time_from_start for p in msg.points]
    for d in durations:
        if d.nanosec >= NS:
            d.sec, d.nanosec = normal_stamp(d.sec, d.nanosec)
    shaped = stream.shape_points(times, fields, (stamp.sec, stamp.nanosec))
    return trajectory_msg(msg.header, names, durations, shaped)


def _point(values, t_ns: int, vel=None, acc=None, effort=None) -> JointTrajectoryPoint:
    pt = JointTrajectoryPoint(positions=list(values), time_from_start=Duration(sec=t_ns // NS, nanosec=t_ns % NS))
    for f, v in (("velocities", vel), ("accelerations", acc), ("effort", effort)):
        if v is not None:
            setattr(pt, f, list(v))
    return pt


def _spoil(msg: JointTrajectory, which: int) -> None:
    """Make ``msg`` one the rules refuse, one class per ``which``."""
    n, npoints = len(msg.joint_names), len(msg.points)
    if which == 0:
        msg.joint_names[0] = "nobody"
    elif which == 1:
        msg.points[0].positions = msg.points[0].positions[:-1]
    elif which == 2:
        msg.points[-1].positions[0] = float("nan")
    elif which == 3:
        msg.points[0].positions[0] = 2.5  # beyond the limits
    elif which == 4:
        msg.points = []
    elif which == 5 and npoints > 1:
        msg.points[1].time_from_start = msg.points[0].time_from_start
    elif which == 6:
        msg.header.stamp.sec, msg.header.stamp.nanosec = 1, 0  # goes back
    elif which == 7 and npoints > 1:
        msg.points[0].velocities = [0.0] * n
        msg.points[1].velocities = []
    elif which == 8:
        msg.points[0].positions[0] = 1e7  # beyond max_abs


def _inputs(names: tuple[str, ...], rng: np.random.Generator) -> list[JointTrajectory]:
    """A stream of one to three points per message, in every joint order and with every field combination,
    with the stamps and durations a stream sends, and inputs the rules refuse."""
    n = len(names)
    out = []
    stamp_ns = 10 * NS
    for k in range(240):
        order = list(rng.permutation(n)) if k % 7 == 3 else list(range(n))
        npoints = 1 + k % 3
        x = np.clip(np.sin(0.02 * k + np.arange(n)) * 1.5 + rng.normal(0.0, 0.01, n), -1.9, 1.9)
        vel = k % 4 in (1, 2)
        acc = k % 8 == 2
        eff = k % 5 == 0
        msg = JointTrajectory(joint_names=[names[i] for i in order])
        msg.header.frame_id = ["", "base", "base_link", "wörld"][k % 4]
        stamp_ns += 2_000_000
        if k % 9 == 4:  # zero: "now"
            msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
        elif k % 11 == 6:  # nanosec beyond a second: carried into sec
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_ns // NS - 1, stamp_ns % NS + NS
        else:
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_ns // NS, stamp_ns % NS
        for i in range(npoints):
            v = x[order] + 0.001 * i
            msg.points.append(_point(v, 1_000_000 * (i + 1), vel=0.1 * v if vel else None,
                                     acc=-0.2 * v if acc else None, effort=np.ones(n) if eff else None))
        if k % 13 == 12:
            msg.points[0].time_from_start = Duration(sec=0, nanosec=NS + 5)  # a duration to normalise
            if npoints > 1:
                msg.points[0].time_from_start = Duration(sec=0, nanosec=500)
        if k % 17 == 16:
            _spoil(msg, k // 17 % 9)
        out.append(msg)
    return out


@pytest.mark.parametrize("names", [("j",), ("a", "bb", "ccc"), tuple(f"joint_{i}" for i in range(1, 7)),
                                   tuple(f"joint_{i}" for i in range(7))], ids=lambda n: f"{len(n)}joints")
def test_the_raw_path_answers_as_the_message_path_byte_for_byte(names: tuple[str, ...]) -> None:
    objects, raw = _stream(names), RawTrajectories(_stream(names), names)
    answers = refusals = 0
    for msg in _inputs(names, np.random.default_rng(len(names))):
        data = serialize_message(msg)
        try:
            expected = serialize_message(_message_path(objects, names, msg))
        except InputError as err:
            with pytest.raises(InputError) as got:
                raw.shape(data)
            assert (got.value.kind, str(got.value)) == (err.kind, str(err))
            refusals += 1
            continue
        answer = raw.shape(data)
        assert deserialize_message(answer, JointTrajectory) == deserialize_message(expected, JointTrajectory)
        layout = raw.codec.last_layout
        assert layout is not None
        ref = bytearray(expected[:len(answer)])
        for start, end in layout.padding:
            ref[start:end] = bytes(end - start)
        assert bytes(ref) == answer
        answers += 1
    assert answers >= 200 and refusals >= 8
    assert objects.last_stamp_ns == raw.stream.last_stamp_ns
    assert objects.fields == raw.stream.fields


def _valid(names: tuple[str, ...], value: float, t_ns: int = 1_000_000) -> bytes:
    return serialize_message(JointTrajectory(joint_names=list(names), points=[_point([value] * len(names), t_ns)]))


@pytest.mark.parametrize(("raw", "words"), [
    (b"", "encapsulation"),
    (b"\x00\x01\x00\x00\x01", "truncated"),
    (b"\x00\x00\x00\x00" + bytes(24), "little-endian"),
    (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + b"\x01\x00\x00\x00\x02\x00\x00\x00\xff\x00",
     "not UTF-8"),
])
def test_malformed_bytes_are_refused_and_the_stream_goes_on(raw: bytes, words: str) -> None:
    names = ("a", "b", "c")
    path, reference = RawTrajectories(_stream(names), names), _stream(names)
    for k in range(3):
        path.shape(_valid(names, 0.5, 1_000_000 * (k + 1)))
        reference.shape_points(np.array([0.001 * (k + 1)]), {"positions": np.full((1, 3), 0.5)})
    with pytest.raises(InputError, match=words) as err:
        path.shape(raw)
    assert err.value.kind == "malformed" and "\n" not in str(err.value)
    for k in range(5):  # the filters went on as if the malformed message never came
        got = deserialize_message(path.shape(_valid(names, 0.5 + 0.1 * k)), JointTrajectory).points[0].positions
        expected = reference.shape_points(np.array([0.001]), {"positions": np.full((1, 3), 0.5 + 0.1 * k)})
        assert got.tolist() == expected["positions"][0].tolist()


def test_every_truncation_and_corruption_is_refused_or_answered_never_a_crash() -> None:
    names = ("a", "bb", "ccc")
    raw = serialize_message(JointTrajectory(joint_names=list(names), points=[
        _point([0.1, 0.2, 0.3], 1_000_000, vel=[0.0] * 3), _point([0.1, 0.2, 0.3], 2_000_000, vel=[0.0] * 3)]))
    path = RawTrajectories(_stream(names), names)
    path.shape(raw)
    end = len(path.codec.encode((0, 0), "", names, [(0, 0)] * 2, {"positions": [[0.0] * 3] * 2,
                                                                  "velocities": [[0.0] * 3] * 2}))
    for n in range(end):
        with pytest.raises(InputError) as err:
            path.shape(raw[:n])
        assert err.value.kind == "malformed" and "\n" not in str(err.value)
    rng = np.random.default_rng(3)
    kinds = set()
    for _ in range(1500):
        bad = bytearray(raw)
        for i in rng.integers(0, len(raw), rng.integers(1, 4)):
            bad[i] = int(rng.integers(0, 256))
        try:
            answer = path.shape(bytes(bad))
        except InputError as err:
            assert "\n" not in str(err)
            kinds.add(err.kind)
        else:
            for p in deserialize_message(answer, JointTrajectory).points:
                assert np.all(np.isfinite(p.positions)) and np.all(np.abs(p.positions) <= 2.0)
    assert "malformed" in kinds and len(kinds) >= 3


def test_too_many_points_are_refused_before_any_is_read() -> None:
    """The message path's too_large, with its text, from the count alone (the points are not there)."""
    names = ("a",)
    raw = (b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + struct.pack("<I", 1)
           + b"\x02\x00\x00\x00a\x00" + bytes(2) + struct.pack("<I", MAX_TRAJECTORY_POINTS + 1))
    with pytest.raises(InputError) as err:
        RawTrajectories(_stream(names), names).shape(raw)
    assert err.value.kind == "too_large"
    assert str(err.value) == f"{MAX_TRAJECTORY_POINTS + 1} points exceed the limit of {MAX_TRAJECTORY_POINTS}"


def test_too_many_names_are_refused_as_the_message_path_refuses_them() -> None:
    """The message path's too_large for the names, with its text, before any name is decoded."""
    names = ("a", "b")
    msg = JointTrajectory(joint_names=["a"] * (MAX_JOINT_NAMES + 1), points=[_point([0.0], 1_000_000)])
    with pytest.raises(InputError) as expected:
        _message_path(_stream(names), names, msg)
    with pytest.raises(InputError) as got:
        RawTrajectories(_stream(names), names).shape(serialize_message(msg))
    text = f"{MAX_JOINT_NAMES + 1} joint names exceed the limit of {MAX_JOINT_NAMES} (2 joints are shaped here)"
    assert (got.value.kind, str(got.value)) == (expected.value.kind, str(expected.value)) == ("too_large", text)
