"""Open a recording and iterate its messages; recover what a damaged MCAP file still holds.

A recording is a rosbag2 folder (metadata.yaml plus storage files) or a bare ``.mcap`` file.
rosbags' :class:`~rosbags.highlevel.AnyReader` reads intact ones (MCAP or sqlite3). It needs the
MCAP footer and summary, so a file cut short (recorder killed, disk full) or with a broken
record fails to open; such a file is then scanned from its start, record by record, with the
``mcap`` library's record parsers: schemas, channels, messages and chunks are taken until the
first record that is cut off or unreadable, a chunk whose data does not decompress or fails its
CRC is skipped, and :class:`Damage` says how much was lost (bytes, and the time range of the
messages in the chunk that was cut, read from its header).

Messages are deserialised with rosbags' typestore built from the schemas in the file; a type
whose definition is missing or does not parse is reported, and its messages are skipped.

A recording that was not closed (no footer, or no metadata.yaml) is described plainly: how many
messages were read, where the data ends, and, from the last heartbeat the suite's recorder wrote
into it (:mod:`shaper_nodes.core.recording`), until when the recorder was alive and how much it
lost at most after its last flush (seconds and messages per topic). A closed recording whose
recorder dropped messages (queue full) says so from metadata.yaml's ``custom_data``.

Reading is bounded (:class:`ReadLimits`): metadata.yaml's size is checked before it is parsed;
every MCAP file is first walked record header by record header (:func:`scan_mcap`, seeking over
the bodies), which refuses a file that is not MCAP, a chunk whose declared uncompressed size is
beyond the limit or beyond a sane compression ratio, and tells a file that was not closed (a
record longer than what remains of the file: "cut inside") before any chunk is inflated. Every
chunk is then inflated by :func:`inflate`, which never produces more than the chunk declares,
both in the record scan and inside rosbags' reader (whose decompressors are replaced by it).
"""

from __future__ import annotations

import io
import pathlib
import struct
from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, BinaryIO

from shaper_nodes.core.recording import Heartbeat, LossBound, is_heartbeat_topic, loss_bound

if TYPE_CHECKING:
    from mcap.data_stream import ReadDataStream
    from rosbags.highlevel import AnyReader
    from rosbags.typesys.store import Typestore

#: MCAP magic (start and end of a file)
MAGIC = b"\x89MCAP0\r\n"
#: MCAP opcodes used here
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x02, 0x0F


class BagError(ValueError):
    """The recording cannot be read or analysed; the message names the problem."""


MIB = 1 << 20


@dataclass(frozen=True)
class ReadLimits:
    """Bounds on what reading a recording may cost.

    Attributes
    ----------
    metadata_bytes : int
        Largest metadata.yaml parsed, bytes (a recorder writes a few kB; default 16 MiB).
    chunk_bytes : int
        Largest declared uncompressed size of one MCAP chunk, bytes (default 256 MiB; rosbag2
        writes 1-4 MiB chunks).
    compression_ratio : float
        Largest uncompressed/compressed size ratio of a chunk (default 1000: zstd on sensor data
        gives 2-20, on long runs of equal bytes a few hundred).
    """

    metadata_bytes: int = 16 * MIB
    chunk_bytes: int = 256 * MIB
    compression_ratio: float = 1000.0


def size_text(n: float) -> str:
    """A byte count for a person: ``3.2 GiB``, ``109 MiB``, ``32 KiB``, ``17 bytes``."""
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            value = n / scale
            return f"{value:.1f} {unit}" if value < 10 else f"{value:.0f} {unit}"
    return f"{int(n)} bytes"


class BagRecovery(Exception):
    """Internal: read the recording with the record-by-record scan."""


@dataclass(frozen=True)
class TopicInfo:
    """A topic of the recording: its type and message count (None: not known before reading)."""

    topic: str
    msgtype: str
    count: int | None


