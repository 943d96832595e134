"""Open a recording and iterate its messages, within bounds, damaged or not.

A recording is a rosbag2 folder (metadata.yaml plus storage files) or a bare ``.mcap`` file.
:class:`Bag` opens it: metadata.yaml's size is checked before it is parsed and every MCAP file is
walked header by header first (:mod:`.bounds`); rosbags' :class:`~rosbags.highlevel.AnyReader`
then reads an intact one (MCAP or sqlite3), its decompressors bounded. A file that was not closed
or does not open is scanned record by record (:mod:`.recovery`) and its :class:`~.recovery.Damage`
said. A closed recording whose recorder dropped messages (queue full) says so from metadata.yaml's
``custom_data``. Messages are deserialised with rosbags' typestores (:mod:`.typestore` for bags
without definitions).

:func:`read_metadata` is the one entry point to a recording's metadata.yaml (bounded): every tool
that reads one (``analyze_bag``, ``analyze_fleet``, calibrate, bag_play) goes through it.
"""

from __future__ import annotations

import pathlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .bounds import ReadLimits, bound_rosbags_decompressors, is_sqlite, read_metadata, scan_mcap
from .damage import Damage
from .errors import BagError
from .recovery import RecoveredFile
from .typestore import default_typestore

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys.store import Typestore

class BagRecovery(Exception):
    """Internal: read the recording with the record-by-record scan."""

@dataclass(frozen=True)
class TopicInfo:
    """A topic of the recording: its type and message count (None: not known before reading)."""

    topic: str
    msgtype: str
    count: int | None

@dataclass
class ReadResult:
    """Counters of one pass over the messages (filled while iterating)."""

    messages: int = 0
    undecodable: dict[str, str] = field(default_factory=dict)  # msgtype -> why

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
        self._recovered: list[RecoveredFile] = []
        if not self.path.exists():
            raise BagError(f"no recording at {self.path}")
        files, expected, has_meta = mcap_files(self.path, self.limits)  # metadata.yaml's size checked
        # every MCAP file walked header by header before anything is inflated (BagError if refused)
        scans = [scan_mcap(f, self.limits) for f in files if not is_sqlite(f)]
        unclosed = [sc for sc in scans if not sc.closed or sc.corrupt]
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
            self._recovered = [RecoveredFile(f, self.limits) for f in files]
            for rec in self._recovered:
                rec.damage.expected_messages = expected if len(files) == 1 else None
                self.damage.append(rec.damage)
            self.reader_name = "mcap record scan (recovery)"

    # ----------------------------------------------------------------- opening
    def _open_rosbags(self) -> None:
        from rosbags.highlevel import AnyReader

        bound_rosbags_decompressors()
        if self.path.is_dir() and not (self.path / "metadata.yaml").exists():
            raise OSError("no metadata.yaml")
        reader = AnyReader([self.path], default_typestore=default_typestore())
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
