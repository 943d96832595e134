"""Bounds on what reading a recording may cost, checked before anything is parsed or inflated.

metadata.yaml's size is checked before it is parsed (:func:`read_metadata`); every MCAP file is
first walked record header by record header (:func:`scan_mcap`, seeking over the bodies), which
refuses a file that is not MCAP, a chunk whose declared uncompressed size is beyond the limit or
beyond a sane compression ratio (:func:`check_chunk`), and tells a file that was not closed (a
record longer than what remains of the file: "cut inside") before any chunk is inflated. Every
chunk is then inflated by :func:`inflate`, which never produces more than the chunk declares,
both in the record scan (:mod:`.recovery`) and inside rosbags' reader (whose decompressors
:func:`bound_rosbags_decompressors` replaces with it). The limits are one :class:`ReadLimits`.
"""

from __future__ import annotations

import io
import pathlib
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import BinaryIO

from .errors import BagError, ChunkTooLarge

#: MCAP magic (start and end of a file)
MAGIC = b"\x89MCAP0\r\n"
#: MCAP opcodes used here
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x02, 0x0F

#: names of the MCAP opcodes, for messages
OPNAMES = {0x01: "header", OP_FOOTER: "footer", OP_SCHEMA: "schema", OP_CHANNEL: "channel", OP_MESSAGE: "message",
           OP_CHUNK: "chunk", 0x07: "message index", 0x08: "chunk index", 0x09: "attachment",
           0x0A: "attachment index", 0x0B: "statistics", 0x0C: "metadata", 0x0D: "metadata index",
           0x0E: "summary offset", OP_DATA_END: "data-end"}

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

def is_sqlite(path: pathlib.Path) -> bool:
    with open(path, "rb") as f:
        return f.read(16) == b"SQLite format 3\x00"

def check_magic(path: pathlib.Path, head: bytes) -> None:
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

def bound_rosbags_decompressors() -> None:
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
    corrupt: list[str] = field(default_factory=list)

    def describe(self) -> str:
        if self.closed:
            return f"{self.path}: " + "; ".join(self.corrupt)
        return (f"{self.path}: recording not closed (no summary/footer): {self.chunks} complete chunk(s)"
                f" ({self.end} of {self.size} bytes), then {self.reason}")

def scan_mcap(path: pathlib.Path, limits: ReadLimits | None = None) -> McapScan:
    """Walk an MCAP file record header by record header, seeking over the bodies, and check its chunks.

    Reads 9 bytes per record and 40 bytes plus the compression name per chunk: never more than the
    file holds, nothing inflated.

    A chunk whose header cannot be one (a compression name or a compressed size larger than its
    record) is damage, not a threat: it is listed in ``corrupt`` (the file is then read record by
    record, which skips it) and the walk goes on.

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
        check_magic(path, f.read(8))
        pos = 8
        while True:
            head = f.read(9)
            if len(head) < 9:
                scan.reason = "the file ends" if not head else f"cut inside a record header at byte {pos}"
                return scan
            op, length = head[0], struct.unpack("<Q", head[1:])[0]
            if pos + 9 + length > size:
                scan.reason = (f"cut inside a {OPNAMES.get(op, hex(op))} record at byte {pos}"
                               f" ({size - pos - 9} of its {length} bytes written)")
                return scan
            if op == OP_CHUNK:
                damage = _check_chunk_header(f, pos, length, limits, path)
                if damage:
                    scan.corrupt.append(damage)
                else:
                    scan.chunks += 1
            elif op == OP_FOOTER:
                scan.closed, scan.end = True, pos + 9 + length
                return scan
            pos += 9 + length
            scan.end = pos
            f.seek(pos)

def _check_chunk_header(f: BinaryIO, pos: int, length: int, limits: ReadLimits, path: pathlib.Path) -> str:
    """Read the fixed fields of the chunk record at ``pos``: "" if sound, else what is corrupt.

    Sizes beyond the limits raise :class:`BagError` (see :func:`scan_mcap`).
    """
    fixed = f.read(28)
    if len(fixed) < 28 or length < 40:
        return f"chunk at offset {pos}: its record of {length} bytes is too short for a chunk header"
    uncompressed = struct.unpack_from("<Q", fixed, 16)[0]
    (name_len,) = struct.unpack("<I", f.read(4))
    if name_len > min(length - 40, 64):
        return f"chunk at offset {pos}: corrupt header (compression name of {name_len} bytes)"
    compression = f.read(name_len).decode("ascii", errors="replace")
    (compressed,) = struct.unpack("<Q", f.read(8))
    if compressed > length - 40 - name_len:
        return f"chunk at offset {pos}: corrupt header (declares {compressed} compressed bytes in a record of {length})"
    check_chunk(pos, compression, uncompressed, compressed, limits, path)
    return ""
