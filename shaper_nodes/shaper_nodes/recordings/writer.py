"""rosbag2 folders with MCAP storage, written with the pure-Python ``rosbags`` library.

rosbag2_py is not on PyPI, so recordings are written with rosbags' Writer (metadata.yaml plus
an MCAP file with ros2msg schemas). Message definitions come from :mod:`.typestore` (rosbags'
Jazzy typestore plus this suite's own types), so that ``ros2 bag info`` and independent readers
(``mcap`` with ``mcap-ros2-support``) can decode every message.

rosbags' MCAP storage closes a chunk when it exceeds 1 MiB; :meth:`BagWriter.flush` also closes
the chunk being filled (``close_chunk`` of rosbags' MCAP storage) and hands the file's bytes to
the operating system (``flush``, and ``os.fsync`` if asked), so that a process killed with
``kill -9`` leaves every message written before the last flush in complete chunks.
:class:`QueuedRecording` is the recorder's writing off the subscription callbacks: a bounded
queue, a writer thread that flushes every ``flush_period`` s with a heartbeat
(:mod:`.heartbeat`), and a write failure that stops the recording cleanly.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import os
import pathlib
import threading
import time
from collections.abc import Callable
from typing import Any, BinaryIO

from rosbags.interfaces import Connection
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from .heartbeat import HEARTBEAT_NAME, HEARTBEAT_TYPE, Heartbeat, rates_between
from .typestore import typestore_with_own_types

#: chunk compressions a recording may use
COMPRESSIONS = ("none", "zstd")


class BagWriter:
    """A rosbag2 folder with MCAP storage; add topics as they appear, write CDR bytes, flush.

    Parameters
    ----------
    path : path
        The folder to create (must not exist).
    wrap_file : callable, optional
        Wraps the open MCAP file object (tests inject failing files with it).
    compression : {"none", "zstd"}
        Chunk compression of the MCAP file ("zstd": each chunk zstd-compressed, as rosbag2's MCAP
        storage can write it; every MCAP reader inflates it).

    Raises
    ------
    FileExistsError
        The folder exists.
    OSError
        It cannot be created or written.
    """

    def __init__(self, path: str | pathlib.Path,
                 wrap_file: Callable[[BinaryIO], BinaryIO] | None = None, compression: str = "none") -> None:
        self.path = pathlib.Path(path)
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
        if self.path.exists():
            raise FileExistsError(f"recording folder {self.path} exists already")
        self._store = typestore_with_own_types()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compression == "zstd":  # rosbags' STORAGE mode: the MCAP chunks are zstd-compressed
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer.open()
        except OSError as err:
            where = f" ({err.filename})" if err.filename and str(err.filename) != str(self.path) else ""
            raise OSError(f"cannot create the recording {self.path}: {err.strerror or err}{where}") from None
        self._storage: Any = self._writer.storage
        if not (callable(getattr(self._storage, "close_chunk", None)) and hasattr(self._storage, "bio")
                and hasattr(self._storage, "chunk")):
            raise RuntimeError("this rosbags version's MCAP writer has no close_chunk(): chunks cannot be"
                               " closed by time")
        storage: Any = self._storage
        if wrap_file is not None:
            storage.bio = wrap_file(storage.bio)
        storage.bio.flush()  # the MCAP header: a file killed before its first flush is not empty
        self._connections: dict[str, Connection] = {}
        self._dir_synced = False
        self.counts: dict[str, int] = {}

    @property
    def file(self) -> pathlib.Path:
        """The MCAP file."""
        return pathlib.Path(self._storage.path) if self._storage is not None else self.path / f"{self.path.name}.mcap"

    def add_topic(self, topic: str, type_name: str) -> None:
        if topic not in self._connections:
            if type_name not in self._store.fielddefs:
                raise KeyError(f"no message definition for {type_name}")
            self._connections[topic] = self._writer.add_connection(topic, type_name, typestore=self._store)
            self.counts[topic] = 0

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        self._writer.write(self._connections[topic], int(timestamp_ns), data)
        self.counts[topic] += 1

    def write_heartbeat(self, topic: str, heartbeat: Heartbeat) -> None:
        """Write a recorder heartbeat (a DiagnosticStatus) at its own stamp; adds the topic if new."""
        self.add_topic(topic, HEARTBEAT_TYPE)
        types = self._store.types
        status = types[HEARTBEAT_TYPE](
            level=0, name=HEARTBEAT_NAME, message="alive", hardware_id="",
            values=[types["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in heartbeat.to_values()])
        self._writer.write(self._connections[topic], heartbeat.stamp_ns,
                           bytes(self._store.serialize_cdr(status, HEARTBEAT_TYPE)))
        self.counts[topic] += 1  # the recorder's closing line counted 0 heartbeats of the 24 written (session 11)

    def flush(self, fsync: bool = False) -> None:
        """Close the chunk being filled (if it holds a message) and hand the file to the OS.

        Parameters
        ----------
        fsync : bool
            Also ``os.fsync`` the file (and the folder, once): the data then survives a power cut
            too, where the disk honours it.
        """
        storage = self._storage
        if storage.chunk.msgs:
            storage.close_chunk()
        storage.bio.flush()
        if fsync:
            os.fsync(storage.bio.fileno())
            if not self._dir_synced:
                fd = os.open(self.path, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                self._dir_synced = True

    def set_custom_data(self, key: str, value: str) -> None:
        """A key of metadata.yaml's ``custom_data`` (written at close)."""
        self._writer.set_custom_data(key, value)

    def close(self) -> None:
        """Write the summary, the footer and metadata.yaml."""
        self._writer.close()
        self._storage = None

    def abandon(self) -> None:
        """Let the file be, as it is, after a write failure: no summary, no metadata.yaml."""
        storage, self._storage = self._storage, None
        self._writer.storage = None
        if storage is not None:
            with contextlib.suppress(OSError):  # its buffer cannot be written either
                storage.bio.close()


