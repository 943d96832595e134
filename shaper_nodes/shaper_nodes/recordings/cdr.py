"""CDR, pure Python: messages serialized in place for publishers, and the fields analyses read parsed directly.

Writing: pre-serialized messages for the per-step publishers of the simulated plant (Imu,
JointState, Clock). Reading: the stamps, accelerations, joint names, positions and efforts of
little-endian CDR sensor_msgs/Imu and JointState, parsed without building message objects
(:func:`imu_fast`, :func:`joint_state_fast`, :class:`JointStateDecoder`; checked against
rosbags' deserialiser in ``shaper_nodes/test/test_bag_analysis.py``).

``rclpy``'s ``Publisher.publish`` takes a message or the ``bytes`` of a serialized one (it then
calls ``publish_raw``). A message object costs, at every publish, the generated setters' checks
in Python and the conversion from Python to C; for messages whose layout stays the same (an
Imu with a fixed frame_id, a JointState with fixed names and array lengths, a Clock), the
serialized bytes can instead be kept in a buffer and only the changing numbers rewritten in
place. The classes here build that buffer and expose its numbers as writable numpy views.

The wire format is what ``rclpy.serialization.serialize_message`` gives under Fast DDS: plain
CDR, little endian (the 4-byte encapsulation header ``00 01 00 00``), each primitive aligned to
its size counted from the end of that header, strings as a uint32 length (with the terminating
NUL) and the bytes with the NUL, sequences as a uint32 count then the elements. The bytes that
only pad for alignment are zero here; Fast CDR leaves whatever its buffer held there, and every
reader skips them. (``serialize_message`` returns Fast DDS's estimate of the size, which aligns
an empty sequence of doubles to 8 as if it had elements: bytes at the end that nothing wrote and
no reader reads; what a publisher sends is the written length, as here.) The unit test
``shaper_nodes/test/test_cdr.py`` holds these buffers byte-equal to ``serialize_message``
outside those padding bytes, and deserialized back equal.

The module is pure Python (struct and numpy): it imports neither rclpy nor message types.
"""

from __future__ import annotations

import struct

import numpy as np

#: CDR, little endian, no options (what Fast DDS writes)
ENCAPSULATION = b"\x00\x01\x00\x00"
_HEAD = len(ENCAPSULATION)
_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
#: the float64 fields of sensor_msgs/Imu after its header, in order, and their lengths
IMU_FIELDS = (("orientation", 4), ("orientation_covariance", 9), ("angular_velocity", 3),
              ("angular_velocity_covariance", 9), ("linear_acceleration", 3), ("linear_acceleration_covariance", 9))


def stamp_parts(t: float) -> tuple[int, int]:
    """``t`` s as a builtin_interfaces/Time's (sec, nanosec), rounded to the nanosecond (as ``sec_to_time``)."""
    return divmod(int(round(t * 1e9)), 1_000_000_000)


class _Writer:
    """A growing CDR body (after the encapsulation header) with its alignment counted from its start."""

    def __init__(self) -> None:
        self.body = bytearray()
        self.padding: list[tuple[int, int]] = []  # (start, end) in the body

    def align(self, size: int) -> None:
        pad = -len(self.body) % size
        if pad:
            self.padding.append((len(self.body), len(self.body) + pad))
            self.body += b"\x00" * pad

    def u32(self, value: int) -> None:
        self.align(4)
        self.body += _U32.pack(value)

    def string(self, text: str) -> None:
        data = text.encode("utf-8")
        if b"\x00" in data:
            raise ValueError(f"a CDR string cannot hold a NUL character: {text!r}")
        self.u32(len(data) + 1)
        self.body += data + b"\x00"

    def header(self, frame_id: str) -> None:
        """std_msgs/Header: the stamp (zero; rewritten in place at offset 0) and ``frame_id``."""
        self.body += _STAMP.pack(0, 0)
        self.string(frame_id)

    def doubles(self, count: int, sequence: bool) -> int:
        """Room for ``count`` float64 (after their count if ``sequence``): their offset in the body."""
        if sequence:
            self.u32(count)
        if count:  # (an empty sequence has no elements to align)
            self.align(8)
        offset = len(self.body)
        self.body += b"\x00" * (8 * count)
        return offset


