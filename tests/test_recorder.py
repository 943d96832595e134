"""The recorder over real DDS: killed with ``kill -9`` it keeps all but about the last second, a
low-rate recording included; a write failure stops it cleanly.

- A 500 Hz sensor_msgs/Imu stream, and a low-rate one (shaper_msgs/CycleEvent at a few Hz plus a
  latched topic), recorded by the recorder as a subprocess, killed with SIGKILL after a few
  seconds: every message the recorder reported flushed (its status on /diagnostics) is in the file,
  read back with the independent ``mcap`` reader and ``mcap_ros2``'s decoder, and the suite's reader
  says that the recording was not closed, with a loss bound from the recorder's heartbeat. (The
  loss in seconds at random kill times is a measurement: scripts/recorder_kill_table.py.)
- A write failure (an injected ENOSPC in-process, always; a real full 1 MiB tmpfs with the
  recorder as a subprocess, where mounting is permitted): ERROR on /diagnostics with the reason,
  subscriptions gone, ``~/stop`` answers false with the reason, exit status 1 with one line.
"""

from __future__ import annotations

import errno
import os
import signal
import struct
import subprocess
import time

import pytest
import rclpy
from builtin_interfaces.msg import Time
from conftest import Diagnosed, call_answered
from diagnostic_msgs.msg import DiagnosticStatus
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap_ros2.decoder import DecoderFactory
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import String
from std_srvs.srv import Trigger

from shaper_msgs.msg import CycleEvent
from shaper_nodes.nodes.recorder import RecorderNode
from shaper_nodes.recordings import Bag, describe_damage

pytestmark = pytest.mark.integration
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def independent(path) -> dict[str, list]:
    """topic -> decoded messages of every complete record, with the ``mcap`` library's non-seeking
    reader and ``mcap_ros2``'s decoder (a file cut short ends the reading)."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        try:
            for _, channel, _, decoded in NonSeekingReader(f, decoder_factories=[DecoderFactory()]
                                                           ).iter_decoded_messages(log_time_order=False):
                out.setdefault(channel.topic, []).append(decoded)
        except (McapError, EOFError, struct.error):
            pass  # cut by the kill
    return out


def wait_for(done, what: str, timeout: float = 60.0, spin=None) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        if spin is not None:
            spin()
        else:
            time.sleep(0.01)


def stamp_of(t: float) -> Time:
    ns = int(t * 1e9)
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)


def publish_until(count: int, rate: float, publish) -> list[float]:
    """Call ``publish(k, t)`` at ``rate`` Hz (wall clock) ``count`` times; returns the publish times."""
    times: list[float] = []
    start = time.time()
    for k in range(count):
        target = start + k / rate
        delay = target - time.time()
        if delay > 0:
            time.sleep(delay)
        t = time.time()
        publish(k, t)
        times.append(t)
    return times


def kill(proc) -> float:
    """SIGKILL the recorder; returns the wall time of the kill."""
    t = time.time()
    os.kill(proc.proc.pid, signal.SIGKILL)
    proc.proc.wait(timeout=30)
    return t


def flushed(diag: Diagnosed, topic: str) -> int:
    """The most messages of ``topic`` the recorder's status has reported flushed to the file."""
    counts = [int(kv.value) for s in diag.statuses if s.name == "recorder: recording"
              for kv in s.values if kv.key == f"flushed:{topic}"]
    return max(counts, default=0)


