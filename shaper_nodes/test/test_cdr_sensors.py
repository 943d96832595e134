"""The checked Imu and JointState readers: what rclpy's deserialize_message reads, bit for bit; bytes cut short,
of another encoding or with broken strings refused with a CdrError naming the problem, never anything else."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, JointState

from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.recordings.cdr import ImuCdr, JointStateCdr
from shaper_nodes.recordings.cdr_sensors import CdrError, JointStateReader, decode_imu, decode_stamp

# frame ids of every length mod 8 (the header's end sets the alignment of what follows), and non-ASCII
FRAMES = ["", "a", "ab", "abc", "abcd", "abcde", "flange", "tool0_ü", "base_link_x"]
NAMES = [[], ["j"], ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
                    "wrist_3_joint"], ["a", "bb", "ccc", "dddd", "gelenk_ü"]]
STAMPS = [(0, 0), (1, 2), (12, 999_999_999), (-3, 500_000_000), (2**31 - 1, 1)]


def _imu(frame: str, rng: np.random.Generator, stamp: tuple[int, int]) -> Imu:
    m = Imu()
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = stamp
    v = rng.standard_normal(37) * 10.0 ** rng.integers(-300, 300, 37)
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = v[0:4]
    m.orientation_covariance = v[4:13].tolist()
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = v[13:16]
    m.angular_velocity_covariance = v[16:25].tolist()
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = v[25:28]
    m.linear_acceleration_covariance = v[28:37].tolist()
    return m


def _js(frame: str, names: list[str], sizes: tuple[int, int, int], rng: np.random.Generator,
        stamp: tuple[int, int]) -> JointState:
    m = JointState(name=names)
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = stamp
    m.position, m.velocity, m.effort = (rng.standard_normal(n).tolist() for n in sizes)
    return m


@pytest.mark.parametrize("frame", FRAMES)
def test_imu_reads_what_rclpy_reads(frame: str) -> None:
    rng = np.random.default_rng(len(frame))
    for stamp in STAMPS:
        raw = serialize_message(_imu(frame, rng, stamp))
        back = deserialize_message(raw, Imu)
        t, acc = decode_imu(raw)
        a = back.linear_acceleration
        assert acc == (a.x, a.y, a.z)
        assert t == stamp_to_sec(back.header.stamp) == decode_stamp(raw)


def test_imu_written_in_place_reads_back() -> None:
    """The sim plant's Imu bytes (recordings.cdr.ImuCdr) are read as rclpy reads them."""
    cdr = ImuCdr("flange")
    cdr.set_stamp(7, 250_000_000)
    cdr.linear_acceleration[:] = (0.1, -9.81, 1e-300)
    t, acc = decode_imu(cdr.data())
    back = deserialize_message(cdr.data(), Imu)
    assert acc == (back.linear_acceleration.x, back.linear_acceleration.y, back.linear_acceleration.z)
    assert acc == (0.1, -9.81, 1e-300) and t == 7.25


SIZES = [(0, 0, 0), (1, 0, 0), (6, 6, 6), (6, 0, 6), (5, 5, 0), (0, 3, 3)]


@pytest.mark.parametrize("frame", FRAMES)
def test_joint_state_reads_what_rclpy_reads(frame: str) -> None:
    rng = np.random.default_rng(len(frame))
    reader = JointStateReader()  # one reader over layouts that change, repeat, and change back
    for names, sizes, stamp in itertools.product(NAMES, SIZES, STAMPS[:3]):
        for _ in range(2):
            raw = serialize_message(_js(frame, names, sizes, rng, stamp))
            back = deserialize_message(raw, JointState)
            t, got_names, positions = reader(raw)
            assert got_names == tuple(back.name) == tuple(names)
            assert positions == tuple(back.position)
            assert t == stamp_to_sec(back.header.stamp)
            assert JointStateReader()(raw) == (t, got_names, positions)  # a fresh reader parses it alike


def test_joint_state_written_in_place_reads_back() -> None:
    """The sim plant's /joint_states bytes (recordings.cdr.JointStateCdr) are read as rclpy reads them."""
    cdr = JointStateCdr(["a", "bb", "ccc"], 3, 3, 3, frame_id="base")
    reader = JointStateReader()
    for k in range(3):
        cdr.set_stamp(k, 2_000_000)
        cdr.position[:] = (k, -0.5, 1e-9 * k)
        back = deserialize_message(cdr.data(), JointState)
        assert reader(cdr.data()) == (stamp_to_sec(back.header.stamp), ("a", "bb", "ccc"), tuple(back.position))


