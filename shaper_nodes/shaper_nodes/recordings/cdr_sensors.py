"""Checked readers of serialized sensor_msgs/Imu and JointState: the stamp and the fields a reader uses.

The suite's readers of the simulated arm (the demo's client, calibrate, the identifier) take the
per-step topics with ``raw=True`` subscriptions: the callback gets the serialized ``bytes`` and no
message object is built (most of what a Python subscriber spends per message is that conversion;
docs/results/benchmarks.md). Unlike :func:`~.cdr.imu_fast` and :class:`~.cdr.JointStateDecoder` (for
recordings that the reader's bounds already checked), these readers take bytes from the wire and check
them first: bytes that are not little-endian plain CDR, that are cut short, or whose strings lack
their NUL are refused with a :class:`~.cdr_arrays.CdrError` whose one-line message names the problem;
nothing else is raised.

- :func:`decode_imu`: the header stamp (s) and ``linear_acceleration`` (m/s^2) of an Imu; the
  whole message must be there (its 37 float64 after the header); ``frame_id`` is checked for its
  NUL, not decoded.
- :class:`JointStateReader`: the header stamp, ``name`` and ``position`` (rad or m) of a JointState;
  the velocity and effort sequences must fit in the bytes (their values are not read). The layout
  of the last message (frame_id, names, the sequences' counts, the length) is remembered: a message of
  the same layout is read with a few byte comparisons and one unpack.

The stamp is ``sec + 1e-9 * nanosec`` s, the value :func:`shaper_nodes.core.stamps.stamp_to_sec`
gives for the message object. The wire format is :mod:`.cdr`'s (alignment counted from the end of
the 4-byte encapsulation header). Checked against rclpy's ``deserialize_message`` in
``shaper_nodes/test/test_cdr_sensors.py``. The module imports neither rclpy nor message types.
"""

from __future__ import annotations

import struct
from typing import Any

from .cdr import IMU_FIELDS
from .cdr_arrays import CdrError

__all__ = ["IMU_DOUBLES", "CdrError", "JointStateReader", "decode_imu", "decode_stamp"]

_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_D3 = struct.Struct("<3d")
#: the float64 values of an Imu after its header
IMU_DOUBLES = sum(n for _, n in IMU_FIELDS)
#: byte offset of linear_acceleration from the first of those values
_ACCEL_AT = 8 * sum(n for name, n in IMU_FIELDS[:IMU_FIELDS.index(("linear_acceleration", 3))])


def _align(pos: int, n: int) -> int:
    return 4 + ((pos - 4 + n - 1) & ~(n - 1))


def _head(raw: Any, what: str) -> int:
    """Check the encapsulation and the header (stamp, frame_id with its NUL); the offset after frame_id."""
    size = len(raw)
    if size < 16 or raw[0] != 0 or raw[1] != 1:
        head = bytes(raw[:2]).hex(" ") or "none"
        if size >= 4 and raw[0] == 0 and raw[1] == 1:
            raise CdrError(f"truncated {what}: its header does not fit in {size} bytes")
        raise CdrError(f"not a little-endian plain CDR {what} (encapsulation {head}, {size} bytes)")
    (n,) = _U32.unpack_from(raw, 12)
    if n == 0 or 16 + n > size:
        raise CdrError(f"truncated {what}: a frame_id of length {n} at byte 16 does not fit in {size} bytes")
    if raw[15 + n] != 0:
        raise CdrError(f"{what}'s frame_id does not end with its NUL")
    return 16 + n


def _u32(raw: Any, pos: int, what: str, field: str) -> tuple[int, int]:
    pos = _align(pos, 4)
    if pos + 4 > len(raw):
        raise CdrError(f"truncated {what}: {field} at byte {pos} is past its end ({len(raw)} bytes)")
    return _U32.unpack_from(raw, pos)[0], pos + 4


def _doubles(raw: Any, pos: int, what: str, field: str) -> tuple[int, int, int]:
    """A float64 sequence at ``pos``: (count, offset of its first value, offset after it)."""
    count, pos = _u32(raw, pos, what, f"the {field} count")
    at = _align(pos, 8) if count else pos
    end = at + 8 * count
    if end > len(raw):
        raise CdrError(f"truncated {what}: {count} {field} values at byte {at} do not fit in {len(raw)} bytes")
    return count, at, end