@dataclass
class Damage:
    """What a damaged MCAP file lost.

    Attributes
    ----------
    path : str
        The file.
    size : int
        File size, bytes.
    readable : int
        Bytes up to the end of the last complete record, from the start of the file.
    reason : str
        Why reading stopped (or "" if it reached the end).
    lost_time : tuple of (int, int) or None
        Log-time range (ns) of the messages in the chunk that was cut, from its header.
    skipped_chunks : list of str
        Chunks skipped because their data was corrupt (and why).
    expected_messages : int or None
        Message count that metadata.yaml promises, if it exists.
    messages_read : int
        Messages read from the file (the recorder's heartbeats not counted).
    data_start, data_end : int or None
        Log times of the first and last message read, ns (heartbeats not counted).
    heartbeat : Heartbeat or None
        The last recorder heartbeat read (None: the file has none).
    loss : LossBound or None
        What was lost after the last flush, at most (from the heartbeat).
    """

    path: str
    size: int
    readable: int
    reason: str = ""
    lost_time: tuple[int, int] | None = None
    skipped_chunks: list[str] = field(default_factory=list)
    expected_messages: int | None = None
    messages_read: int = 0
    data_start: int | None = None
    data_end: int | None = None
    heartbeat: Heartbeat | None = None
    loss: LossBound | None = None

    @property
    def not_closed(self) -> bool:
        """The file ends without its footer (the writer stopped before closing it)."""
        return self.reason == "the file ends without a footer" or self.reason.startswith("cut inside")

    @property
    def lost_bytes(self) -> int:
        return self.size - self.readable


def _sec(ns: int) -> float:
    return ns * 1e-9


@dataclass
class ReadResult:
    """Counters of one pass over the messages (filled while iterating)."""

    messages: int = 0
    undecodable: dict[str, str] = field(default_factory=dict)  # msgtype -> why


