"""The recorder's writing: chunks closed by time, files cut anywhere still readable to their last
complete chunk, the loss bound, the bounded queue and write failures (an injected OSError, and a
real full disk where a tmpfs can be mounted)."""

from __future__ import annotations

import errno
import os
import pathlib
import random
import shutil
import struct
import subprocess
import threading
import time

import pytest
import yaml
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from shaper_nodes.recordings import (
    Bag,
    BagWriter,
    Heartbeat,
    QueuedRecording,
    describe_damage,
    loss_bound,
    mcap_chunks,
    rename_recording,
    typestore_with_own_types,
)

STORE = typestore_with_own_types()
HEARTBEAT = "/recorder/heartbeat"


def cdr(text: str) -> bytes:
    return bytes(STORE.serialize_cdr(STORE.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))


def independent(path: pathlib.Path) -> list[tuple[str, int, object]]:
    """(topic, log time, decoded message) of every complete message, with the ``mcap`` library's
    non-seeking reader and ``mcap_ros2``'s decoder; a file cut short ends the reading."""
    out = []
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, decoder_factories=[DecoderFactory()])
        try:
            for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
                out.append((channel.topic, message.log_time, decoded))
        except (McapError, EOFError, struct.error) as err:  # the cut
            assert "magic" not in str(err).lower() or out == [], err
    return out


