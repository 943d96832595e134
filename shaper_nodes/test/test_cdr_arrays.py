"""Float64MultiArray CDR: written byte-equal to rclpy's serialization, read back as rclpy reads, refused when malformed.

The padding rule is test_cdr.py's: the bytes that only align the next field are left out of the
comparison (Fast CDR leaves its buffer's old contents there; ours are zero), and serialize_message's
size estimate may end up to 8 bytes after the written data when the data are empty.
"""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from shaper_nodes.recordings.cdr_arrays import (
    MAX_DIMS,
    ArrayLayout,
    CdrError,
    Float64ArrayCodec,
    Float64MultiArrayCdr,
    decode_float64_multi_array,
)

# labels of every length mod 4 (each label's end sets the alignment of what follows), and non-ASCII
LAYOUTS = [
    ArrayLayout(),
    ArrayLayout((("", 7, 7),)),
    ArrayLayout((("joints", 7, 7),), 3),
    ArrayLayout((("samples", 100, 700), ("joints", 7, 7)), 2**32 - 1),
    ArrayLayout((("a", 1, 1), ("bb", 2, 2), ("ccc", 3, 3), ("dddd", 4, 4))),
    ArrayLayout((("gelenk_ü", 6, 6),), 17),
]
COUNTS = [0, 1, 2, 3, 6, 7, 8, 700]


def _msg(layout: ArrayLayout, values: np.ndarray) -> Float64MultiArray:
    msg = Float64MultiArray(data=values.tolist())
    msg.layout.dim = [MultiArrayDimension(label=a, size=b, stride=c) for a, b, c in layout.dims]
    msg.layout.data_offset = layout.data_offset
    return msg


def _same(cdr: Float64MultiArrayCdr, data: bytes, reference: bytes) -> None:
    """``data`` (of ``cdr``) equals ``reference`` outside the padding; its padding bytes zero."""
    assert len(data) <= len(reference) <= len(data) + (8 if cdr.count == 0 else 0)
    ref = bytearray(reference[:len(data)])
    got = bytearray(data)
    for start, end in cdr.padding:
        assert 0 < end - start < 8
        assert got[start:end] == bytes(end - start)
        ref[start:end] = bytes(end - start)
    assert got == ref


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda lay: "x".join(map(str, lay.sizes)) or "none")
@pytest.mark.parametrize("count", COUNTS)
def test_written_equals_rclpy_and_reads_back(layout: ArrayLayout, count: int) -> None:
    rng = np.random.default_rng(count)
    cdr = Float64MultiArrayCdr(layout, count)
    _same(cdr, cdr.data(), serialize_message(_msg(layout, np.zeros(count))))
    for _ in range(3):
        values = rng.normal(0.0, 10.0, count) * np.where(np.arange(count) % 2, -1.0, 1.0)
        data = cdr.write(values.tolist())
        msg = _msg(layout, values)
        reference = serialize_message(msg)
        _same(cdr, data, reference)
        assert deserialize_message(data, Float64MultiArray) == msg
        # read: our bytes and rclpy's (its padding and trailing bytes as they come) give the same
        for raw in (data, reference):
            got_layout, got = decode_float64_multi_array(raw)
            assert got_layout == layout
            assert got.tolist() == values.tolist()  # every bit of the doubles
            assert not got.flags.writeable


def test_codec_answers_in_the_layout_of_the_input_with_its_data_offset() -> None:
    codec = Float64ArrayCodec()
    layout = ArrayLayout((("samples", 2, 6), ("joints", 3, 3)))
    for seq, lay in enumerate([ArrayLayout(), ArrayLayout(), layout, layout, ArrayLayout((("j", 6, 6),)), layout]):
        values = np.arange(6.0) * (seq + 1) - 2.5
        msg = _msg(ArrayLayout(lay.dims, seq * 1000), values)
        sizes, got = codec.decode(serialize_message(msg))
        assert sizes == lay.sizes
        assert isinstance(got, tuple)  # a few values: floats, not a view
        got = np.asarray(got)
        assert got.tolist() == values.tolist()
        answer = deserialize_message(codec.encode((-got).tolist()), Float64MultiArray)
        assert answer.layout == msg.layout  # dims and data_offset
        assert answer.data.tolist() == (-values).tolist()