def read_metadata(meta: pathlib.Path, limits: ReadLimits | None = None) -> dict:
    """metadata.yaml parsed with ``yaml.safe_load``, after its size was checked against the limit.

    Raises
    ------
    BagError
        The file is larger than ``limits.metadata_bytes``.
    """
    import yaml

    limit = (limits or ReadLimits()).metadata_bytes
    size = meta.stat().st_size
    if size > limit:
        raise BagError(f"{meta}: metadata.yaml is {size_text(size)}, beyond the limit of {size_text(limit)} (a"
                       " recorder writes a few kB; not parsed; raise --max-metadata-mib if it is genuine)")
    try:
        doc = yaml.safe_load(meta.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise BagError(f"{meta}: unreadable metadata ({err})") from None
    return doc if isinstance(doc, dict) else {}


def mcap_files(path: pathlib.Path, limits: ReadLimits | None = None) -> tuple[list[pathlib.Path], int | None, bool]:
    """The MCAP files of a recording, the message count its metadata.yaml gives, and whether that exists."""
    if path.is_file():
        return [path], None, False
    if not path.is_dir():
        raise BagError(f"no recording at {path} (neither a rosbag2 folder nor a file)")
    meta = path / "metadata.yaml"
    expected = None
    if meta.exists():
        doc = read_metadata(meta, limits)  # BagError if too large
        try:
            info = doc.get("rosbag2_bagfile_information", {})
            expected = int(info.get("message_count")) if info.get("message_count") is not None else None
            files = [path / f for f in info.get("relative_file_paths", [])]
        except Exception as err:
            raise BagError(f"{meta}: unreadable metadata ({err})") from None
    else:
        files = []
    files = [f for f in files if f.suffix == ".mcap" and f.exists()] or sorted(path.glob("*.mcap"))
    return files, expected, meta.exists()


class Bag:
    """An open recording: its topics, its messages, a deserialiser, and damage if any.

    Parameters
    ----------
    path : path
        A rosbag2 folder or a bare .mcap file.

    Raises
    ------
    BagError
        Nothing there, not a recording, or no message at all could be read.
    """

    def __init__(self, path: str | pathlib.Path, recover: bool = False, limits: ReadLimits | None = None) -> None:
        self.path = pathlib.Path(path)
        self.limits = limits or ReadLimits()
        self.notes: list[str] = []
        self.damage: list[Damage] = []
        self.reader_name = ""
        self._reader: AnyReader | None = None
        self._recovered: list[_Recovered] = []
        if not self.path.exists():
            raise BagError(f"no recording at {self.path}")
        files, expected, has_meta = mcap_files(self.path, self.limits)  # metadata.yaml's size checked
        # every MCAP file walked header by header before anything is inflated (BagError if refused)
        scans = [scan_mcap(f, self.limits) for f in files if not _is_sqlite(f)]
        unclosed = [sc for sc in scans if not sc.closed]
        try:
            if recover:
                raise BagRecovery("asked to scan the file record by record")
            if unclosed:
                raise BagRecovery("; ".join(sc.describe() for sc in unclosed))
            self._open_rosbags()
            self._note_drops()
        except BagError:
            raise
        except Exception as err:
            if not files:
                raise BagError(f"cannot read {self.path}: {err}") from None
            if not has_meta and self.path.is_dir():
                self.notes.append(f"{self.path} has no metadata.yaml: the recorder did not finish the bag")
            if unclosed and not recover:
                self.notes.append(f"{err}; scanned record by record")
            elif not isinstance(err, BagRecovery):
                self.notes.append(f"rosbags could not open the recording ({err}); scanned it record by record")
            self._recovered = [_Recovered(f, self.limits) for f in files]
            for rec in self._recovered:
                rec.damage.expected_messages = expected if len(files) == 1 else None
                self.damage.append(rec.damage)
            self.reader_name = "mcap record scan (recovery)"

    # ----------------------------------------------------------------- opening
    def _open_rosbags(self) -> None:
        from rosbags.highlevel import AnyReader

        _bound_rosbags_decompressors()
        if self.path.is_dir() and not (self.path / "metadata.yaml").exists():
            raise OSError("no metadata.yaml")
        reader = AnyReader([self.path], default_typestore=_default_typestore())
        reader.open()
        self._reader = reader
        self.reader_name = "rosbags AnyReader"

    def _note_drops(self) -> None:
        """A note if metadata.yaml says that the recorder dropped messages (its queue was full)."""
        meta = self.path / "metadata.yaml"
        if not meta.is_file():
            return
        try:
            info = read_metadata(meta, self.limits).get("rosbag2_bagfile_information", {})
            text = str((info.get("custom_data") or {}).get("shaper_nodes.recorder.dropped", ""))
            dropped = {t: int(n) for t, _, n in (x.rpartition("=") for x in text.split(",") if x)}
        except Exception:
            return
        if any(dropped.values()):
            self.notes.append(f"the recorder dropped {sum(dropped.values())} message(s) because its write queue was"
                              " full (" + ", ".join(f"{t}: {n}" for t, n in sorted(dropped.items()) if n) + ")")

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------------- content
    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> TopicInfo (for a recovered file: every channel seen in the readable part)."""
        if self._reader is not None:
            return {name: TopicInfo(name, info.msgtype or "", info.msgcount)
                    for name, info in self._reader.topics.items()}
        out: dict[str, TopicInfo] = {}
        for rec in self._recovered:
            for topic, msgtype in rec.channels.values():
                out.setdefault(topic, TopicInfo(topic, msgtype, None))
        return out

    @property
    def message_count(self) -> int | None:
        """Messages in the bag (None if not known before reading: a recovered file)."""
        return self._reader.message_count if self._reader is not None else None

    def messages(self, topics: Iterable[str], result: ReadResult | None = None
                 ) -> Iterator[tuple[str, str, int, object]]:
        """(topic, msgtype, log time ns, raw CDR bytes) of the given topics, in recording order."""
        wanted = set(topics)
        result = result if result is not None else ReadResult()
        if self._reader is not None:
            conns = [c for c in self._reader.connections if c.topic in wanted]
            for conn, stamp, raw in self._reader.messages(connections=conns):
                result.messages += 1
                yield conn.topic, conn.msgtype, stamp, raw
            return
        for rec in self._recovered:
            for topic, msgtype, stamp, raw in rec.messages(wanted):
                result.messages += 1
                yield topic, msgtype, stamp, raw

    def deserializer(self, msgtype: str):
        """A function raw bytes -> message of ``msgtype``.

        Raises
        ------
        BagError
            The type's definition is missing from the recording or does not parse.
        """
        store: Typestore | None
        if self._reader is not None:
            store = self._reader.typestore
        else:
            store = next((r.store for r in self._recovered if msgtype in r.store.fielddefs), None)
            if store is None:
                why = next((r.bad_types[msgtype] for r in self._recovered if msgtype in r.bad_types),
                           "no definition in the recording")
                raise BagError(f"cannot decode {msgtype}: {why}")
        if msgtype not in store.fielddefs:
            raise BagError(f"cannot decode {msgtype}: no definition in the recording")
        deserialize = store.deserialize_cdr
        return lambda raw: deserialize(raw, msgtype)


def _default_typestore():
    """rosbags' Jazzy store, with this suite's types when shaper_msgs is installed (for bags without
    definitions, e.g. sqlite3 ones written without them)."""
    try:
        from shaper_nodes.ros.bag_writer import typestore_with_own_types

        return typestore_with_own_types()
    except Exception:
        from rosbags.typesys import Stores, get_typestore

        return get_typestore(Stores.ROS2_JAZZY)


class _Recovered:
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
            _check_magic(self.path, f.read(8))
            good = 8
            while True:
                record = self._next_record(f, good, collect)
                if record is None:
                    return
                op, length, body = record
                stream = ReadDataStream(io.BytesIO(body))
                try:
                    end = yield from self._record_items(op, length, stream, wanted, collect, good)
                except Exception as err:
                    self._stop(collect, good, f"unreadable {_OPNAMES.get(op, hex(op))} record at byte {good}: {err}")
                    return
                if end:
                    return
                good += 9 + length

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
        if length > self.size and (op not in _OPNAMES or length >= 2**40):
            self._stop(collect, good, f"corrupt record header at byte {good} (length {length})")
            return None
        if good + 9 + length > self.size:  # a record cut by the end of the file (its header written, not all of it)
            body = f.read(16)
            lost = struct.unpack("<QQ", body[:16]) if op == OP_CHUNK and len(body) >= 16 else None
            self._stop(collect, good, f"cut inside a {_OPNAMES.get(op, hex(op))} record"
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

    def _stop(self, collect: bool, good: int, reason: str, lost: tuple[int, int] | None = None) -> None:
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


_OPNAMES = {0x01: "header", OP_FOOTER: "footer", OP_SCHEMA: "schema", OP_CHANNEL: "channel", OP_MESSAGE: "message",
            OP_CHUNK: "chunk", 0x07: "message index", 0x08: "chunk index", 0x09: "attachment",
            0x0A: "attachment index", 0x0B: "statistics", 0x0C: "metadata", 0x0D: "metadata index",
            0x0E: "summary offset", OP_DATA_END: "data-end"}


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


def _when(ns: int, origin: int | None) -> str:
    """A log time as seconds from ``origin``, with the UTC clock time when it looks like wall time."""
    text = f"{_sec(ns - (origin or 0)):.3f} s"
    if ns > 10**18:  # after 2001: a wall clock, not simulated time
        import datetime

        clock = datetime.datetime.fromtimestamp(ns * 1e-9, tz=datetime.UTC).strftime("%Y-%m-%d %H:%M:%S.%f")
        text += f" ({clock[:-3]} UTC)"
    return text


def describe_unclosed(d: Damage) -> str:
    """What a recording that was not closed holds and lost, in one sentence (see the module docstring)."""
    if d.data_end is None:
        head = f"recording not closed (recorder killed?): no message in {d.path}"
    else:
        head = (f"recording not closed (recorder killed?): {d.messages_read} messages read, data ends at"
                f" {_when(d.data_end, d.data_start)} from its first message")
    if d.loss is None or d.heartbeat is None:
        return head + ("; the file has no recorder heartbeat, so how much the recorder still held when it stopped"
                       " is not known")
    loss, beat = d.loss, d.heartbeat
    origin = d.data_start if d.data_start is not None else beat.stamp_ns
    per_topic = ", ".join(f"{t} {n}" for t, n in sorted(loss.messages.items()))
    text = f"{head}; the recorder had written everything it received until {_when(beat.stamp_ns, origin)}"
    if loss.alive_ns > beat.stamp_ns:
        text += f" and was still alive at {_sec(loss.alive_ns - origin):.3f} s (the chunk it was writing was cut)"
    text += (f"; lost after its last flush: at most ~{loss.seconds:.1f} s, {loss.total} messages ({per_topic};"
             f" at the rates it measured, if its writer kept the pace of its {beat.flush_period:g} s flushes)")
    if loss.dropped:
        text += (f"; it had also dropped {sum(loss.dropped.values())} message(s) (queue full: "
                 + ", ".join(f"{t} {n}" for t, n in sorted(loss.dropped.items())) + ")")
    return text


def describe_damage(d: Damage) -> str:
    """One sentence on what a damaged file lost."""
    if not d.reason and not d.skipped_chunks:
        return f"{d.path}: read to the end"
    parts = []
    if d.not_closed:
        parts.append(describe_unclosed(d))
    if d.reason and d.reason != "the file ends without a footer":
        parts.append(f"{d.path}: {d.reason}; read {d.readable} of {d.size} bytes, {d.lost_bytes} bytes"
                     f" ({100.0 * d.lost_bytes / max(d.size, 1):.1f} %) lost")
        if d.lost_time is not None:
            a, b = d.lost_time
            parts.append(f"the cut chunk held messages logged {_sec(a):.3f}-{_sec(b):.3f} s")
    if d.skipped_chunks:
        parts.append(f"{len(d.skipped_chunks)} corrupt chunk(s) skipped: " + "; ".join(d.skipped_chunks))
    return "; ".join(parts)


# ------------------------------------------------------------------ bounded reading
class ChunkTooLarge(ValueError):
    """A chunk inflates to more bytes than it declares."""


def _is_sqlite(path: pathlib.Path) -> bool:
    with open(path, "rb") as f:
        return f.read(16) == b"SQLite format 3\x00"


def _check_magic(path: pathlib.Path, head: bytes) -> None:
    """BagError unless ``head`` (the first 8 bytes) is the MCAP magic; a file cut inside it is said to be cut."""
    if head == MAGIC:
        return
    if MAGIC.startswith(head):
        what = "is empty (0 bytes)" if not head else f"ends after {len(head)} of the 8 bytes of the MCAP magic"
        raise BagError(f"{path} {what}: recording not closed (the recorder created the file and wrote nothing"
                       " more), no message to read")
    raise BagError(f"{path}: not an MCAP file (its first bytes are {head.hex(' ')}, the MCAP magic is"
                   f" {MAGIC.hex(' ')})")


def check_chunk(offset: int, compression: str, uncompressed: int, compressed: int, limits: ReadLimits,
                path: str | pathlib.Path = "") -> None:
    """BagError if a chunk declares more uncompressed bytes than the limit or than a sane ratio allows.

    Parameters
    ----------
    offset : int
        Byte offset of the chunk record in its file (for the message).
    compression : str
        "", "zstd" or "lz4".
    uncompressed, compressed : int
        Declared uncompressed size and size of the compressed data, bytes.
    limits : ReadLimits
        The bounds.
    path : path, optional
        The file (for the message).
    """
    where = f"{path}: " if path else ""
    if uncompressed > limits.chunk_bytes:
        raise BagError(f"{where}chunk at offset {offset} declares {size_text(uncompressed)} uncompressed, beyond"
                       f" the limit of {size_text(limits.chunk_bytes)} (not inflated; raise --max-chunk-mib if it is"
                       " genuine)")
    if compression and uncompressed > limits.compression_ratio * max(compressed, 1):
        raise BagError(f"{where}chunk at offset {offset} declares {size_text(uncompressed)} uncompressed from"
                       f" {size_text(compressed)} of {compression} data, a ratio of"
                       f" {uncompressed / max(compressed, 1):.0f} beyond the limit of {limits.compression_ratio:g}"
                       " (not inflated)")


def inflate(data: bytes, compression: str, declared: int) -> bytes:
    """A chunk's data, uncompressed, never more than ``declared`` + 1 bytes produced.

    Raises
    ------
    ChunkTooLarge
        The data inflates beyond ``declared`` bytes (the inflation stops there).
    ValueError
        Unknown compression.
    """
    if compression == "":
        out = data
    elif compression == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data), read_across_frames=True)
        parts, got = [], 0
        while got <= declared:
            part = reader.read(declared + 1 - got)
            if not part:
                break
            parts.append(part)
            got += len(part)
        out = b"".join(parts)
    elif compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=declared + 1)
    else:
        raise ValueError(f"unsupported chunk compression {compression!r}")
    if len(out) > declared:
        raise ChunkTooLarge(f"the {compression or 'uncompressed'} data inflates beyond the {declared} bytes the chunk"
                            " declares")
    return out


def _bound_rosbags_decompressors() -> None:
    """Make rosbags' MCAP reader inflate through :func:`inflate` (bounded by each chunk's declared size,
    which :func:`scan_mcap` has checked against the limits before rosbags opens the file)."""
    from rosbags.rosbag2 import storage_mcap

    def bounded(compression: str) -> Callable[[bytes, int], bytes]:
        return lambda data, size: inflate(data, compression, size)

    for name in ("lz4", "zstd"):
        storage_mcap.DECOMPRESSORS[name] = bounded(name)


@dataclass
class McapScan:
    """What walking an MCAP file's record headers found (see :func:`scan_mcap`).

    Attributes
    ----------
    path : path
        The file.
    size : int
        File size, bytes.
    closed : bool
        The file ends with its footer.
    chunks : int
        Complete chunk records.
    end : int
        Byte offset where the complete records end.
    reason : str
        Why the walk stopped before a footer ("" if closed).
    """

    path: pathlib.Path
    size: int
    closed: bool = False
    chunks: int = 0
    end: int = 8
    reason: str = ""

    def describe(self) -> str:
        return (f"{self.path}: recording not closed (no summary/footer): {self.chunks} complete chunk(s)"
                f" ({self.end} of {self.size} bytes), then {self.reason}")


def scan_mcap(path: pathlib.Path, limits: ReadLimits | None = None) -> McapScan:
    """Walk an MCAP file record header by record header, seeking over the bodies, and check its chunks.

    Reads 9 bytes per record and 40 bytes plus the compression name per chunk: never more than the
    file holds, nothing inflated.

    Raises
    ------
    BagError
        Not an MCAP file (magic bytes), or a chunk declares an uncompressed size beyond
        ``limits.chunk_bytes`` or beyond ``limits.compression_ratio`` times its compressed size.
    """
    limits = limits or ReadLimits()
    size = path.stat().st_size
    scan = McapScan(path, size)
    with open(path, "rb") as f:
        _check_magic(path, f.read(8))
        pos = 8
        while True:
            head = f.read(9)
            if len(head) < 9:
                scan.reason = "the file ends" if not head else f"cut inside a record header at byte {pos}"
                return scan
            op, length = head[0], struct.unpack("<Q", head[1:])[0]
            if pos + 9 + length > size:
                scan.reason = (f"cut inside a {_OPNAMES.get(op, hex(op))} record at byte {pos}"
                               f" ({size - pos - 9} of its {length} bytes written)")
                return scan
            if op == OP_CHUNK:
                _check_chunk_header(f, pos, length, limits, path)
                scan.chunks += 1
            elif op == OP_FOOTER:
                scan.closed, scan.end = True, pos + 9 + length
                return scan
            pos += 9 + length
            scan.end = pos
            f.seek(pos)


def _check_chunk_header(f: BinaryIO, pos: int, length: int, limits: ReadLimits, path: pathlib.Path) -> None:
    """Read the fixed fields of the chunk record at ``pos`` and check its sizes (BagError)."""
    fixed = f.read(28)
    if len(fixed) < 28 or length < 40:
        raise BagError(f"{path}: chunk at offset {pos}: its record of {length} bytes is too short for a chunk"
                       " header")
    uncompressed = struct.unpack_from("<Q", fixed, 16)[0]
    (name_len,) = struct.unpack("<I", f.read(4))
    if name_len > min(length - 40, 64):
        raise BagError(f"{path}: chunk at offset {pos}: corrupt header (compression name of {name_len} bytes)")
    compression = f.read(name_len).decode("ascii", errors="replace")
    (compressed,) = struct.unpack("<Q", f.read(8))
    if compressed > length - 40 - name_len:
        raise BagError(f"{path}: chunk at offset {pos}: corrupt header (declares {compressed} compressed bytes in"
                       f" a record of {length})")
    check_chunk(pos, compression, uncompressed, compressed, limits, path)