def decode_stamp(raw: Any, what: str = "message") -> float:
    """The header stamp, s, of a serialized message that begins with a std_msgs/Header (its header checked).

    Raises
    ------
    CdrError
        Not little-endian plain CDR, or the header cut short; the message names ``what``.
    """
    _head(raw, what)
    sec, nanosec = _STAMP.unpack_from(raw, 4)
    return sec + 1e-9 * nanosec


def decode_imu(raw: Any) -> tuple[float, tuple[float, float, float]]:
    """(header stamp in s, linear acceleration in m/s^2 as x, y, z) of a serialized sensor_msgs/Imu.

    Parameters
    ----------
    raw : bytes-like
        The serialized message (what a ``raw=True`` subscription receives).

    Raises
    ------
    CdrError
        Not little-endian plain CDR, cut short, or a frame_id without its NUL.
    """
    at = _align(_head(raw, "Imu"), 8)
    if at + 8 * IMU_DOUBLES > len(raw):
        raise CdrError(f"truncated Imu: {IMU_DOUBLES} float64 values at byte {at} do not fit in {len(raw)} bytes")
    sec, nanosec = _STAMP.unpack_from(raw, 4)
    return sec + 1e-9 * nanosec, _D3.unpack_from(raw, at + _ACCEL_AT)


class JointStateReader:
    """Reads serialized sensor_msgs/JointState: (header stamp in s, names, positions in rad or m).

    One caller at a time (a subscription's callback); it remembers the last message's layout.
    """

    def __init__(self) -> None:
        self._prefix = b""  # the bytes from the frame_id's length to the position count, of the last layout
        # the velocity and effort counts of the last layout: their offsets and their bytes
        self._velocity_at, self._velocity_count, self._effort_at, self._effort_count = 0, b"", 0, b""
        self._end = -1  # the bytes the last layout needs (-1: none yet)
        self._names: tuple[str, ...] = ()
        self._at = 0
        self._unpack = struct.Struct("<0d")

    def __call__(self, raw: Any) -> tuple[float, tuple[str, ...], tuple[float, ...]]:
        """The stamp, names and positions of ``raw``.

        Raises
        ------
        CdrError
            Not little-endian plain CDR, cut short (the velocities and efforts included), a string without
            its NUL or with one inside, or a name not UTF-8; the message names the problem.
        """
        n = len(self._prefix)
        if not (0 <= self._end <= len(raw) and raw[12:12 + n] == self._prefix and raw[0] == 0 and raw[1] == 1
                and raw[self._velocity_at:self._velocity_at + 4] == self._velocity_count
                and raw[self._effort_at:self._effort_at + 4] == self._effort_count):
            self._parse(raw)
        sec, nanosec = _STAMP.unpack_from(raw, 4)
        return sec + 1e-9 * nanosec, self._names, self._unpack.unpack_from(raw, self._at)

    def _parse(self, raw: Any) -> None:
        self._end = -1  # until every cached part is of this layout
        what = "JointState"
        pos = _head(raw, what)
        count, pos = _u32(raw, pos, what, "the name count")
        if count > len(raw):  # each name takes at least 5 bytes: refused before the loop
            raise CdrError(f"truncated {what}: {count} names do not fit in {len(raw)} bytes")
        names = []
        for i in range(count):
            size, pos = _u32(raw, pos, what, f"the length of name {i}")
            if size == 0 or pos + size > len(raw):
                raise CdrError(f"truncated {what}: name {i} of length {size} at byte {pos} does not fit in"
                               f" {len(raw)} bytes")
            if raw[pos + size - 1] != 0:
                raise CdrError(f"{what}'s name {i} does not end with its NUL")
            text = bytes(raw[pos:pos + size - 1])
            if 0 in text:
                raise CdrError(f"{what}'s name {i} holds a NUL before its end")
            try:
                names.append(text.decode("utf-8"))
            except UnicodeDecodeError as err:
                raise CdrError(f"{what}'s name {i} is not UTF-8 ({err.reason} at byte {pos + err.start})") from None
            pos += size
        count_at = _align(pos, 4)
        npos, at, pos = _doubles(raw, pos, what, "position")
        counts = []  # where the velocity and effort counts are (their values are not read)
        for field in ("velocity", "effort"):
            counts.append(_align(pos, 4))
            _, _, pos = _doubles(raw, pos, what, field)
        self._prefix = bytes(raw[12:count_at + 4])
        (self._velocity_at, self._velocity_count), (self._effort_at, self._effort_count) = (
            (c, bytes(raw[c:c + 4])) for c in counts)
        self._names, self._at = tuple(names), at
        self._unpack = struct.Struct(f"<{npos}d")
        self._end = pos