class SerializedMessage:
    """A serialized message of a fixed layout: the stamp and the float64 fields are rewritten in place.

    Built by the subclasses; ``data()`` gives the ``bytes`` to publish. ``padding`` lists the (start, end) byte
    ranges that only align the next field: zero here, whatever the buffer held in Fast DDS's serialization
    (Fast CDR does not clear them); readers skip them.
    """

    def __init__(self, writer: _Writer) -> None:
        self._buffer = bytearray(ENCAPSULATION) + writer.body
        self.padding = [(_HEAD + a, _HEAD + b) for a, b in writer.padding]

    def _view(self, offset: int, count: int) -> np.ndarray:
        """Writable float64 view of ``count`` values at ``offset`` of the body."""
        return np.frombuffer(self._buffer, dtype="<f8", count=count, offset=_HEAD + offset)

    def set_stamp(self, sec: int, nanosec: int) -> None:
        """The header's stamp (s, ns), as builtin_interfaces/Time holds it."""
        _STAMP.pack_into(self._buffer, _HEAD, sec, nanosec)

    def data(self) -> bytes:
        """The serialized message as it stands (a copy: the buffer may be rewritten after)."""
        return bytes(self._buffer)


class ImuCdr(SerializedMessage):
    """sensor_msgs/Imu with a fixed ``frame_id``; every float64 field a writable view (attributes named as the
    message's fields: ``orientation`` x, y, z, w; ``angular_velocity`` rad/s and ``linear_acceleration`` m/s^2,
    x, y, z; the three covariances, 9 values row-major). All start as a new message has them: orientation
    (0, 0, 0, 1), everything else zero."""

    def __init__(self, frame_id: str) -> None:
        w = _Writer()
        w.header(frame_id)
        start = w.doubles(sum(n for _, n in IMU_FIELDS), sequence=False)
        super().__init__(w)
        for name, count in IMU_FIELDS:
            setattr(self, name, self._view(start, count))
            start += 8 * count
        self.orientation[3] = 1.0  # geometry_msgs/Quaternion's default w

    orientation: np.ndarray
    orientation_covariance: np.ndarray
    angular_velocity: np.ndarray
    angular_velocity_covariance: np.ndarray
    linear_acceleration: np.ndarray
    linear_acceleration_covariance: np.ndarray


class JointStateCdr(SerializedMessage):
    """sensor_msgs/JointState with fixed ``names``, ``frame_id`` and array lengths; ``position`` (rad or m),
    ``velocity`` and ``effort`` are writable views (start at zero)."""

    def __init__(self, names: list[str], positions: int, velocities: int, efforts: int, frame_id: str = "") -> None:
        w = _Writer()
        w.header(frame_id)
        w.u32(len(names))
        for name in names:
            w.string(name)
        offsets = [w.doubles(count, sequence=True) for count in (positions, velocities, efforts)]
        super().__init__(w)
        self.sizes = (positions, velocities, efforts)
        self.position, self.velocity, self.effort = (
            self._view(off, count) for off, count in zip(offsets, self.sizes, strict=True))


def clock_cdr(sec: int, nanosec: int) -> bytes:
    """rosgraph_msgs/Clock at (``sec`` s, ``nanosec`` ns), serialized."""
    return ENCAPSULATION + _STAMP.pack(sec, nanosec)


def empty_sequence_appended(raw: bytes) -> bytes:
    """A message's CDR with one empty sequence appended (its length 0, aligned to 4 bytes): a message recorded with a
    definition that ended one sequence field short, as the definition with that field has it, the field empty
    (shaper_msgs/CycleEvent before its ``start_stamp``, session 14)."""
    data = bytes(raw)
    return data + bytes((-(len(data) - 4)) % 4) + bytes(4)


# ------------------------------------------------------------------------------ reading
_D3 = struct.Struct("<3d")


def _align(pos: int, n: int) -> int:
    """Absolute offset ``pos`` aligned to ``n`` relative to the CDR payload (after 4 header bytes)."""
    return 4 + ((pos - 4 + n - 1) & ~(n - 1))


def _header(raw) -> tuple[float, int]:
    sec, nsec = _STAMP.unpack_from(raw, 4)
    (n,) = _U32.unpack_from(raw, 12)
    return sec + 1e-9 * nsec, 16 + n


