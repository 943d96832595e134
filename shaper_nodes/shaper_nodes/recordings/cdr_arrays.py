"""CDR of std_msgs/Float64MultiArray, pure Python: read from the serialized bytes, written in place.

The shaper node takes its streamed array input raw (a subscription with ``raw=True`` hands the callback
the serialized ``bytes``) and publishes the shaped samples as bytes (``Publisher.publish`` takes the
``bytes`` of a serialized message and calls ``publish_raw``), so that no message object is built on
the command path. The wire format is the one of :mod:`.cdr` (plain CDR, little endian, primitives
aligned to their size counted from the end of the 4-byte encapsulation header)::

    uint32 dim count; per dim: string label (uint32 length with the NUL, the bytes, NUL),
                               uint32 size, uint32 stride
    uint32 data_offset
    uint32 data count; (aligned to 8 when there are elements) float64 data[count]

:func:`decode_float64_multi_array` parses any such buffer and refuses a malformed one with a
:class:`CdrError` whose one-line message names the problem (truncated, not little-endian CDR, a
string without its NUL, with one inside or not UTF-8, more dimensions than :data:`MAX_DIMS`); the data are a read-only
numpy view of the buffer (no copy). :class:`Float64MultiArrayCdr` is a serialized message of a fixed
layout whose data are rewritten in place (zero padding; byte-equal to rclpy's
``serialize_message`` outside the padding bytes, which Fast CDR does not clear: checked in
``shaper_nodes/test/test_cdr_arrays.py``). :class:`Float64ArrayCodec` joins the two for a stream whose
layout stays the same from message to message: it recognises the layout's bytes and skips the parse,
and it answers with the same layout (``data_offset`` passed through) and new data.

The module imports neither rclpy nor message types.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cdr import _HEAD, ENCAPSULATION, SerializedMessage, _Writer

#: most dimensions a layout may have (refused beyond, before their labels are read)
MAX_DIMS = 32
_U32 = struct.Struct("<I")
_DIM = struct.Struct("<II")


class CdrError(ValueError):
    """A serialized message that cannot be read; the message names the problem in one line."""


@dataclass(frozen=True)
class ArrayLayout:
    """A std_msgs/MultiArrayLayout: ``dims`` as (label, size, stride) per dimension, and ``data_offset``."""

    dims: tuple[tuple[str, int, int], ...] = ()
    data_offset: int = 0

    @property
    def sizes(self) -> tuple[int, ...]:
        """The dimensions' sizes, in order."""
        return tuple(d[1] for d in self.dims)


@dataclass(frozen=True)
class _Parsed:
    layout: ArrayLayout
    offset_at: int  # absolute offset of data_offset
    count_end: int  # absolute offset after the data count
    data_at: int    # absolute offset of the first double
    count: int


def _pad4(pos: int) -> int:
    return _HEAD + ((pos - _HEAD + 3) & ~3)


def _u32(raw: Any, pos: int, what: str, kind: str = "Float64MultiArray") -> tuple[int, int]:
    """The uint32 at ``pos`` aligned to 4, and the position after it; CdrError (naming ``what`` of the message
    type ``kind``) when it is past the end."""
    pos = _pad4(pos)
    if pos + 4 > len(raw):
        raise CdrError(f"truncated {kind}: {what} at byte {pos} is past its end ({len(raw)} bytes)")
    return _U32.unpack_from(raw, pos)[0], pos + 4


def _string(raw: Any, pos: int, what: str, kind: str = "Float64MultiArray") -> tuple[str, int]:
    """The CDR string at ``pos`` (its uint32 length aligned to 4, counting the NUL), and the position after
    its NUL; CdrError naming ``what`` when it does not fit, lacks its NUL, holds one before or is not UTF-8."""
    n, pos = _u32(raw, pos, f"the length of {what}", kind)
    if n == 0 or pos + n > len(raw):
        raise CdrError(f"{what}: a string of length {n} at byte {pos} does not fit in {len(raw)} bytes")
    if raw[pos + n - 1] != 0:
        raise CdrError(f"{what} does not end with its NUL")
    if 0 in raw[pos:pos + n - 1]:
        raise CdrError(f"{what} holds a NUL before its end")
    try:
        text = bytes(raw[pos:pos + n - 1]).decode("utf-8")
    except UnicodeDecodeError as err:
        raise CdrError(f"{what} is not UTF-8 ({err.reason} at byte {pos + err.start})") from None
    return text, pos + n