def wait_for(done, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


class Clock:
    """A settable receive clock, ns."""

    def __init__(self) -> None:
        self.t = 1_700_000_000_000_000_000

    def __call__(self) -> int:
        return self.t


def test_chunks_are_closed_by_time_and_flushed_for_low_rate_topics(tmp_path):
    clock = Clock()
    rec = QueuedRecording(BagWriter(tmp_path / "bag"), clock, HEARTBEAT, flush_period=0.05, fsync=True).start()
    rec.add_topic("/events", "std_msgs/msg/String")
    file = rec.bag.file
    for k in range(3):  # one small message per period, far from rosbags' 1 MiB chunk size
        clock.t += 10**9
        assert rec.put("/events", clock.t, cdr(f"event {k}"))
        flushes, count = rec.flushes, k + 1
        wait_for(lambda: rec.written["/events"] == count and rec.flushes > flushes + 1,  # noqa: B023
                 "a flush after the message")
        # on disk now, while the writer is open: every message so far, decoded by an independent reader
        got = [m for m in independent(file) if m[0] == "/events"]
        assert [m[2].data for m in got] == [f"event {i}" for i in range(k + 1)]
    assert len(mcap_chunks(file.read_bytes())) >= 3
    assert rec.close()
    # closed: a rosbag2 folder (metadata.yaml version 9) that rosbags and mcap's indexed reader open
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}["/events"] == 3
    with AnyReader([tmp_path / "bag"]) as reader:
        assert reader.topics["/events"].msgcount == 3
        beats = reader.topics[HEARTBEAT].msgcount
        assert beats >= 3
    assert rec.bag.counts == {"/events": 3, HEARTBEAT: beats}  # what the recorder's closing line prints
    with open(file, "rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None and summary.statistics.message_count == 3 + beats
    with Bag(tmp_path / "bag") as bag:
        assert not bag.damage and not bag.notes


def _unclosed_recording(path: pathlib.Path, chunks: int = 6, per_chunk: int = 40) -> tuple[QueuedRecording, bytes]:
    """A recording of ``chunks`` flushes of ``per_chunk`` messages each, left open (as killed)."""
    clock = Clock()
    rec = QueuedRecording(BagWriter(path), clock, HEARTBEAT, flush_period=3600.0)
    rec.add_topic("/imu", "std_msgs/msg/String")
    for c in range(chunks):
        for k in range(per_chunk):
            clock.t += 2_000_000  # 500 Hz
            rec.put("/imu", clock.t, cdr(f"{c}/{k}" + "x" * random.Random(k).randrange(200)))
        rec._drain()
        rec._flush()
    return rec, rec.bag.file.read_bytes()


def test_a_file_cut_at_any_byte_keeps_every_complete_chunk(tmp_path):
    rec, data = _unclosed_recording(tmp_path / "bag")
    chunks = mcap_chunks(data)
    assert len(chunks) == 6
    rng = random.Random(18)
    for cut in [rng.randrange(len(data) + 1) for _ in range(25)] + [end + 9 + n for end, n in chunks]:
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        complete = sum(1 for start, n in chunks if start + 9 + n <= cut)
        expected = [f"{c}/{k}" for c in range(complete) for k in range(40)]
        got = [m[2].data.split("x")[0] for m in independent(path) if m[0] == "/imu"] if cut >= 8 else []
        assert got == expected, cut
        if cut < 8:
            continue
        with Bag(path) as bag:
            ours = [STORE.deserialize_cdr(raw, t).data.split("x")[0] for _, t, _, raw in bag.messages(["/imu"])]
            assert ours == expected, cut
            (d,) = bag.damage
            assert d.not_closed and d.messages_read == len(expected)
            text = describe_damage(d)
            assert text.startswith("recording not closed (recorder killed?)")
            if complete:
                assert d.loss is not None and f"at most ~{d.loss.seconds:.1f} s" in text
            else:
                assert "no recorder heartbeat" in text or "no message" in text
    rec.close()


def test_the_loss_bound_covers_what_the_recorder_held():
    # a heartbeat at t = 10 s: 500 Hz topic with 3 messages queued, 1 Hz topic; flush every 1 s
    beat = Heartbeat(10 * 10**9, 1.0, {"/imu": 5003, "/events": 10}, {"/imu": 5000, "/events": 10},
                     {"/imu": 0, "/events": 0}, {"/imu": 500.0, "/events": 1.0})
    assert beat.queued == {"/imu": 3, "/events": 0}
    assert Heartbeat.from_values(beat.stamp_ns, beat.to_values()) == beat
    loss = loss_bound(beat, first_ns=0)
    assert loss.seconds == pytest.approx(1.0) and loss.stopped_by_ns == 11 * 10**9
    # at most what was queued, plus the larger of the recent and the mean rate (5003 in 10 s) for 1 s
    assert loss.messages == {"/imu": 3 + 501, "/events": 1}
    # a chunk cut while written (its header read: messages up to 10.8 s): alive then, stopped before 11.8 s
    cut = loss_bound(beat, first_ns=0, cut_chunk_end_ns=10_800_000_000)
    assert cut.alive_ns == 10_800_000_000 and cut.seconds == pytest.approx(1.8)
    assert cut.messages["/imu"] == 3 + 901
    # a late writer (1.3 s since the previous flush, which took 0.2 s) and 0.5 s of receive lag widen it
    late = Heartbeat(beat.stamp_ns, 1.0, beat.received, beat.written, beat.dropped, beat.rates, 1.3, 0.2, 0.5)
    assert Heartbeat.from_values(late.stamp_ns, late.to_values()) == late
    slow = loss_bound(late, first_ns=0)
    assert slow.seconds == pytest.approx(1.3 + 0.2 + 0.5) and slow.stopped_by_ns == 11_500_000_000
    assert slow.messages["/imu"] == 3 + 1001
    with pytest.raises(ValueError, match="flush_period"):
        Heartbeat.from_values(0, [("received:/imu", "3")])


def test_the_reader_reports_the_bound_of_a_killed_recording(tmp_path):
    rec, _ = _unclosed_recording(tmp_path / "bag", chunks=3)
    rec.put("/imu", 10**19, cdr("queued when killed"))  # received, never written
    with Bag(tmp_path / "bag") as bag:
        (d,) = bag.damage
        assert d.heartbeat is not None and d.heartbeat.written == {"/imu": 120}
        # the flush period, plus the last flush's duration as measured on the wall clock (ms; more under load)
        assert d.loss is not None and 3600.0 <= d.loss.seconds < 3601.0
        assert d.data_end == d.heartbeat.stamp_ns
        text = describe_damage(d)
        assert "120 messages read" in text and "had written everything it received until" in text
        assert any("has no metadata.yaml" in n for n in bag.notes)
    rec.close()


def test_a_full_queue_drops_and_counts(tmp_path):
    clock = Clock()
    rec = QueuedRecording(BagWriter(tmp_path / "bag"), clock, HEARTBEAT, flush_period=3600.0,
                          max_queue_messages=5, max_queue_bytes=10**6)  # writer not started
    rec.add_topic("/imu", "std_msgs/msg/String")
    accepted = [rec.put("/imu", clock.t + k, cdr(str(k))) for k in range(8)]
    assert accepted == [True] * 5 + [False] * 3 and rec.dropped["/imu"] == 3 and rec.received["/imu"] == 8
    assert not rec.put("/imu", clock.t, b"x" * 2 * 10**6)  # larger than the byte bound
    assert rec.heartbeat().dropped == {"/imu": 4}
    assert rec.close(custom_data={"shaper_nodes.recorder.dropped": "/imu=4"})
    with Bag(tmp_path / "bag") as bag:
        assert any("dropped 4 message(s)" in n and "/imu: 4" in n for n in bag.notes)


class FailingFile:
    """A file object that takes ``budget`` bytes, then fails every write as a full disk does."""

    def __init__(self, inner, budget: int, err: int = errno.ENOSPC) -> None:
        self.inner, self.budget, self.err = inner, budget, err

    def write(self, data) -> int:
        if len(data) > self.budget:
            raise OSError(self.err, os.strerror(self.err))
        self.budget -= len(data)
        return self.inner.write(data)

    def __getattr__(self, name):
        return getattr(self.inner, name)


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EIO])
def test_a_write_failure_stops_the_recording_cleanly(tmp_path, err):
    clock = Clock()
    bag = BagWriter(tmp_path / "bag", wrap_file=lambda f: FailingFile(f, 20_000, err))
    rec = QueuedRecording(bag, clock, HEARTBEAT, flush_period=0.05).start()
    rec.add_topic("/imu", "std_msgs/msg/String")
    stop = threading.Event()

    def feed():  # paced by the writer (each message taken before the next): a writer thread starved by a busy
        # machine would otherwise find the whole 20 kB before its first flush, and nothing would reach the disk
        while not stop.is_set() and rec.put("/imu", clock.t, cdr("x" * 300)):
            clock.t += 2_000_000
            time.sleep(0.001)
            while rec.queued_messages and rec.failure is None and not stop.is_set():
                time.sleep(0.001)

    feeder = threading.Thread(target=feed)
    feeder.start()
    wait_for(lambda: rec.failure is not None, "the write failure")
    stop.set()
    feeder.join()
    assert rec.failure == f"cannot write {bag.file}: {os.strerror(err)} ({errno.errorcode[err]})"
    assert rec.queued_messages == 0 and rec.queued_bytes == 0
    assert not rec.put("/imu", clock.t, cdr("after"))  # refused: memory stays bounded
    assert not rec.close() and not (tmp_path / "bag" / "metadata.yaml").exists()
    # what reached the disk reads as a killed recording's
    written = independent(bag.file)
    assert 0 < len([m for m in written if m[0] == "/imu"]) <= rec.written["/imu"]
    with Bag(tmp_path / "bag") as bag_read:
        assert bag_read.damage[0].not_closed