def rename_recording(src: str | pathlib.Path, dst: str | pathlib.Path) -> pathlib.Path:
    """Rename a closed rosbag2 folder ``src`` to ``dst``, its one MCAP file to ``<dst name>.mcap`` with it.

    rosbags names the file after the folder, so a folder written as ``pose_000.partial`` holds
    ``pose_000.partial.mcap``. The file is renamed and metadata.yaml's ``relative_file_paths`` and
    ``files`` entries rewritten (atomically: a temporary file renamed over it) while the folder still
    has its old name; the folder's rename comes last and is the commit: a process killed before it
    leaves ``src`` complete but under its old name.

    Parameters
    ----------
    src : path
        A closed recording folder (metadata.yaml and one MCAP file).
    dst : path
        Its new path (must not exist).

    Returns
    -------
    pathlib.Path
        ``dst``.

    Raises
    ------
    ValueError
        ``src`` has no metadata.yaml or not exactly one file, or ``dst`` exists.
    """
    import yaml

    src, dst = pathlib.Path(src), pathlib.Path(dst)
    if dst.exists():
        raise ValueError(f"cannot rename the recording {src} to {dst}: {dst} exists")
    meta = src / "metadata.yaml"
    if not meta.is_file():
        raise ValueError(f"cannot rename the recording {src}: no metadata.yaml (not closed?)")
    text = meta.read_text()
    info = yaml.safe_load(text)["rosbag2_bagfile_information"]
    files = list(info.get("relative_file_paths") or [])
    if len(files) != 1:
        raise ValueError(f"cannot rename the recording {src}: {len(files)} files in metadata.yaml, expected one")
    old, new = files[0], f"{dst.name}.mcap"
    if old != new:
        lines = [_renamed(line, old, new) for line in text.splitlines(keepends=True)]
        check = yaml.safe_load("".join(lines))["rosbag2_bagfile_information"]
        if check.get("relative_file_paths") != [new] or any(f.get("path") != new for f in check.get("files") or []):
            raise ValueError(f"cannot rename the recording {src}: metadata.yaml does not list {old} as expected")
        (src / old).rename(src / new)
        tmp = src / "metadata.yaml.tmp"
        tmp.write_text("".join(lines))
        os.replace(tmp, meta)
    src.rename(dst)
    return dst