def _written_length(raw: bytes, kind: type) -> int:
    """The bytes that hold the message (serialize_message may add its size estimate's slack at the end)."""
    n = len(raw)
    while n > 0:
        try:
            if kind is Imu:
                decode_imu(raw[:n - 1])
            else:
                JointStateReader()(raw[:n - 1])
        except CdrError:
            return n
        n -= 1
    return n


@pytest.mark.parametrize("frame", ["", "abc", "tool0_ü"])
def test_every_cut_is_refused(frame: str) -> None:
    """Each prefix of a message (to its last byte) is refused with a CdrError, by a fresh reader and by one that
    has read the whole message (its remembered layout must not accept fewer bytes)."""
    rng = np.random.default_rng(0)
    for kind, msg in ((Imu, _imu(frame, rng, (1, 2))),
                      (JointState, _js(frame, NAMES[2], (6, 6, 6), rng, (1, 2))),
                      (JointState, _js(frame, NAMES[3], (5, 0, 5), rng, (1, 2)))):
        raw = serialize_message(msg)
        end = _written_length(raw, kind)
        assert end >= len(raw) - 8
        primed = JointStateReader()
        if kind is JointState:
            primed(raw)
        for n in range(end):
            cut = raw[:n]
            with pytest.raises(CdrError, match=r"truncated|not a little-endian") as err:
                decode_imu(cut) if kind is Imu else JointStateReader()(cut)
            assert "\n" not in str(err.value)
            if kind is JointState:
                with pytest.raises(CdrError):
                    primed(cut)


def test_refusals_name_the_problem() -> None:
    rng = np.random.default_rng(1)
    imu = bytearray(serialize_message(_imu("abc", rng, (1, 2))))
    js = bytearray(serialize_message(_js("abc", ["j1", "j2"], (2, 2, 2), rng, (1, 2))))
    for raw in (imu, js):
        big = bytearray(raw)
        big[1] = 0  # big-endian CDR
        with pytest.raises(CdrError, match=r"not a little-endian plain CDR .*encapsulation 00 00"):
            decode_imu(big) if raw is imu else JointStateReader()(big)
        with pytest.raises(CdrError, match="not a little-endian"):
            decode_stamp(b"")
    no_nul = bytearray(imu)
    no_nul[19] = ord("x")  # frame_id "abc": length 4 at 12, bytes 16..19 with the NUL at 19
    with pytest.raises(CdrError, match="frame_id does not end with its NUL"):
        decode_imu(no_nul)
    huge = bytearray(imu)
    huge[12:16] = (2**32 - 1).to_bytes(4, "little")
    with pytest.raises(CdrError, match="frame_id of length 4294967295"):
        decode_imu(huge)
    # names: "j1" at 24 (length 3 at 24, bytes 28..30), "j2" at 32 (bytes 36..38)
    assert bytes(js[28:31]) == b"j1\x00" and bytes(js[36:39]) == b"j2\x00"
    cases = {30: (ord("x"), "name 0 does not end with its NUL"), 29: (0, "name 0 holds a NUL before its end"),
             37: (0xFF, "name 1 is not UTF-8")}
    for at, (value, problem) in cases.items():
        bad = bytearray(js)
        bad[at] = value
        with pytest.raises(CdrError, match=problem):
            JointStateReader()(bad)
    many = bytearray(js)
    many[20:24] = (10**6).to_bytes(4, "little")  # the name count
    with pytest.raises(CdrError, match="1000000 names do not fit"):
        JointStateReader()(many)


def test_corrupt_bytes_give_a_cdr_error_or_a_reading_never_another_exception() -> None:
    rng = np.random.default_rng(2)
    sources = [serialize_message(_imu("abc", rng, (1, 2))),
               serialize_message(_js("base", NAMES[2], (6, 6, 6), rng, (1, 2)))]
    reader = JointStateReader()
    reader(sources[1])
    refused = read = 0
    for k in range(4000):
        raw = bytearray(sources[k % 2])
        for at in rng.integers(0, len(raw), rng.integers(1, 4)):
            raw[at] = int(rng.integers(0, 256))
        try:
            decode_imu(raw) if k % 2 == 0 else reader(raw)
            read += 1
        except CdrError as err:
            assert "\n" not in str(err)
            refused += 1
    assert refused > 100 and read > 100