def test_a_killed_500_hz_recording_keeps_everything_it_reported_flushed(start_node, ros_context, tmp_path):
    """What the recorder reported flushed (its status on /diagnostics, every second) is in the file after a
    kill -9, read by an independent reader; the suite's reader says the recording was not closed and bounds
    the loss. (How much a kill loses in seconds is measured by scripts/recorder_kill_table.py.)"""
    out = tmp_path / "bag"
    rec = start_node("shaper_nodes", "recorder", {"output": str(out), "topics": ["/test_imu"]})
    node = rclpy.create_node("imu_source", context=ros_context)
    diag = Diagnosed(node)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    pub = node.create_publisher(Imu, "/test_imu", RELIABLE)
    wait_for(lambda: pub.get_subscription_count() >= 1, "the recorder's subscription")

    def publish(k: int, t: float) -> None:
        msg = Imu()
        msg.header.stamp, msg.header.frame_id = stamp_of(t), str(k)
        msg.linear_acceleration.z = 9.81
        pub.publish(msg)
        ex.spin_once(timeout_sec=0.0)

    times = publish_until(1500, 500.0, publish)  # 3 s
    wait_for(lambda: flushed(diag, "/test_imu") >= 500, "500 messages flushed", timeout=120.0,
             spin=lambda: ex.spin_once(timeout_sec=0.05))
    reported = flushed(diag, "/test_imu")
    kill(rec)
    assert rec.proc.returncode == -signal.SIGKILL

    assert not (out / "metadata.yaml").exists()
    got = {int(m.header.frame_id) for m in independent(out / "bag.mcap").get("/test_imu", [])}
    assert got <= set(range(len(times)))
    # one reliable publisher: the recorder received and wrote them in order, so the first `reported` are in
    must = set(range(reported))
    assert must <= got, f"reported {reported} flushed; missing: {sorted(must - got)[:10]}"
    with Bag(out) as bag:
        (d,) = bag.damage
        assert d.not_closed and d.messages_read == len(got)
        assert d.heartbeat is not None and d.loss is not None
        assert describe_damage(d).startswith("recording not closed (recorder killed?)")
    ex.shutdown()
    node.destroy_node()


def test_a_killed_low_rate_recording_is_not_empty(start_node, ros_context, tmp_path):
    node = rclpy.create_node("task", context=ros_context)
    diag = Diagnosed(node)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    latched = node.create_publisher(String, "/test_latched", LATCHED)
    latched.publish(String(data="the active shaper"))
    events = node.create_publisher(CycleEvent, "/test_events", RELIABLE)
    out = tmp_path / "bag"
    rec = start_node("shaper_nodes", "recorder", {"output": str(out), "topics": ["/test_events", "/test_latched"]})
    wait_for(lambda: events.get_subscription_count() >= 1 and latched.get_subscription_count() >= 1,
             "the recorder's subscriptions")

    def publish(k: int, t: float) -> None:
        msg = CycleEvent(event=k % 3, cycle=k // 3, task="test")
        msg.header.stamp = stamp_of(t)
        events.publish(msg)
        ex.spin_once(timeout_sec=0.0)

    publish_until(13, 4.0, publish)  # 3 s at 4 Hz
    wait_for(lambda: flushed(diag, "/test_events") >= 4 and flushed(diag, "/test_latched") >= 1,
             "the events and the latched message flushed", timeout=120.0, spin=lambda: ex.spin_once(timeout_sec=0.05))
    reported = flushed(diag, "/test_events")
    kill(rec)

    read = independent(out / "bag.mcap")
    assert [m.data for m in read.get("/test_latched", [])] == ["the active shaper"]
    got = [(m.cycle, m.event) for m in read.get("/test_events", [])]
    must = [(k // 3, k % 3) for k in range(reported)]
    assert got[:len(must)] == must
    with Bag(out) as bag:
        (d,) = bag.damage
        assert d.loss is not None and "recording not closed" in describe_damage(d)
    ex.shutdown()
    node.destroy_node()


class FailingFile:
    """Takes ``budget`` bytes, then fails every write as a full disk does."""

    def __init__(self, inner, budget: int) -> None:
        self.inner, self.budget = inner, budget

    def write(self, data) -> int:
        if len(data) > self.budget:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.budget -= len(data)
        return self.inner.write(data)

    def __getattr__(self, name):
        return getattr(self.inner, name)


class DiskFillingRecorder(RecorderNode):
    def _wrap_file(self):
        return lambda f: FailingFile(f, 40_000)


def test_a_write_failure_stops_the_recorder_cleanly(ros_context, tmp_path):
    recorder = DiskFillingRecorder(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "bag")), Parameter("topics", value=["/test_imu"]),
        Parameter("flush_period", value=0.2)])
    probe = rclpy.create_node("probe", context=ros_context)
    diag = Diagnosed(probe)
    pub = probe.create_publisher(Imu, "/test_imu", RELIABLE)
    stop = probe.create_client(Trigger, "/recorder/stop")
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (recorder, probe):
        ex.add_node(n)

    def spin() -> None:
        ex.spin_once(timeout_sec=0.002)

    wait_for(lambda: recorder.subscribed == ["/test_imu"] and pub.get_subscription_count() >= 1, "subscription",
             spin=spin)
    sent = 0

    def publish_and_spin() -> None:
        nonlocal sent
        pub.publish(Imu())
        sent += 1
        spin()

    wait_for(lambda: diag.find("recorder", "recording stopped") is not None, "the ERROR status",
             spin=publish_and_spin)
    status = diag.find("recorder", "recording stopped")
    assert status.level == DiagnosticStatus.ERROR and "No space left on device (ENOSPC)" in status.message
    assert str(tmp_path / "bag") in status.message
    assert recorder.subscribed == [] and recorder.recording.queued_messages == 0
    wait_for(lambda: pub.get_subscription_count() == 0, "the subscription to go", spin=publish_and_spin)
    received = recorder.recording.received["/test_imu"]
    for _ in range(50):
        publish_and_spin()
    assert recorder.recording.received["/test_imu"] == received  # nothing more is taken in
    assert stop.wait_for_service(timeout_sec=30.0)
    future = stop.call_async(Trigger.Request())
    wait_for(future.done, "the ~/stop reply", spin=spin)
    assert future.result().success is False and "No space left on device" in future.result().message
    recorder.close()
    assert recorder.exit_code == 1 and recorder.exit_reason.startswith("recording stopped: cannot write")
    assert not (tmp_path / "bag" / "metadata.yaml").exists()
    with Bag(tmp_path / "bag") as bag:
        assert bag.damage[0].not_closed  # readable up to its last complete chunk
    ex.shutdown()
    recorder.destroy_node()
    probe.destroy_node()


