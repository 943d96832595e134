"""What a damaged or unclosed MCAP file still holds, read record by record, and what it lost.

rosbags' reader needs the MCAP footer and summary, so a file cut short (recorder killed, disk
full) or with a broken record fails to open; :class:`RecoveredFile` scans it from its start,
record by record, with the ``mcap`` library's record parsers: schemas, channels, messages and
chunks are taken until the first record that is cut off or unreadable, a chunk whose data does
not decompress or fails its CRC is skipped, and :class:`Damage` says how much was lost (bytes,
and the time range of the messages in the chunk that was cut, read from its header). Messages
are deserialised with a typestore built from the schemas in the file; a type whose definition is
missing or does not parse is reported.

A file that was closed still has its summary section, whose chunk index gives the offset and the
length of every chunk. So a record whose header is corrupt (a chunk length that overruns the file,
or does not match the index) or whose content does not parse does not end the reading there: the
chunk is read with the index's length, and where it still does not read, the scan goes on at the
next indexed chunk; the skipped bytes and the log-time range of the skipped chunk(s) are stated
(:attr:`Damage.skipped_chunks`). The summary is read only when the footer points at one inside the
file, and its size is bounded by ``ReadLimits.metadata_bytes``.

What was lost, and how it is said, is :mod:`.damage`'s (:class:`~.damage.Damage`, :func:`~.damage.describe_unclosed`,
:func:`~.damage.describe_damage`).
"""

from __future__ import annotations

import io
import pathlib
import struct
from collections.abc import Generator, Iterator
from typing import TYPE_CHECKING, Any, BinaryIO

from .bounds import (
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_MESSAGE,
    OP_SCHEMA,
    OPNAMES,
    ReadLimits,
    check_chunk,
    check_magic,
    inflate,
)
from .damage import Damage, _sec
from .errors import BagError
from .heartbeat import Heartbeat, is_heartbeat_topic, loss_bound

if TYPE_CHECKING:
    from mcap.data_stream import ReadDataStream