def _parse(raw: Any) -> _Parsed:
    """The layout and where the data are, of serialized Float64MultiArray bytes; CdrError when malformed."""
    if len(raw) < _HEAD or raw[0] != 0 or raw[1] != 1:
        head = bytes(raw[:2]).hex(" ") or "none"
        raise CdrError(f"not a little-endian plain CDR message (encapsulation {head}, {len(raw)} bytes)")
    ndims, pos = _u32(raw, _HEAD, "the dimension count")
    if ndims > MAX_DIMS:
        raise CdrError(f"a layout of {ndims} dimensions (at most {MAX_DIMS})")
    dims = []
    for i in range(ndims):
        label, pos = _string(raw, pos, f"dim {i}'s label")
        pos = _pad4(pos)
        if pos + 8 > len(raw):
            raise CdrError(f"truncated Float64MultiArray: dim {i}'s size and stride are past its end")
        size, stride = _DIM.unpack_from(raw, pos)
        dims.append((label, size, stride))
        pos += 8
    offset_at = pos
    data_offset, pos = _u32(raw, pos, "data_offset")
    count, pos = _u32(raw, pos, "the data count")
    count_end = pos
    data_at = _HEAD + ((pos - _HEAD + 7) & ~7) if count else pos
    if data_at + 8 * count > len(raw):
        raise CdrError(f"truncated Float64MultiArray: {count} doubles at byte {data_at} do not fit in {len(raw)}"
                       " bytes")
    return _Parsed(ArrayLayout(tuple(dims), data_offset), offset_at, count_end, data_at, count)


def decode_float64_multi_array(raw: Any) -> tuple[ArrayLayout, np.ndarray]:
    """The layout and the data of a serialized std_msgs/Float64MultiArray.

    Parameters
    ----------
    raw : bytes-like
        The serialized message (what a ``raw=True`` subscription receives).

    Returns
    -------
    layout : ArrayLayout
    data : numpy.ndarray
        float64, shape (count,): a view of ``raw`` (read-only for ``bytes``), no copy.

    Raises
    ------
    CdrError
        The bytes are not a well-formed little-endian CDR Float64MultiArray; the message names why.
    """
    p = _parse(raw)
    return p.layout, np.frombuffer(raw, dtype="<f8", count=p.count, offset=p.data_at)


class Float64MultiArrayCdr(SerializedMessage):
    """std_msgs/Float64MultiArray of a fixed ``layout`` and ``count`` values, written in place.

    ``values`` is a writable float64 view of the data (start at zero); :meth:`write` packs a
    sequence of values and returns the bytes to publish; :meth:`set_data_offset` rewrites the
    layout's ``data_offset``.
    """

    def __init__(self, layout: ArrayLayout, count: int) -> None:
        w = _Writer()
        w.u32(len(layout.dims))
        for label, size, stride in layout.dims:
            w.string(label)
            w.u32(size)
            w.u32(stride)
        self._offset_at = _HEAD + len(w.body)
        w.u32(layout.data_offset)
        start = w.doubles(count, sequence=True)
        super().__init__(w)
        self.layout, self.count = layout, count
        self.values = self._view(start, count)
        self._data_at = _HEAD + start
        self._pack = struct.Struct(f"<{count}d")

    def set_data_offset(self, value: int) -> None:
        """The layout's ``data_offset`` (uint32)."""
        _U32.pack_into(self._buffer, self._offset_at, value)

    def write(self, values: Any) -> bytes:
        """``values`` (``count`` floats) as the data; returns the serialized message (a copy)."""
        self._pack.pack_into(self._buffer, self._data_at, *values)
        return bytes(self._buffer)


