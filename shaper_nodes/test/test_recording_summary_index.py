"""A closed recording with one damaged chunk: the summary's chunk index saves the rest.

Before, a corrupt chunk length (a record header claiming more bytes than the file holds) ended the
record-by-record scan there, and a 3.6 MB file was reported 100 % lost though its summary still
indexed every other chunk. Now the chunk is read with the index's length, and a chunk whose content
is corrupt (or whose opcode is) is skipped to the next indexed chunk, the loss stated.
"""

from __future__ import annotations

import pathlib
import struct

import pytest

from shaper_nodes.recordings import (
    Bag,
    BagWriter,
    QueuedRecording,
    describe_damage,
    mcap_chunks,
    typestore_with_own_types,
)

STORE = typestore_with_own_types()
CHUNKS, PER_CHUNK = 6, 40


def _cdr(text: str) -> bytes:
    return bytes(STORE.serialize_cdr(STORE.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))


@pytest.fixture
def closed(tmp_path: pathlib.Path) -> bytes:
    """A closed recording (footer and summary) of six chunks of 40 messages on /imu."""
    t = [1_700_000_000_000_000_000]
    rec = QueuedRecording(BagWriter(tmp_path / "bag"), lambda: t[0], "/recorder/heartbeat", flush_period=3600.0)
    rec.add_topic("/imu", "std_msgs/msg/String")
    for c in range(CHUNKS):
        for k in range(PER_CHUNK):
            t[0] += 2_000_000
            rec.put("/imu", t[0], _cdr(f"{c}/{k}"))
        rec._drain()
        rec._flush()
    assert rec.close()
    return rec.bag.file.read_bytes()


def _read(path: pathlib.Path, recover: bool = False) -> tuple[list[str], Bag]:
    bag = Bag(path, recover=recover)
    with bag:
        got = [STORE.deserialize_cdr(raw, t).data for _, t, _, raw in bag.messages(["/imu"])]
    return got, bag


def _imu_chunks(data: bytes) -> list[tuple[int, int]]:
    chunks = mcap_chunks(data)
    assert len(chunks) >= CHUNKS
    return chunks


def test_a_corrupt_chunk_length_is_read_with_the_index_length(closed, tmp_path):
    data = closed
    start, _ = _imu_chunks(data)[0]
    bad = bytearray(data)
    struct.pack_into("<Q", bad, start + 1, 10**12)  # the first chunk claims 1 TB
    path = tmp_path / "length.mcap"
    path.write_bytes(bytes(bad))
    got, bag = _read(path)
    every = [f"{c}/{k}" for c in range(CHUNKS) for k in range(PER_CHUNK)]
    assert got == every, "nothing lost: the index gives the chunk's true length"
    (d,) = bag.damage
    assert d.readable == d.size and d.reason == ""
    assert any(f"chunk at byte {start}: its length field says {10**12} bytes" in s for s in d.skipped_chunks)


@pytest.mark.parametrize("which", [0, 2])
def test_a_chunk_with_corrupt_content_is_skipped_and_the_rest_read(closed, tmp_path, which):
    data = closed
    chunks = _imu_chunks(data)
    start, _ = chunks[which]
    bad = bytearray(data)
    # the chunk's header fields: start/end time, uncompressed size, CRC, compression string length
    struct.pack_into("<I", bad, start + 9 + 8 + 8 + 8 + 4, 0xFFFFFFF0)  # compression name of 4 GB
    path = tmp_path / "content.mcap"
    path.write_bytes(bytes(bad))
    got, bag = _read(path)
    lost_chunk = {f"{which}/{k}" for k in range(PER_CHUNK)}
    every = [f"{c}/{k}" for c in range(CHUNKS) for k in range(PER_CHUNK)]
    assert got == [m for m in every if m not in lost_chunk]
    (d,) = bag.damage
    text = describe_damage(d)
    assert f"skipped {chunks[which + 1][0] - start} bytes to the next chunk the summary indexes" in text
    assert "it held the messages logged" in text and "100.0 %" not in text


def test_a_corrupt_chunk_opcode_is_skipped_not_passed_over_silently(closed, tmp_path):
    data = closed
    start, _ = _imu_chunks(data)[1]
    bad = bytearray(data)
    bad[start] = 0x7E
    path = tmp_path / "opcode.mcap"
    path.write_bytes(bytes(bad))
    got, bag = _read(path)
    assert len(got) == CHUNKS * PER_CHUNK and not bag.damage, "rosbags reads it all through the summary"
    got, bag = _read(path, recover=True)  # the record-by-record scan (used when rosbags cannot open a file)
    assert len(got) == (CHUNKS - 1) * PER_CHUNK and not any(m.startswith("1/") for m in got)
    (d,) = bag.damage
    assert any("has opcode 0x7e where the summary indexes a chunk" in s for s in d.skipped_chunks)


def test_without_a_summary_reading_stops_at_the_damage_as_before(closed, tmp_path):
    data = closed
    start, _ = _imu_chunks(data)[1]
    bad = bytearray(data)
    struct.pack_into("<Q", bad, start + 1, 10**12)
    footer = len(bad) - 8 - 29
    struct.pack_into("<Q", bad, footer + 9, 0)  # the footer points at no summary
    path = tmp_path / "nosummary.mcap"
    path.write_bytes(bytes(bad))
    got, bag = _read(path)
    assert got == [f"0/{k}" for k in range(PER_CHUNK)]
    (d,) = bag.damage
    assert d.reason.startswith("cut inside a chunk record") and d.readable == start