def test_a_full_disk_stops_the_recorder_process(start_node, ros_context, tmp_path):
    """A real full disk: a 1 MiB tmpfs (skipped where mounting is not permitted)."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (not root)")
    try:
        rec = start_node("shaper_nodes", "recorder", {"output": str(mnt / "bag"), "topics": ["/test_imu"]})
        node = rclpy.create_node("imu_source", context=ros_context)
        diag = Diagnosed(node)
        pub = node.create_publisher(Imu, "/test_imu", RELIABLE)
        stop = node.create_client(Trigger, "/recorder/stop")
        ex = SingleThreadedExecutor(context=ros_context)
        ex.add_node(node)
        wait_for(lambda: pub.get_subscription_count() >= 1, "the recorder's subscription")
        msg = Imu()
        msg.header.frame_id = "x" * 1000  # about 0.5 MB/s at 500 Hz

        def publish_and_spin() -> None:
            pub.publish(msg)
            ex.spin_once(timeout_sec=0.002)

        wait_for(lambda: diag.find("recorder", "recording stopped") is not None, "the ERROR status",
                 spin=publish_and_spin)
        assert "No space left on device (ENOSPC)" in diag.find("recorder", "recording stopped").message
        wait_for(lambda: pub.get_subscription_count() == 0, "the subscription to go", spin=publish_and_spin)
        # another process: the reply may be lost at match, and a stopped recording answers the same again
        assert call_answered(ex, stop, Trigger.Request(), "/recorder/stop", timeout=60.0).success is False
        assert rec.running()  # it keeps running to answer and report
        assert rec.stop() == 1
        last = rec.log_path.read_text().strip().splitlines()[-1]
        assert last.startswith("recorder: recording stopped: cannot write") and "(ENOSPC)" in last
        assert not (mnt / "bag" / "metadata.yaml").exists()
        read = independent(mnt / "bag" / "bag.mcap")
        assert len(read.get("/test_imu", [])) > 100
        ex.shutdown()
        node.destroy_node()
    finally:
        subprocess.run(["umount", str(mnt)], check=False)