class Float64ArrayCodec:
    """Reads a stream of serialized Float64MultiArray and writes answers of the same layout.

    :meth:`decode` remembers the bytes of the last layout (the dimensions and the data count;
    ``data_offset`` may change from message to message, as the latency benchmark's sequence number
    does); a message whose bytes there are the same is read without a parse. :meth:`encode` then
    writes values into a buffer of that layout, with the last message's ``data_offset``.
    """

    #: most values returned as a tuple of floats (a struct unpack, cheaper than a numpy view for a few values)
    SMALL = 64

    def __init__(self) -> None:
        self._out: Float64MultiArrayCdr | None = None
        self._head = b""   # the bytes up to data_offset (encapsulation and dimensions) of the last layout
        self._count = b""  # the bytes of the data count
        self._at = (0, 0, 0)  # the offsets of data_offset, after the data count, of the data
        self._end = -1     # the bytes the data need (-1: no layout yet)
        self._sizes: tuple[int, ...] = ()
        self._unpack: struct.Struct | None = None
        self._n = 0
        # the single-sample fast path (read_sample, write_sample): the layout's bytes up to data_offset (as read,
        # as written), of the data count, where the count's bytes start, the bytes a message needs, the structs that
        # read (data_offset, values...) from data_offset on and write the whole answer; None when the last
        # layout is not one sample of at most SMALL values
        self._sample: tuple[bytes, bytes, bytes, int, int, struct.Struct, struct.Struct] | None = None

    def decode(self, raw: Any) -> tuple[tuple[int, ...], tuple[float, ...] | np.ndarray]:
        """The layout's sizes and the data of ``raw``: a tuple of floats for up to :attr:`SMALL` values, a
        read-only numpy view beyond; CdrError when malformed."""
        offset_at, count_end, data_at = self._at
        if not (0 <= self._end <= len(raw) and raw[0:offset_at] == self._head
                and raw[offset_at + 4:count_end] == self._count):
            p = _parse(raw)
            self._end = -1  # until every cached part is of this layout
            offset_at, count_end, data_at = self._at = (p.offset_at, p.count_end, p.data_at)
            self._head, self._count = bytes(raw[0:offset_at]), bytes(raw[offset_at + 4:count_end])
            if self._out is None or (self._out.layout.dims, self._out.count) != (p.layout.dims, p.count):
                self._out = Float64MultiArrayCdr(p.layout, p.count)
            self._sizes, self._n = p.layout.sizes, p.count
            self._unpack = struct.Struct(f"<{p.count}d") if p.count <= self.SMALL else None
            self._end = data_at + 8 * p.count
            pad = data_at - count_end
            # (the answer's bytes up to data_offset are the new buffer's: zero padding, not the input's)
            self._sample = None if self._unpack is None or len(p.layout.dims) > 1 else (
                self._head, bytes(self._out._buffer[:offset_at]), self._count, offset_at + 4, self._end,
                struct.Struct(f"<I{data_at - offset_at - 4}x{p.count}d"),
                struct.Struct(f"<{offset_at}sII{pad}x{p.count}d"))
        self._out._buffer[offset_at:offset_at + 4] = raw[offset_at:offset_at + 4]  # type: ignore[union-attr]
        if self._unpack is not None:
            return self._sizes, self._unpack.unpack_from(raw, data_at)
        return self._sizes, np.frombuffer(raw, dtype="<f8", count=self._n, offset=data_at)

    def read_sample(self, raw: Any) -> tuple[Any, ...] | None:
        """``(data_offset, value, ...)`` of ``raw`` when it is ``bytes`` of the last layout decoded and that layout
        is one sample (at most one dimension) of at most :attr:`SMALL` values: the streamed sample's path, one
        comparison of the layout's bytes and one unpack (no slice, no parse). None otherwise: :meth:`decode`
        reads it then (a new layout, a block, a malformed message). :meth:`write_sample` writes the answer."""
        fast = self._sample
        if fast is None or type(raw) is not bytes:
            return None
        head, _, count, count_at, end, unpack, _ = fast
        if end <= len(raw) and raw.startswith(head) and raw.startswith(count, count_at):
            return unpack.unpack_from(raw, count_at - 4)
        return None

    def write_sample(self, data_offset: int, values: Any) -> bytes:
        """The serialized answer to a message :meth:`read_sample` read: its layout, ``data_offset`` and
        ``values`` (as many as it had), packed in one call (zero padding, as :class:`Float64MultiArrayCdr`)."""
        if self._sample is None:
            raise CdrError("Float64ArrayCodec.write_sample: the last layout is not a single sample")
        _, head, _, _, _, _, pack = self._sample
        return pack.pack(head, data_offset, self._n, *values)

    def encode(self, values: Any) -> bytes:
        """The last message decoded, its data replaced by ``values`` (as many), serialized."""
        if self._out is None:
            raise CdrError("Float64ArrayCodec.encode: no message decoded yet")
        return self._out.write(values)


__all__ = ["ENCAPSULATION", "MAX_DIMS", "ArrayLayout", "CdrError", "Float64ArrayCodec", "Float64MultiArrayCdr",
           "decode_float64_multi_array"]