def imu_fast(raw) -> tuple[float, tuple[float, float, float]]:
    """(header stamp in s, linear acceleration) of a little-endian CDR sensor_msgs/Imu."""
    t, pos = _header(raw)
    return t, _D3.unpack_from(raw, _align(pos, 8) + 200)  # after orientation, 3 covariances/vectors


def joint_state_fast(raw) -> tuple[float, tuple[str, ...], tuple[float, ...]]:
    """(header stamp in s, names, positions) of a little-endian CDR sensor_msgs/JointState."""
    t, pos = _header(raw)
    pos = _align(pos, 4)
    (count,) = _U32.unpack_from(raw, pos)
    pos += 4
    names = []
    for _ in range(count):
        pos = _align(pos, 4)
        (n,) = _U32.unpack_from(raw, pos)
        names.append(bytes(raw[pos + 4: pos + 3 + n]).decode())
        pos += 4 + n
    pos = _align(pos, 4)
    (npos,) = _U32.unpack_from(raw, pos)
    pos += 4
    if npos:
        pos = _align(pos, 8)
    return t, tuple(names), struct.unpack_from(f"<{npos}d", raw, pos)


class JointStateDecoder:
    """:func:`joint_state_fast` that skips the names when they are those of the previous message."""

    def __init__(self) -> None:
        self._prefix = b""
        self._names: tuple[str, ...] = ()
        self._layout: tuple[int, struct.Struct] | None = None

    def __call__(self, raw) -> tuple[float, tuple[str, ...], tuple[float, ...]]:
        n = len(self._prefix)
        if n and self._layout is not None and raw[12:12 + n] == self._prefix:  # a prefix comes with its layout
            offset, fmt = self._layout
            sec, nsec = _STAMP.unpack_from(raw, 4)
            return sec + 1e-9 * nsec, self._names, fmt.unpack_from(raw, offset)
        t, names, pos = joint_state_fast(raw)
        # the bytes from the frame_id to the position count fix where the positions are
        _, end = _header(raw)
        end = _align(end, 4) + 4  # the names' count
        for _ in names:
            end = _align(end, 4)
            end += 4 + _U32.unpack_from(raw, end)[0]
        end = _align(end, 4) + 4
        self._prefix = bytes(raw[12:end])
        self._names = names
        self._layout = (_align(end, 8) if pos else end, struct.Struct(f"<{len(pos)}d"))
        return t, names, pos

    @property
    def positions_end(self) -> int:
        """Where the positions of the message last decoded end (for :func:`joint_state_efforts`)."""
        if self._layout is None:
            raise TypeError("JointStateDecoder.positions_end: no message decoded yet")
        return self._layout[0] + self._layout[1].size


def joint_state_efforts(raw, end: int) -> tuple[float, ...]:
    """The efforts of a little-endian CDR sensor_msgs/JointState whose positions end at ``end``."""
    return joint_state_motion(raw, end)[1]


def joint_state_motion(raw, end: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The velocities and the efforts of a little-endian CDR sensor_msgs/JointState whose positions end at
    ``end``."""
    pos = _align(end, 4)
    (nvel,) = _U32.unpack_from(raw, pos)
    pos = _align(pos + 4, 8) if nvel else pos + 4
    vel = struct.unpack_from(f"<{nvel}d", raw, pos)
    pos = _align(pos + 8 * nvel, 4)
    (neff,) = _U32.unpack_from(raw, pos)
    pos += 4
    return vel, struct.unpack_from(f"<{neff}d", raw, _align(pos, 8) if neff else pos)


def time_ns(raw) -> int:
    """The builtin_interfaces/Time a CDR message begins with (a std_msgs/Header's stamp, rosgraph_msgs/Clock's
    clock), in ns; either byte order."""
    sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


def goal_feedback_stamp(raw) -> tuple[bytes, float]:
    """(goal id, the feedback's header stamp in s) of a CDR action FeedbackMessage whose feedback begins with a
    std_msgs/Header (FollowJointTrajectory's): the goal's 16-byte UUID, then the stamp; either byte order."""
    sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 20)
    return bytes(raw[4:20]), sec + 1e-9 * nanosec


def little_endian(raw) -> bool:
    """Whether serialized bytes are little-endian CDR (their encapsulation header says so)."""
    return len(raw) > 4 and raw[1] == 1