def test_a_full_disk_stops_the_recording_cleanly(tmp_path):
    """A real full disk: a 1 MiB tmpfs (needs the right to mount; skipped without it)."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if shutil.which("mount") is None or subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (not root)")
    try:
        clock = Clock()
        rec = QueuedRecording(BagWriter(mnt / "bag"), clock, HEARTBEAT, flush_period=0.05).start()
        rec.add_topic("/imu", "std_msgs/msg/String")
        payload = cdr("x" * 2000)
        while rec.failure is None:
            rec.put("/imu", clock.t, payload)
            clock.t += 2_000_000
            time.sleep(0.002)  # about 500 Hz: chunks of about 50 kB, far below the tmpfs' size
            assert rec.received["/imu"] < 10**5, "1 MiB never filled"
        assert "No space left on device (ENOSPC)" in rec.failure
        assert not rec.close() and not (mnt / "bag" / "metadata.yaml").exists()
        got = [m for m in independent(rec.bag.file) if m[0] == "/imu"]
        assert len(got) > 100
        with Bag(mnt / "bag") as bag:
            assert bag.damage[0].messages_read == len(got)
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_analyze_bag_reports_a_killed_recording_it_cannot_analyse(tmp_path, capsys):
    """A killed low-rate recording (no accelerometer): the error, and what the recording holds and lost."""
    from shaper_nodes.cli import analyze_bag

    rec, _ = _unclosed_recording(tmp_path / "bag", chunks=2, per_chunk=3)
    assert analyze_bag.main([str(tmp_path / "bag"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "no accelerometer topic" in err
    assert "WARNING: damaged recording: recording not closed (recorder killed?): 6 messages read" in err
    assert "lost after its last flush: at most ~" in err
    rec.close()


def test_a_recording_that_cannot_be_created_is_named(tmp_path):
    (tmp_path / "a_file").write_text("")
    with pytest.raises(OSError, match=r"cannot create the recording .*a_file/bag: .*\(.*a_file\)"):
        BagWriter(tmp_path / "a_file" / "bag")
    with pytest.raises(FileExistsError, match="exists already"):
        BagWriter(tmp_path / "a_file")


def test_a_renamed_recording_names_its_file_after_the_new_folder(tmp_path):
    """As calibrate finishes a pose: ``pose_000.partial/pose_000.partial.mcap`` becomes ``pose_000/pose_000.mcap``,
    metadata.yaml lists the new name, and both rosbags and the independent reader read every message."""
    src, dst = tmp_path / "pose_000.partial", tmp_path / "pose_000"
    bag = BagWriter(src, compression="zstd")
    bag.add_topic("/text", "std_msgs/msg/String")
    for i in range(5):
        bag.write("/text", 1_000_000_000 + i, cdr(f"m{i}"))
    bag.close()
    assert (src / "pose_000.partial.mcap").exists()
    assert rename_recording(src, dst) == dst
    assert not src.exists() and sorted(p.name for p in dst.iterdir()) == ["metadata.yaml", "pose_000.mcap"]
    info = yaml.safe_load((dst / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == ["pose_000.mcap"] and [f["path"] for f in info["files"]] == ["pose_000.mcap"]
    assert "partial" not in (dst / "metadata.yaml").read_text()
    with AnyReader([dst]) as reader:
        assert [STORE.deserialize_cdr(raw, c.msgtype).data for c, _, raw in reader.messages()] == [
            f"m{i}" for i in range(5)]
    assert [m.data for _, _, m in independent(dst / "pose_000.mcap")] == [f"m{i}" for i in range(5)]
    with pytest.raises(ValueError, match="exists"):
        rename_recording(dst, dst)
    (tmp_path / "open").mkdir()
    with pytest.raises(ValueError, match=r"no metadata\.yaml"):
        rename_recording(tmp_path / "open", tmp_path / "closed")


def test_a_shaper_logged_with_a_later_end_at_the_same_time_is_put_after_it():
    """Ties of log time only: the shapers before the group's last END move to just after it, in their order; a
    shaper at another time, or after the END, or with no END in its group, stays where it was recorded."""
    from shaper_nodes.recordings import shaper_after_end

    def order(items, max_group=10_000):
        return [name for _, name in shaper_after_end(items, lambda m: m[0], lambda m: m[1].startswith("shaper"),
                                                     lambda m: m[1].startswith("END"), max_group)]

    rec = [(1, "imu a"), (1, "shaper 1"), (1, "imu b"), (1, "shaper 2"), (1, "END"), (1, "imu c"), (1, "START"),
           (2, "shaper 3"), (2, "START"), (3, "END"), (3, "shaper 4"), (4, "shaper 5"), (4, "imu d")]
    assert order(rec) == ["imu a", "imu b", "END", "shaper 1", "shaper 2", "imu c", "START",
                          "shaper 3", "START", "END", "shaper 4", "shaper 5", "imu d"]
    # a shaper before an END at a later time (a change during the cycle) stays before it
    assert order([(1, "shaper"), (2, "END")]) == ["shaper", "END"]
    # two ENDs at one time: after the last
    assert order([(5, "shaper"), (5, "END 1"), (5, "END 2"), (5, "imu")]) == ["END 1", "END 2", "shaper", "imu"]
    # a run longer than the bound goes as recorded
    assert order([(1, "shaper"), (1, "imu"), (1, "END")], max_group=2) == ["shaper", "imu", "END"]
    assert order([]) == []