def test_codec_reads_messages_whose_padding_differs() -> None:
    """Padding bytes are not part of the layout: a message whose padding holds other bytes reads the same."""
    codec = Float64ArrayCodec()
    msg = _msg(ArrayLayout(), np.arange(7.0))
    raw = bytearray(serialize_message(msg))
    assert list(codec.decode(bytes(raw))[1]) == list(range(7))
    raw[16:20] = b"\xab\xcd\xef\x01"  # the 4 bytes that align the doubles to 8
    raw[28:36] = np.float64(-3.5).tobytes()  # the second double (data at byte 20)
    assert list(codec.decode(bytes(raw))[1]) == [0.0, -3.5, 2.0, 3.0, 4.0, 5.0, 6.0]


def _one_line(err: CdrError) -> str:
    text = str(err)
    assert text and "\n" not in text
    return text


def test_every_truncation_is_refused_with_the_reason() -> None:
    layout = ArrayLayout((("samples", 2, 14), ("joints", 7, 7)), 5)
    raw = Float64MultiArrayCdr(layout, 14).write([0.5] * 14)
    codec = Float64ArrayCodec()
    codec.decode(raw)  # a layout known to the codec: a shorter message must not take its shortcut
    for n in range(len(raw)):
        for decode in (decode_float64_multi_array, codec.decode):
            with pytest.raises(CdrError) as err:
                decode(raw[:n])
            text = _one_line(err.value)
            assert "truncated" in text or "past its end" in text or "encapsulation" in text or "does not fit" in text


@pytest.mark.parametrize(("raw", "words"), [
    (b"", "encapsulation none"),
    (b"\x00\x00\x00\x00" + bytes(12), "not a little-endian"),  # big-endian CDR
    (b"\x00\x03\x00\x00" + bytes(12), "not a little-endian"),  # parameter list
    (b"\x00\x01\x00\x00" + (MAX_DIMS + 1).to_bytes(4, "little") + bytes(8), f"{MAX_DIMS + 1} dimensions"),
    (b"\x00\x01\x00\x00\x01\x00\x00\x00" + bytes(16), "length 0"),  # a string's length counts its NUL
    (b"\x00\x01\x00\x00\x01\x00\x00\x00\x02\x00\x00\x00ab" + bytes(18), "NUL"),
    (b"\x00\x01\x00\x00\x01\x00\x00\x00\x02\x00\x00\x00\xff\x00" + bytes(18), "not UTF-8"),
    (b"\x00\x01\x00\x00\x01\x00\x00\x00\x03\x00\x00\x00a\x00\x00" + bytes(17), "a NUL before its end"),
    (b"\x00\x01\x00\x00\x01\x00\x00\x00\xff\xff\xff\xff" + bytes(16), "does not fit"),
    (b"\x00\x01\x00\x00" + bytes(4) + bytes(4) + b"\xff\xff\xff\x7f" + bytes(8), "doubles"),
])
def test_malformed_buffers_are_refused_with_the_reason(raw: bytes, words: str) -> None:
    for decode in (decode_float64_multi_array, Float64ArrayCodec().decode):
        with pytest.raises(CdrError, match=words) as err:
            decode(raw)
        _one_line(err.value)