class RecoveredFile:
    """A damaged MCAP file scanned record by record (see the module docstring)."""

    def __init__(self, path: pathlib.Path, limits: ReadLimits | None = None) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.limits = limits or ReadLimits()
        self.size = path.stat().st_size
        self.damage = Damage(str(path), self.size, 0)
        self.channels: dict[int, tuple[str, str]] = {}  # id -> (topic, msgtype)
        self._schemas: dict[int, tuple[str, str, str]] = {}  # id -> (name, encoding, text)
        self.store = get_typestore(Stores.EMPTY)
        self.bad_types: dict[str, str] = {}
        self._last_beat: tuple[int, bytes, str] | None = None  # log time, raw, msgtype
        self._stopped = ""  # why the scan stopped last
        self.index: dict[int, tuple[int, int, int]] = {}  # chunk offset -> (length, start ns, end ns)
        for rec in _summary_records(path, self.size, self.limits):  # the schemas and channels of a lost chunk too
            if isinstance(rec, tuple):
                self.index[rec[0]] = rec[1:]
            elif hasattr(rec, "encoding"):
                self._add_schema(rec.id, rec.name, rec.encoding, rec.data)
            else:
                self._add_channel(rec.id, rec.topic, rec.schema_id)
        # a first pass over the readable part: channels, definitions, counts (messages stream later)
        for _ in self._records(set(), collect=True):
            pass
        self._conclude()

    def _conclude(self) -> None:
        """The last heartbeat, and the loss bound it gives if the file was not closed."""
        d = self.damage
        if self._last_beat is None:
            return
        stamp, raw, msgtype = self._last_beat
        try:
            status: Any = self.store.deserialize_cdr(raw, msgtype)
            d.heartbeat = Heartbeat.from_values(stamp, ((kv.key, kv.value) for kv in status.values))
        except Exception:
            return
        if d.not_closed:
            d.loss = loss_bound(d.heartbeat, d.data_start, d.lost_time[1] if d.lost_time else None)

    def messages(self, wanted: set[str]) -> Iterator[tuple[str, str, int, bytes]]:
        yield from self._records(wanted, collect=False)

    # ----------------------------------------------------------------- scanning
    def _records(self, wanted: set[str], collect: bool) -> Iterator[tuple[str, str, int, bytes]]:
        """The messages of ``wanted`` topics, up to the first record that is cut off or unreadable.

        With ``collect``, also take the schemas and channels and note where and why reading stopped.
        """
        from mcap.data_stream import ReadDataStream

        with open(self.path, "rb") as f:
            check_magic(self.path, f.read(8))
            good = 8
            while True:
                record = self._next_record(f, good, collect)
                if record is not None:
                    op, length, body = record
                    stream = ReadDataStream(io.BytesIO(body))
                    try:
                        end = yield from self._record_items(op, length, stream, wanted, collect, good)
                    except Exception as err:
                        self._stop(collect, good, f"unreadable {OPNAMES.get(op, hex(op))} record at byte {good}:"
                                   f" {err}")
                    else:
                        if end:
                            return
                        good += 9 + length
                        continue
                resume = self._resume(collect, good)
                if resume is None:
                    return
                good = resume
                f.seek(good)

    def _next_record(self, f: BinaryIO, good: int, collect: bool) -> tuple[int, int, bytes] | None:
        """(opcode, length, body) of the record at ``good`` (bytes), or None where reading stops (noted)."""
        head = f.read(9)
        if len(head) == 0:
            self._stop(collect, good, "the file ends without a footer")
            return None
        if len(head) < 9:
            self._stop(collect, good, "cut inside a record header")
            return None
        op, length = head[0], struct.unpack("<Q", head[1:])[0]
        indexed = self.index.get(good) if self.index else None
        if op == OP_CHUNK and indexed is not None and 9 + length != indexed[0]:
            if collect:
                self.damage.skipped_chunks.append(
                    f"chunk at byte {good}: its length field says {length} bytes, the summary's index"
                    f" {indexed[0] - 9}; read with the index's")
            length = indexed[0] - 9
        if op != OP_CHUNK and indexed is not None:
            self._stop(collect, good, f"record at byte {good} has opcode {op:#04x} where the summary indexes a chunk")
            return None
        if length > self.size and (op not in OPNAMES or length >= 2**40):
            self._stop(collect, good, f"corrupt record header at byte {good} (length {length})")
            return None
        if good + 9 + length > self.size:  # a record cut by the end of the file (its header written, not all of it)
            body = f.read(16)
            lost = struct.unpack("<QQ", body[:16]) if op == OP_CHUNK and len(body) >= 16 else None
            self._stop(collect, good, f"cut inside a {OPNAMES.get(op, hex(op))} record"
                       f" ({self.size - good - 9} of {length} bytes)", lost)
            return None
        return op, length, f.read(length)

    def _record_items(self, op: int, length: int, stream: ReadDataStream, wanted: set[str], collect: bool,
                      good: int) -> Generator[tuple[str, str, int, bytes], None, bool]:
        """The messages of one record (a message, or those of a chunk); returns True at the end of the data."""
        from mcap.records import Channel, Chunk, Message, Schema

        if op == OP_SCHEMA:
            if collect:
                s = Schema.read(stream)
                self._add_schema(s.id, s.name, s.encoding, s.data)
        elif op == OP_CHANNEL:
            if collect:
                c = Channel.read(stream)
                self._add_channel(c.id, c.topic, c.schema_id)
        elif op == OP_MESSAGE:
            m = Message.read(stream, length)
            item = self._message(m, wanted, collect)
            if item is not None:
                yield item
        elif op == OP_CHUNK:
            yield from self._chunk_items(Chunk.read(stream), wanted, collect, good)
        elif op in (OP_FOOTER, OP_DATA_END):
            self._stop(collect, self.size, "")
            return True
        return False

    def _chunk_items(self, chunk, wanted: set[str], collect: bool, good: int) -> Iterator[tuple[str, str, int, bytes]]:
        """The messages of the chunk at ``good`` (bytes) up to its first corrupt record (noted)."""
        from mcap.records import Channel, Message, Schema

        records, err = _chunk_records(chunk, self.limits, good, self.path)
        if err and collect:
            self.damage.skipped_chunks.append(
                f"chunk at byte {good} ({_sec(chunk.message_start_time):.3f}-"
                f"{_sec(chunk.message_end_time):.3f} s): {err}; {len(records)} records before it kept")
        for rec in records:
            if isinstance(rec, Schema):
                if collect:
                    self._add_schema(rec.id, rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                if collect:
                    self._add_channel(rec.id, rec.topic, rec.schema_id)
            elif isinstance(rec, Message):
                item = self._message(rec, wanted, collect)
                if item is not None:
                    yield item

    def _resume(self, collect: bool, good: int) -> int | None:
        """Where reading goes on after the record at ``good`` failed: the next chunk the summary indexes.

        The failure noted by :meth:`_stop` becomes a skipped chunk, with the bytes and log times lost.
        """
        if not self.index or self._stopped in ("", "the file ends without a footer"):
            return None
        later = sorted(o for o in self.index if o > good)
        if not later:
            return None
        nxt = later[0]
        if collect:
            d = self.damage
            lost = [v for o, v in self.index.items() if good <= o < nxt]
            times = (f"; it held the messages logged {_sec(min(v[1] for v in lost)):.3f}-"
                     f"{_sec(max(v[2] for v in lost)):.3f} s") if lost else ""
            d.skipped_chunks.append(f"{d.reason}; skipped {nxt - good} bytes to the next chunk the summary"
                                    f" indexes (byte {nxt}){times}")
            d.reason, d.lost_time, d.readable = "", None, 0
        return nxt

    def _stop(self, collect: bool, good: int, reason: str, lost: tuple[int, int] | None = None) -> None:
        self._stopped = reason  # in both passes: where to go on depends on it (:meth:`_resume`)
        if collect:
            self.damage.readable, self.damage.reason, self.damage.lost_time = good, reason, lost

    def _message(self, m, wanted: set[str], collect: bool = False) -> tuple[str, str, int, bytes] | None:
        ch = self.channels.get(m.channel_id)
        if collect and ch is not None:
            stamp = int(m.log_time)
            if is_heartbeat_topic(*ch):
                if self._last_beat is None or stamp >= self._last_beat[0]:
                    self._last_beat = (stamp, m.data, ch[1])
            else:
                d = self.damage
                d.messages_read += 1
                d.data_start = stamp if d.data_start is None else min(d.data_start, stamp)
                d.data_end = stamp if d.data_end is None else max(d.data_end, stamp)
        if ch is None or ch[0] not in wanted:
            return None
        return ch[0], ch[1], int(m.log_time), m.data

    def _add_schema(self, sid: int, name: str, encoding: str, data: bytes) -> None:
        self._schemas[sid] = (name, encoding, data.decode("utf-8", errors="replace"))

    def _add_channel(self, cid: int, topic: str, schema_id: int) -> None:
        from rosbags.typesys import get_types_from_idl, get_types_from_msg

        name, encoding, text = self._schemas.get(schema_id, ("", "", ""))
        self.channels[cid] = (topic, name)
        if not name or name in self.store.fielddefs or name in self.bad_types:
            return
        try:
            if encoding == "ros2msg":
                types = get_types_from_msg(text, name)
            elif encoding == "ros2idl":
                sep = "=" * 80 + "\n"
                types = {}
                for part in (text.split(sep)[1:] if text.startswith(sep + "IDL: ") else [text]):
                    types.update(get_types_from_idl(part.split("\n", 1)[1] if part.startswith("IDL: ") else part))
            else:
                raise BagError(f"schema encoding {encoding!r} is not supported")
            self.store.register(types)
        except Exception as err:
            self.bad_types[name] = f"its definition does not parse ({err})"

def _summary_records(path: pathlib.Path, size: int, limits: ReadLimits) -> list:
    """The summary section's schemas, channels and chunk index entries (as (offset, record length with its
    9-byte header, first and last log time ns)).

    Empty when the file has no footer, no summary, or a summary that does not read (or is larger than
    ``limits.metadata_bytes``): the summary only helps, it is never needed.
    """
    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, ChunkIndex, Schema

    footer_at = size - 8 - 29  # footer record (opcode, length, 20 bytes), then the magic
    if footer_at < 8:
        return []
    with open(path, "rb") as f:
        f.seek(footer_at)
        tail = f.read(37)
        if len(tail) != 37 or tail[0] != OP_FOOTER:
            return []
        summary_start = struct.unpack_from("<Q", tail, 9)[0]
        if not 8 <= summary_start < footer_at or footer_at - summary_start > limits.metadata_bytes:
            return []
        f.seek(summary_start)
        data = f.read(footer_at - summary_start)
    out: list = []
    pos = 0
    while pos + 9 <= len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if pos + 9 + length > len(data):
            break
        body = ReadDataStream(io.BytesIO(data[pos + 9: pos + 9 + length]))
        try:
            if op == 0x08:  # chunk index
                ci = ChunkIndex.read(body)
                if 8 <= ci.chunk_start_offset < size and 9 < ci.chunk_length <= size - ci.chunk_start_offset:
                    out.append((ci.chunk_start_offset, ci.chunk_length, ci.message_start_time, ci.message_end_time))
            elif op == OP_SCHEMA:
                out.append(Schema.read(body))
            elif op == OP_CHANNEL:
                out.append(Channel.read(body))
        except Exception:
            return []
        pos += 9 + length
    return out


def _chunk_records(chunk, limits: ReadLimits, offset: int, path: pathlib.Path) -> tuple[list, str]:
    """The records of a chunk up to the first corrupt one, and what was wrong ("" if nothing)."""
    import zlib

    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, Message, Schema

    check_chunk(offset, chunk.compression, chunk.uncompressed_size, len(chunk.data), limits, path)
    try:
        data = inflate(chunk.data, chunk.compression, chunk.uncompressed_size)
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            raise ValueError("CRC mismatch")
    except Exception as err:
        return [], f"its data is corrupt ({type(err).__name__}: {err})"
    size = len(data)
    records: list = []
    pos = 0
    parsers = {OP_SCHEMA: Schema.read, OP_CHANNEL: Channel.read}
    while pos < size:
        if pos + 9 > size:
            return records, f"corrupt record header at offset {pos} of the chunk"
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if pos + 9 + length > size:
            return records, f"record at offset {pos} of the chunk claims {length} bytes, {size - pos - 9} remain"
        body = ReadDataStream(io.BytesIO(data[pos + 9: pos + 9 + length]))
        try:
            if op == OP_MESSAGE:
                records.append(Message.read(body, length))
            elif op in parsers:
                records.append(parsers[op](body))
        except Exception as err:
            return records, f"unreadable record at offset {pos} of the chunk ({err})"
        pos += 9 + length
    return records, ""

def mcap_chunks(data: bytes) -> list[tuple[int, int]]:
    """(byte offset, record length) of every chunk record of an MCAP file's bytes (for tests and tools)."""
    pos, out = 8, []
    while pos + 9 <= len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == OP_CHUNK:
            out.append((pos, length))
        if op == OP_FOOTER:
            break
        pos += 9 + length
    return out