def _renamed(line: str, old: str, new: str) -> str:
    """``line`` of metadata.yaml with the file name ``old`` replaced by ``new`` where it is a value
    (``- old`` or ``path: old``)."""
    stripped = line.rstrip("\r\n")
    for prefix in ("- ", "path: ", "- path: "):
        body = stripped.lstrip(" ")
        if body == prefix + old:
            return stripped[: len(stripped) - len(body)] + prefix + new + line[len(stripped):]
    return line


def describe_write_error(err: BaseException, path: pathlib.Path) -> str:
    """One line naming a write failure: what, where and the system's reason."""
    if isinstance(err, OSError) and err.errno is not None:
        name = errno.errorcode.get(err.errno, str(err.errno))
        return f"cannot write {path}: {err.strerror or err} ({name})"
    return f"cannot write {path}: {type(err).__name__}: {err}"


class QueuedRecording:
    """A recording written off the subscription callbacks (see the module docstring).

    ``put`` (called by the subscription callbacks) only queues; a writer thread writes the queue
    every ``poll`` s, and every ``flush_period`` s writes a heartbeat and flushes
    (:meth:`BagWriter.flush`). The queue holds at most ``max_queue_bytes`` bytes and
    ``max_queue_messages`` messages; what does not fit is dropped and counted per topic. A write
    failure (a full disk, an I/O error, a permission) stops the writer: ``failure`` names it, the
    queue is emptied, ``put`` refuses everything, and the file is left as it is (readable up to
    its last complete chunk, like a killed recorder's).

    Parameters
    ----------
    bag : BagWriter
        Where to write.
    now_ns : callable returning int
        The receive clock, ns (the heartbeats' log time; that of the messages too).
    heartbeat_topic : str or None
        Topic of the heartbeat in the recording (None: none).
    flush_period : float
        Time between two flushes, s.
    fsync : bool
        ``os.fsync`` at every flush.
    max_queue_bytes, max_queue_messages : int
        Bounds of the queue.
    poll : float
        How often the writer thread takes the queue, s.
    """

    def __init__(self, bag: BagWriter, now_ns: Callable[[], int], heartbeat_topic: str | None = None,
                 flush_period: float = 1.0, fsync: bool = False, max_queue_bytes: int = 100_000_000,
                 max_queue_messages: int = 100_000, poll: float = 0.02) -> None:
        if not flush_period > 0.0:
            raise ValueError(f"flush_period must be positive, got {flush_period} s")
        self.bag, self.now_ns, self.heartbeat_topic = bag, now_ns, heartbeat_topic
        self.flush_period, self.fsync, self.poll = float(flush_period), bool(fsync), float(poll)
        self.max_queue_bytes, self.max_queue_messages = int(max_queue_bytes), int(max_queue_messages)
        self.received: collections.Counter[str] = collections.Counter()
        self.written: collections.Counter[str] = collections.Counter()
        self.dropped: collections.Counter[str] = collections.Counter()
        #: messages per topic written before the last completed flush (in the file, whatever happens next)
        self.flushed: dict[str, int] = {}
        self.queued_bytes = 0
        self.flushes = 0
        self.failure: str | None = None
        self._queue: collections.deque[tuple[str, int, bytes]] = collections.deque()
        self._qlock = threading.Lock()   # the queue's counters
        self._wlock = threading.Lock()   # the bag
        self._stop = threading.Event()
        self._closed = False
        self._last_counts: dict[str, int] = {}
        self._last_flush = time.monotonic()
        self._flush_time = 0.0
        self._lag = 0.0
        self.lag = 0.0  # the largest receive lag of the last full period, s
        self._thread = threading.Thread(target=self._loop, name="bag-writer", daemon=True)

    # ------------------------------------------------------------------ callbacks' side
    def start(self) -> QueuedRecording:
        self._thread.start()
        return self

    def add_topic(self, topic: str, type_name: str) -> None:
        """Add a topic (nothing once the recording has stopped).

        Raises
        ------
        KeyError
            No message definition for ``type_name``.
        """
        with self._wlock:
            if self.failure is None and not self._closed:
                self.bag.add_topic(topic, type_name)

    def put(self, topic: str, stamp_ns: int, data: bytes, lag: float = 0.0) -> bool:
        """Queue one message; False if it was dropped (queue full) or the recording has stopped.

        ``lag`` is how long the message waited between the middleware and this call, s.
        """
        if self.failure is not None or self._closed:
            return False
        size = len(data)
        with self._qlock:
            self.received[topic] += 1
            if lag > self._lag:
                self._lag = lag
            if (self.queued_bytes + size > self.max_queue_bytes
                    or len(self._queue) >= self.max_queue_messages):
                self.dropped[topic] += 1
                return False
            self.queued_bytes += size
            self._queue.append((topic, stamp_ns, data))
        return True

    @property
    def queued_messages(self) -> int:
        return len(self._queue)

    # ------------------------------------------------------------------ writer thread
    def _loop(self) -> None:
        while not self._stop.wait(self.poll):
            try:
                self._drain()
                if time.monotonic() - self._last_flush >= self.flush_period:
                    self._flush()
            except Exception as err:  # a write failure of any kind stops the recording, named
                self._fail(err)
                return

    def _drain(self) -> None:
        while True:
            try:
                topic, stamp, data = self._queue.popleft()
            except IndexError:
                return
            with self._qlock:
                self.queued_bytes -= len(data)
            with self._wlock:
                self.bag.write(topic, stamp, data)
            self.written[topic] += 1

    def heartbeat(self) -> Heartbeat:
        """What the recorder knows now (counts since the start, rates over the last period)."""
        now = time.monotonic()
        with self._qlock:
            received, dropped, lag = dict(self.received), dict(self.dropped), self._lag
        interval = now - self._last_flush
        rates = rates_between(self._last_counts, received, interval)
        return Heartbeat(int(self.now_ns()), self.flush_period, received, dict(self.written), dropped, rates,
                         interval, self._flush_time, lag)

    def _flush(self) -> None:
        beat = self.heartbeat()
        written = dict(self.written)  # the writer thread is the only one that writes: all of these are in
        with self._qlock:
            self.lag, self._lag = self._lag, 0.0
        start = time.monotonic()
        with self._wlock:
            if self.heartbeat_topic:
                self.bag.write_heartbeat(self.heartbeat_topic, beat)
            self.bag.flush(self.fsync)
        self._flush_time = time.monotonic() - start
        self._last_counts, self._last_flush = beat.received, start
        self.flushed = written
        self.flushes += 1

    def _fail(self, err: BaseException) -> None:
        self.failure = describe_write_error(err, self.bag.file)
        with self._qlock:
            self._queue.clear()
            self.queued_bytes = 0
        with self._wlock:
            self.bag.abandon()

    # ------------------------------------------------------------------ the end
    def close(self, custom_data: dict[str, str] | None = None, timeout: float = 10.0) -> bool:
        """Stop the writer, write what is queued and finish the bag (idempotent).

        Returns False if the recording failed (now or before): then no metadata.yaml is written.
        """
        if self._closed:
            return self.failure is None
        self._closed = True
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout)
        if self.failure is not None:
            return False
        try:
            self._drain()
            self._flush()
            with self._wlock:
                for key, value in (custom_data or {}).items():
                    self.bag.set_custom_data(key, value)
                self.bag.close()
        except Exception as err:
            self._fail(err)
            return False
        return True