def test_corrupted_bytes_are_read_or_refused_never_crash() -> None:
    """Any byte changed in a valid message: a CdrError or a reading whose data fit in the buffer."""
    rng = np.random.default_rng(34)
    layout = ArrayLayout((("samples", 2, 6), ("joints", 3, 3)), 9)
    raw = Float64MultiArrayCdr(layout, 6).write(np.linspace(-1, 1, 6).tolist())
    codec = Float64ArrayCodec()
    for _ in range(2000):
        bad = bytearray(raw)
        for i in rng.integers(0, len(raw), rng.integers(1, 4)):
            bad[i] = int(rng.integers(0, 256))
        for decode in (decode_float64_multi_array, codec.decode):
            try:
                _, data = decode(bytes(bad))
            except CdrError as err:
                _one_line(err)
            else:
                assert len(data) * 8 <= len(bad)


def test_codec_gives_a_view_for_many_values_and_reads_them_as_rclpy_wrote_them() -> None:
    codec = Float64ArrayCodec()
    values = np.linspace(-5.0, 5.0, 7 * 100)
    msg = _msg(ArrayLayout((("samples", 100, 700), ("joints", 7, 7))), values)
    for _ in range(2):  # parsed, then recognised
        sizes, got = codec.decode(serialize_message(msg))
        assert sizes == (100, 7) and isinstance(got, np.ndarray) and not got.flags.writeable
        assert got.tolist() == values.tolist()
    assert deserialize_message(codec.encode(values[::-1].tolist()), Float64MultiArray).data.tolist() == \
        values[::-1].tolist()


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda lay: "x".join(map(str, lay.sizes)) or "none")
@pytest.mark.parametrize("count", [0, 1, 7, Float64ArrayCodec.SMALL, Float64ArrayCodec.SMALL + 1])
def test_the_single_sample_path_reads_and_writes_what_decode_and_encode_do(layout: ArrayLayout, count: int) -> None:
    """read_sample / write_sample (the streamed sample's path): for a message of the last layout decoded, one
    sample (at most one dimension) of at most SMALL values, the data_offset and the values as decode reads them,
    and the answer's bytes as encode writes them (rclpy's serialization outside the padding); None for anything
    else, which decode then reads."""
    rng = np.random.default_rng(count)
    codec = Float64ArrayCodec()
    ours = Float64MultiArrayCdr(layout, count)  # zero padding; rclpy's padding bytes are whatever its buffer held
    assert codec.read_sample(ours.data()) is None  # no layout decoded yet
    codec.decode(ours.data())
    single = len(layout.dims) <= 1 and count <= Float64ArrayCodec.SMALL
    for seq in (0, 5, 2**32 - 1):
        values = rng.normal(0.0, 10.0, count)
        ours.set_data_offset(seq)
        raw = ours.write(values.tolist())
        got = codec.read_sample(raw)
        if not single:
            assert got is None
            continue
        assert got is not None and got[0] == seq and list(got[1:]) == values.tolist()
        # rclpy's bytes of the same message: the same, or None where its padding differs (decode reads them)
        assert codec.read_sample(serialize_message(_msg(ArrayLayout(layout.dims, seq), values))) in (got, None)
        answer = codec.write_sample(seq, (-values).tolist())
        assert codec.read_sample(bytearray(raw)) is None  # bytes only: decode reads the rest
        _, data = codec.decode(raw)
        assert list(data) == values.tolist()
        assert answer == codec.encode((-values).tolist())  # encode: the last decoded's data_offset, seq
        reference = _msg(ArrayLayout(layout.dims, seq), -values)
        _same(Float64MultiArrayCdr(ArrayLayout(layout.dims, seq), count), answer, serialize_message(reference))
        assert deserialize_message(answer, Float64MultiArray) == reference
    if single:  # another layout, or the same cut short: not read here (decode parses or refuses it)
        other = serialize_message(_msg(ArrayLayout((("other", count + 1, count + 1),)), np.zeros(count + 1)))
        assert codec.read_sample(other) is None
        assert codec.read_sample(serialize_message(_msg(layout, np.zeros(count)))[:-1]) is None if count else True


def test_write_sample_before_a_single_sample_layout_is_refused_by_name() -> None:
    codec = Float64ArrayCodec()
    with pytest.raises(CdrError, match="write_sample: the last layout is not a single sample"):
        codec.write_sample(0, [])
