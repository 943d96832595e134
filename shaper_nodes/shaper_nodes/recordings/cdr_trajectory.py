"""CDR of trajectory_msgs/JointTrajectory, pure Python: read from the serialized bytes, written in one pack.

The shaper node takes the JointTrajectory points of its stream topic raw (a subscription with
``raw=True`` hands the callback the serialized ``bytes``) and publishes the shaped points as bytes,
so that no message object is built on that path either (the Float64MultiArray input's codec is
:mod:`.cdr_arrays`). The wire format is the one of :mod:`.cdr` (plain CDR, little endian, primitives
aligned to their size counted from the end of the 4-byte encapsulation header)::

    header:      int32 sec, uint32 nanosec, string frame_id
    joint_names: uint32 count; per name: uint32 length with the NUL, the bytes, NUL
    points:      uint32 count; per point:
                     positions, velocities, accelerations, effort: each uint32 count, then
                         (aligned to 8 when there are elements) float64[count]
                     time_from_start: int32 sec, uint32 nanosec

:func:`decode_joint_trajectory` (and :meth:`JointTrajectoryCodec.decode`, which skips the frame_id
and the names when their bytes are the previous message's, and reads points of the previous message's
layout in one unpack) parses any such buffer and refuses a
malformed one with a :class:`~.cdr_arrays.CdrError` whose one-line message names the problem
(truncated, not little-endian CDR, a string without its NUL, with one inside or not UTF-8, a count
that the bytes left cannot hold); more points than the caller's ``max_points`` is a
:class:`TooManyPoints`, more names than ``max_names`` a :class:`TooManyNames` (each refused before
any is read). The values are tuples of Python floats.
:meth:`JointTrajectoryCodec.encode` writes a trajectory with one :class:`struct.Struct` per layout
(frame_id, names, points and their fields' counts), kept for the next message of that layout; the
bytes equal rclpy's ``serialize_message`` outside the padding bytes (zero here; Fast CDR does not
clear them), checked in ``shaper_nodes/test/test_cdr_trajectory.py``.

The module imports neither rclpy nor message types.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

from .cdr import _HEAD, ENCAPSULATION, _Writer
from .cdr_arrays import CdrError, _string, _u32

#: the float64 sequences of a trajectory_msgs/JointTrajectoryPoint, in message order
POINT_FIELDS = ("positions", "velocities", "accelerations", "effort")
_TYPE = "JointTrajectory"
_STAMP = struct.Struct("<iI")
#: fewest bytes a name (its length and its NUL) and a point (four counts and a duration) take
_MIN_NAME, _MIN_POINT = 5, 24


class TooManyPoints(CdrError):
    """A JointTrajectory with more points than the reader takes (counted before any point is read)."""


class TooManyNames(CdrError):
    """A JointTrajectory with more joint names than the reader takes (counted before any name is read);
    ``count`` is their number."""

    def __init__(self, count: int, limit: int) -> None:
        super().__init__(f"{count} joint names exceed the limit of {limit}")
        self.count = count


class Stamp(NamedTuple):
    """A builtin_interfaces/Time or Duration: ``sec`` (int32) and ``nanosec`` (uint32), as the message holds
    them (not normalised)."""

    sec: int
    nanosec: int


class TrajectoryPoint(NamedTuple):
    """A trajectory_msgs/JointTrajectoryPoint: the four sequences (rad or m, and their derivatives; N or N m)
    as tuples of floats, and ``time_from_start``."""

    positions: tuple[float, ...]
    velocities: tuple[float, ...]
    accelerations: tuple[float, ...]
    effort: tuple[float, ...]
    time_from_start: Stamp


class Trajectory(NamedTuple):
    """A trajectory_msgs/JointTrajectory read from its bytes (the fields named as the message's, the header's
    as ``stamp`` and ``frame_id``)."""

    stamp: Stamp
    frame_id: str
    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]


def _pad8(pos: int) -> int:
    return _HEAD + ((pos - _HEAD + 7) & ~7)


def _stamp(raw: Any, pos: int, what: str) -> tuple[Stamp, int]:
    pos = _HEAD + ((pos - _HEAD + 3) & ~3)
    if pos + 8 > len(raw):
        raise CdrError(f"truncated {_TYPE}: {what} at byte {pos} is past its end ({len(raw)} bytes)")
    sec, nanosec = _STAMP.unpack_from(raw, pos)
    return Stamp(sec, nanosec), pos + 8


#: struct formats of n doubles, made once per n
_DOUBLES: dict[int, struct.Struct] = {}


def _doubles(raw: Any, pos: int, what: str) -> tuple[tuple[float, ...], int]:
    count, pos = _u32(raw, pos, f"the count of {what}", _TYPE)
    if not count:
        return (), pos
    pos = _pad8(pos)
    if pos + 8 * count > len(raw):
        raise CdrError(f"truncated {_TYPE}: {what}, {count} doubles at byte {pos}, do not fit in {len(raw)} bytes")
    fmt = _DOUBLES.get(count)
    if fmt is None:
        fmt = _DOUBLES[count] = struct.Struct(f"<{count}d")
    return fmt.unpack_from(raw, pos), pos + 8 * count


def _check_head(raw: Any) -> None:
    if len(raw) < _HEAD or raw[0] != 0 or raw[1] != 1:
        head = bytes(raw[:2]).hex(" ") or "none"
        raise CdrError(f"not a little-endian plain CDR message (encapsulation {head}, {len(raw)} bytes)")


def _names(raw: Any, pos: int, max_names: int | None) -> tuple[str, tuple[str, ...], int]:
    """The frame_id and the joint names from byte ``pos`` (after the stamp); the position after them."""
    frame_id, pos = _string(raw, pos, "the header's frame_id", _TYPE)
    count, pos = _u32(raw, pos, "the joint names' count", _TYPE)
    if count * _MIN_NAME > len(raw) - pos:
        raise CdrError(f"truncated {_TYPE}: {count} joint names at byte {pos} do not fit in {len(raw)} bytes")
    if max_names is not None and count > max_names:
        raise TooManyNames(count, max_names)
    names = []
    for i in range(count):
        name, pos = _string(raw, pos, f"joint name {i}", _TYPE)
        names.append(name)
    return frame_id, tuple(names), pos


def _points(raw: Any, pos: int, max_points: int | None) -> tuple[TrajectoryPoint, ...]:
    count, pos = _u32(raw, pos, "the points' count", _TYPE)
    if max_points is not None and count > max_points:
        raise TooManyPoints(f"{count} points exceed the limit of {max_points}")
    if count * _MIN_POINT > len(raw) - pos:
        raise CdrError(f"truncated {_TYPE}: {count} points at byte {pos} do not fit in {len(raw)} bytes")
    points = []
    for k in range(count):
        pos_, pos = _doubles(raw, pos, f"point {k} positions")
        vel, pos = _doubles(raw, pos, f"point {k} velocities")
        acc, pos = _doubles(raw, pos, f"point {k} accelerations")
        eff, pos = _doubles(raw, pos, f"point {k} effort")
        t, pos = _stamp(raw, pos, f"point {k} time_from_start")
        points.append(TrajectoryPoint(pos_, vel, acc, eff, t))
    return tuple(points)


class _PointsLayout:
    """One Struct that reads every point of a known layout (the counts of each point's fields) from a known
    offset, with the counts among what it reads: a message whose counts are not those is parsed instead."""

    def __init__(self, start: int, counts: Sequence[Sequence[int]]) -> None:
        fmt, pos, index = ["<"], start, 0
        count_at: list[int] = []  # where the point count and every field's count are among the values read
        expected: list[int] = []
        self.plan: list[tuple[tuple[int, int], ...]] = []  # per point: each field's (start, end), then the time's

        def align(size: int) -> None:
            nonlocal pos
            to = _HEAD + ((pos - _HEAD + size - 1) & ~(size - 1))
            if to > pos:
                fmt.append(f"{to - pos}x")
                pos = to

        def take(code: str, values: int, size: int) -> int:
            nonlocal pos, index
            align(size)
            fmt.append(code)
            pos += size * values
            index += values
            return index - values

        count_at.append(take("I", 1, 4))
        expected.append(len(counts))
        for point in counts:
            spans = []
            for n in point:
                count_at.append(take("I", 1, 4))
                expected.append(n)
                first = take(f"{n}d", n, 8) if n else index
                spans.append((first, first + n))
            first = take("iI", 2, 4)
            spans.append((first, first + 2))
            self.plan.append(tuple(spans))
        self.struct = struct.Struct("".join(fmt))
        self.start, self.points = start, len(counts)
        self.counts = operator.itemgetter(*count_at)
        self.expected = tuple(expected) if len(expected) > 1 else expected[0]

    def read(self, raw: Any) -> tuple[TrajectoryPoint, ...] | None:
        """The points of ``raw`` if they are of this layout (else None)."""
        if len(raw) < self.start + self.struct.size:
            return None
        v = self.struct.unpack_from(raw, self.start)
        if self.counts(v) != self.expected:
            return None
        return tuple(TrajectoryPoint(v[p[0][0]:p[0][1]], v[p[1][0]:p[1][1]], v[p[2][0]:p[2][1]], v[p[3][0]:p[3][1]],
                                     Stamp(v[p[4][0]], v[p[4][0] + 1])) for p in self.plan)


def decode_joint_trajectory(raw: Any, max_points: int | None = None, max_names: int | None = None) -> Trajectory:
    """A serialized trajectory_msgs/JointTrajectory, read.

    Parameters
    ----------
    raw : bytes-like
        The serialized message (what a ``raw=True`` subscription receives).
    max_points : int, optional
        Most points taken; more is a :class:`TooManyPoints` before any point is read.
    max_names : int, optional
        Most joint names taken; more is a :class:`TooManyNames` before any name is read (the names come
        before the points: a message with too many of both is refused for its names).

    Raises
    ------
    CdrError
        The bytes are not a well-formed little-endian CDR JointTrajectory; the message names why.
    """
    _check_head(raw)
    stamp, pos = _stamp(raw, _HEAD, "the header's stamp")
    frame_id, names, pos = _names(raw, pos, max_names)
    return Trajectory(stamp, frame_id, names, _points(raw, pos, max_points))


#: one part of a layout's bytes: a constant (bytes), the header stamp, a point's duration or field
_Part = tuple[str, Any]


class _Layout:
    """The Struct that writes every JointTrajectory of one layout, and where its parts go."""

    def __init__(self, frame_id: str, names: Sequence[str], counts: Sequence[Sequence[int]]) -> None:
        w = _Writer()
        w.body += bytes(8)  # the stamp
        var: list[tuple[int, str, _Part]] = [(0, "iI", ("stamp", None))]
        w.string(frame_id)
        w.u32(len(names))
        for name in names:
            w.string(name)
        w.u32(len(counts))
        for k, point in enumerate(counts):
            for field, n in zip(POINT_FIELDS, point, strict=True):
                at = w.doubles(n, sequence=True)
                if n:
                    var.append((at, f"{n}d", ("values", (k, field))))
            w.align(4)
            var.append((len(w.body), "iI", ("duration", k)))
            w.body += bytes(8)
        body = bytes(w.body)
        fmt, pos = ["<4s"], 0
        parts: list[_Part] = [("const", ENCAPSULATION)]
        for at, f, part in var:
            if at > pos:
                fmt.append(f"{at - pos}s")
                parts.append(("const", body[pos:at]))
            fmt.append(f)
            parts.append(part)
            pos = at + struct.calcsize("<" + f)
        if pos < len(body):
            fmt.append(f"{len(body) - pos}s")
            parts.append(("const", body[pos:]))
        self.struct = struct.Struct("".join(fmt))
        self.parts = parts
        #: (start, end) byte ranges that only align the next field (zero here)
        self.padding = [(_HEAD + a, _HEAD + b) for a, b in w.padding]

    def pack(self, stamp: tuple[int, int], durations: Sequence[tuple[int, int]],
             rows: Mapping[str, Sequence[Sequence[float]]]) -> bytes:
        args: list[Any] = []
        for kind, what in self.parts:
            if kind == "const":
                args.append(what)
            elif kind == "values":
                args += rows[what[1]][what[0]]
            elif kind == "duration":
                args += durations[what]
            else:
                args += stamp
        return self.struct.pack(*args)


class JointTrajectoryCodec:
    """Reads serialized JointTrajectory messages and writes them, each side remembering its last layout.

    :meth:`decode` skips the frame_id and the names when their bytes are the previous message's;
    :meth:`encode` keeps the Struct of the last few layouts it wrote (a stream's layout seldom changes).
    One caller at a time (not locked).
    """

    #: most layouts :meth:`encode` keeps (it starts afresh when full)
    MAX_LAYOUTS = 8
    #: most points whose layout :meth:`decode` keeps for the next message
    MAX_POINTS_LAYOUT = 64

    def __init__(self) -> None:
        self._prefix = b""  # the bytes of the last frame_id and names (from after the stamp)
        self._points: _PointsLayout | None = None  # the last points' layout, read in one unpack
        self._names: tuple[str, tuple[str, ...]] = ("", ())
        self._layouts: dict[tuple[str, tuple[str, ...], tuple[tuple[int, ...], ...]], _Layout] = {}
        #: the layout :meth:`encode` wrote last (its ``padding`` for tests)
        self.last_layout: _Layout | None = None

    def decode(self, raw: Any, max_points: int | None = None,
               max_names: int | None = None) -> Trajectory:
        """:func:`decode_joint_trajectory`, the names taken from the last message when their bytes are
        the same, and the points read in one unpack when their layout is the last message's (the counts
        of their fields are among the values that unpack reads, and compared)."""
        _check_head(raw)
        stamp, pos = _stamp(raw, _HEAD, "the header's stamp")
        n = len(self._prefix)
        if n and len(raw) >= pos + n and raw[pos:pos + n] == self._prefix:
            (frame_id, names), end = self._names, pos + n
            if max_names is not None and len(names) > max_names:
                raise TooManyNames(len(names), max_names)
        else:
            frame_id, names, end = _names(raw, pos, max_names)
            self._prefix, self._names = bytes(raw[pos:end]), (frame_id, names)
        known = self._points
        if known is not None and known.start == end and (max_points is None or known.points <= max_points):
            points = known.read(raw)
            if points is not None:
                return Trajectory(stamp, frame_id, names, points)
        points = _points(raw, end, max_points)
        if len(points) <= self.MAX_POINTS_LAYOUT:
            self._points = _PointsLayout(end, [tuple(len(getattr(p, f)) for f in POINT_FIELDS) for p in points])
        return Trajectory(stamp, frame_id, names, points)

    def encode(self, stamp: tuple[int, int], frame_id: str, joint_names: Sequence[str],
               durations: Sequence[tuple[int, int]], fields: Mapping[str, Sequence[Sequence[float]]]) -> bytes:
        """A JointTrajectory, serialized.

        Parameters
        ----------
        stamp : (int, int)
            The header's stamp (sec, nanosec).
        frame_id : str
            The header's frame_id.
        joint_names : sequence of str
        durations : sequence of (int, int)
            Each point's time_from_start (sec, nanosec); one per point.
        fields : mapping of str to rows
            Per field of :data:`POINT_FIELDS` that the points carry, one row of floats per point; a field
            left out is an empty sequence in every point.

        Raises
        ------
        ValueError
            A field that is not a JointTrajectoryPoint's, a number of rows that is not the points', a
            name or frame_id with a NUL.
        """
        unknown = set(fields) - set(POINT_FIELDS)
        if unknown:
            raise ValueError(f"not fields of a JointTrajectoryPoint: {sorted(unknown)}")
        npoints = len(durations)
        if any(len(rows) != npoints for rows in fields.values()):
            raise ValueError(f"every field needs one row per point ({npoints})")
        counts = tuple(tuple(len(fields[f][k]) if f in fields else 0 for f in POINT_FIELDS) for k in range(npoints))
        key = (frame_id, tuple(joint_names), counts)
        layout = self._layouts.get(key)
        if layout is None:
            if len(self._layouts) >= self.MAX_LAYOUTS:
                self._layouts.clear()
            layout = self._layouts[key] = _Layout(frame_id, joint_names, counts)
        self.last_layout = layout
        return layout.pack(stamp, durations, fields)


__all__ = ["POINT_FIELDS", "JointTrajectoryCodec", "Stamp", "TooManyNames", "TooManyPoints", "Trajectory",
           "TrajectoryPoint", "decode_joint_trajectory"]
