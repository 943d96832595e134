"""The shaper node's array input on serialized messages (ros/raw_stream.py) answers as the message path does.

The message path is the core's rules on message objects (what the node did before: shape_array for a
sample, shape_block for a layout of [samples, joints], the input message sent on with the shaped
data); the raw path must give the bytes rclpy serializes for that answer (outside the padding bytes),
refuse what it refuses with the same kind, and refuse malformed bytes with the reason, before any
filter: the stream goes on from where it was, finite, within the limits.
"""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.lockstep import block_rows
from shaper_nodes.core.shaping import Mode, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.stream import CommandStream
from shaper_nodes.ros.raw_stream import RawArrays

RATE = 1000.0
NAMES = tuple(f"joint_{i}" for i in range(7))
ZVD = discretize(design("zvd", [Mode.from_hz(8.0, 0.05)]), RATE)
LOWER, UPPER = [-2.0] * 7, [2.0] * 7


def _stream() -> CommandStream:
    return CommandStream(ZVD, JointLimits.from_lists(NAMES, LOWER, UPPER, ()), max_abs=1e6, max_samples=50)


def _message_path(stream: CommandStream, msg: Float64MultiArray) -> Float64MultiArray:
    """The node's path on message objects (as it was before the raw path)."""
    if msg.layout.dim:
        rows = block_rows([d.size for d in msg.layout.dim], len(msg.data), stream.joints, stream.max_samples)
        if rows > 1:
            msg.data = stream.shape_block(msg.data, rows)
            return msg
    msg.data = stream.shape_array(msg.data)
    return msg


def _msg(values, dims=(), data_offset=0) -> Float64MultiArray:
    msg = Float64MultiArray(data=list(values))
    msg.layout.dim = [MultiArrayDimension(label=a, size=b, stride=c) for a, b, c in dims]
    msg.layout.data_offset = data_offset
    return msg


def _inputs(rng: np.random.Generator) -> list[Float64MultiArray]:
    """A stream of samples and blocks with every layout the node takes, and inputs it refuses."""
    out = []
    for k in range(300):
        x = np.clip(np.sin(0.01 * k + np.arange(7)) * 1.5 + rng.normal(0.0, 0.01, 7), -1.9, 1.9)
        kind = k % 10
        if kind == 3:
            out.append(_msg(x, [("joints", 7, 7)], k))
        elif kind == 5:
            rows = 1 + k % 4
            block = np.tile(x, rows)
            out.append(_msg(block, [("samples", rows, 7 * rows), ("joints", 7, 7)], k))
        elif kind == 7 and k % 20 == 7:  # refused by the rules: wrong size, beyond the limits, not finite
            bad = [x[:5], np.where(np.arange(7) == 2, 2.5, x), np.where(np.arange(7) == 4, np.nan, x)]
            out.append(_msg(bad[k // 20 % 3], (), k))
        elif kind == 9 and k % 30 == 9:  # a layout that does not describe the data
            out.append(_msg(np.tile(x, 2), [("samples", 3, 21), ("joints", 7, 7)], k))
        else:
            out.append(_msg(x, (), k))
    return out


def test_the_raw_path_answers_as_the_message_path_byte_for_byte() -> None:
    objects, raw = _stream(), RawArrays(_stream())
    refusals = 0
    for msg in _inputs(np.random.default_rng(7)):
        data = serialize_message(msg)
        try:
            expected = serialize_message(_message_path(objects, msg))
        except InputError as err:
            with pytest.raises(InputError) as got:
                raw.shape(data)
            assert got.value.kind == err.kind
            assert str(got.value) == str(err)
            refusals += 1
            continue
        answer = raw.shape(data)
        # rclpy's bytes and ours differ at most in padding (Fast CDR does not clear it): equal read back,
        # and equal bytes outside the padding the codec names
        assert deserialize_message(answer, Float64MultiArray) == deserialize_message(expected, Float64MultiArray)
        ref = bytearray(expected[:len(answer)])
        for start, end in raw.codec._out.padding:  # type: ignore[union-attr]
            ref[start:end] = bytes(end - start)
        assert bytes(ref) == answer
    assert refusals >= 15


@pytest.mark.parametrize(("raw", "words"), [
    (b"", "encapsulation"),
    (b"\x00\x01\x00\x00\x01", "truncated"),
    (b"\x00\x00\x00\x00" + bytes(12), "little-endian"),
    (b"\x00\x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x07\x00\x00\x00" + bytes(20), "7 doubles"),
])
def test_malformed_bytes_are_refused_and_the_stream_goes_on(raw: bytes, words: str) -> None:
    path, reference = RawArrays(_stream()), _stream()
    x = [0.5] * 7
    for _ in range(3):
        path.shape(serialize_message(_msg(x)))
        reference.shape_array(x)
    with pytest.raises(InputError, match=words) as err:
        path.shape(raw)
    assert err.value.kind == "malformed" and "\n" not in str(err.value)
    for k in range(5):  # the filters went on as if the malformed message never came
        y = [0.5 + 0.1 * k] * 7
        got = deserialize_message(path.shape(serialize_message(_msg(y))), Float64MultiArray).data.tolist()
        assert got == reference.shape_array(y)
        assert all(np.isfinite(got)) and all(-2.0 <= v <= 2.0 for v in got)


@pytest.mark.parametrize("names", [[], ["j"], list(NAMES), ["ä", "bb", "ccc", "dddd", "eeeee"]])
@pytest.mark.parametrize("sizes", [(0, 0), (3, 0), (0, 5), (2, 2)])
def test_joint_states_read_raw_as_rclpy_reads_them(names: list[str], sizes: tuple[int, int]) -> None:
    from sensor_msgs.msg import JointState

    from shaper_nodes.ros.raw_stream import RawJointStates

    poses, rng = RawJointStates(), np.random.default_rng(len(names))
    for stamp in [(0, 0), (5, 999_999_999), (-2, 1), (5, 999_999_999)]:
        msg = JointState(name=names, position=rng.normal(0.0, 2.0, len(names)).tolist(),
                         velocity=[1.5] * sizes[0], effort=[-2.5] * sizes[1])
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
        msg.header.frame_id = "base"[:len(names)]
        got = poses.decode(serialize_message(msg))
        assert got == (tuple(names), tuple(msg.position.tolist()), stamp)


def test_malformed_joint_states_are_refused_with_the_reason() -> None:
    """Every truncation before the positions' end, a name not UTF-8, big-endian bytes: refused as malformed."""
    from sensor_msgs.msg import JointState

    from shaper_nodes.ros.raw_stream import RawJointStates

    raw = serialize_message(JointState(name=list(NAMES), position=[0.25] * 7, velocity=[1.0] * 7))
    poses = RawJointStates()
    poses.decode(raw)
    end = poses._decoder.positions_end  # only what is read is checked: names, positions, stamp
    for poses in (RawJointStates(), RawJointStates()):
        for n in range(end):
            if n == 0:
                poses.decode(raw)  # the second decoder knows the layout: a short message must not pass its shortcut
                continue
            with pytest.raises(InputError) as err:
                poses.decode(raw[:n])
            assert err.value.kind == "malformed" and "\n" not in str(err.value)
    bad = bytearray(raw)
    bad[20:22] = b"\xff\xfe"  # inside the first name
    with pytest.raises(InputError, match="UTF-8"):
        RawJointStates().decode(bytes(bad))
    with pytest.raises(InputError, match="little-endian"):
        RawJointStates().decode(b"\x00\x00" + raw[2:])
