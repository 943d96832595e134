"""Recorder node: chosen topics, serialized CDR as received, into a rosbag2 MCAP folder.

For machines without rosbag2 (it is not on PyPI). Subscriptions take the raw bytes and only
queue them (a bounded queue); a writer thread writes them, so no disk I/O happens in a callback.
Topics are found by name as they appear on the graph (types from the graph), with a QoS that
matches their publishers (TRANSIENT_LOCAL for latched topics such as the active shaper).

Every ``flush_period`` s the writer closes the MCAP chunk being filled, writes a heartbeat of
its own into it (``<node>/heartbeat``, a DiagnosticStatus with the counts received, written and
dropped per topic; see :mod:`shaper_nodes.recordings.heartbeat`) and flushes the file to the
operating system (and ``os.fsync`` with ``fsync``), so that a recorder killed with ``kill -9``
loses at most about ``flush_period`` s, and the analysis can say how much at most. The bag is
finished (summary, footer, metadata.yaml) on shutdown (SIGINT) or by the ``~/stop`` service.

A write failure (a full disk, an I/O error, a permission) stops the recording cleanly: the
reason goes to the log and ``/diagnostics`` (ERROR, repeated every second), the subscriptions
are destroyed and the queue emptied (memory stays bounded), the file is left readable up to its
last complete chunk (no metadata.yaml), ``~/stop`` answers ``success: false`` with the reason,
and the node keeps running until it is shut down, then exits with status 1 and the reason on one
line. A full queue drops the newest messages, counted per topic and reported (WARN).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, BinaryIO

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from std_srvs.srv import Trigger

from shaper_nodes.core.lockstep import Gaps
from shaper_nodes.recordings import COMPRESSIONS, HEARTBEAT_SUFFIX, BagWriter, QueuedRecording
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from shaper_nodes.ros.lockstep_reader import HEADER_FIRST, STREAM_QOS, LockstepReader, header_stamp, subscribe_draining
from shaper_nodes.ros.message_types import message_class
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import Spec, declare, param, table
from shaper_nodes.ros.qos import SERVICE_QOS


@dataclass(frozen=True)
class RecorderParams:
    """The recorder node's parameters."""

    output: str = param("recording", "rosbag2 folder to create (must not exist).", read_only=True)
    topics: tuple[str, ...] = param(
        ["/joint_states", "/tip_imu", "/cycle_events"], "Topics to record (fully qualified names).",
        read_only=True)
    compression: str = param("none", "MCAP chunk compression: 'zstd' compresses each chunk (a 500 Hz IMU recording"
         " shrinks several times), 'none' writes them as they are.", choices=COMPRESSIONS, read_only=True)
    discovery_period: float = param(0.2, "How often to look for requested topics not yet subscribed, s.", (0.01, 60.0),
                                    read_only=True)
    flush_period: float = param(1.0, "Time between two flushes of the recording to the operating system (MCAP chunk"
         " closed, heartbeat written), s: a killed recorder loses at most about this much.", (0.05, 60.0),
         read_only=True)
    fsync: bool = param(True, "os.fsync the file at every flush (the data then also survives a power cut, where the"
                        " disk honours it); false: flush to the operating system only (enough for a killed process).",
                        read_only=True)
    max_queue_mb: float = param(100.0, "Most bytes waiting to be written, MB (10^6 bytes); beyond, new messages are"
                                " dropped and counted.", (0.001, 100000.0), read_only=True)
    max_queue_messages: int = param(100000, "Most messages waiting to be written; beyond, new messages are dropped"
                                    " and counted.", (1, 10**8), read_only=True)


#: the recorder node's parameters (derived from RecorderParams)
PARAMETERS: tuple[Spec, ...] = table(RecorderParams)


class RecorderNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("recorder", *args, **kwargs)
        self.params = declare(self, RecorderParams)
        p = self.params.value
        self.wanted = [t if t.startswith("/") else "/" + t for t in p.topics]
        self.bag = BagWriter(p.output, wrap_file=self._wrap_file(), compression=str(p.compression))
        self.recording = QueuedRecording(
            self.bag, lambda: self.get_clock().now().nanoseconds,
            heartbeat_topic=self.get_fully_qualified_name().rstrip("/") + HEARTBEAT_SUFFIX,
            flush_period=float(p.flush_period), fsync=bool(p.fsync),
            max_queue_bytes=int(float(p.max_queue_mb) * 1e6),
            max_queue_messages=int(p.max_queue_messages)).start()
        self.diagnostics = Diagnostics(self, throttle=5.0)
        self._subs: dict[str, Subscription] = {}
        self._closed = False
        self._failed_handled = False
        self._dropped_seen = 0
        self._lost_seen = 0  # samples lost (gaps in a per-step stream's stamps) already reported
        self.exit_code = 0
        self.exit_reason = ""
        # wall-clock timers: with use_sim_time the ROS clock stands still while the plant is idle
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(float(p.discovery_period), self._discover, clock=wall)
        self.create_timer(1.0, self._publish_status, clock=wall)
        self.create_service(Trigger, "~/stop", self._on_stop, qos_profile=SERVICE_QOS)
        # a lockstep sim plant that names this node in lockstep.readers waits for it: the stamps of the per-step
        # streams it records (IMU, joint states) say what it has taken; gaps in them are losses
        self.lockstep = LockstepReader(self)
        self._discover()
        self.get_logger().info(f"recording {self.wanted} to {self.bag.path}")

    def _wrap_file(self) -> Callable[[BinaryIO], BinaryIO] | None:
        """What wraps the MCAP file object: nothing here (tests inject failing files)."""
        return None

    @property
    def subscribed(self) -> list[str]:
        return sorted(self._subs)

    def _qos_for(self, topic: str) -> QoSProfile:
        infos = self.get_publishers_info_by_topic(topic)
        latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
        return QoSProfile(
            depth=STREAM_QOS.depth,  # deeper than a lockstep plant's lead over this reader
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _discover(self) -> None:
        if self.recording.failure is not None:
            self._on_failure()
            return
        if self._closed:
            return
        graph = dict(self.get_topic_names_and_types())
        for topic in self.wanted:
            if topic in self._subs or topic not in graph or not self.get_publishers_info_by_topic(topic):
                continue
            type_name = graph[topic][0]
            try:
                cls = message_class(type_name)
                self.recording.add_topic(topic, type_name)
            except (ImportError, AttributeError, KeyError) as err:
                self.get_logger().error(f"cannot record {topic} ({type_name}): {err}", throttle_duration_sec=10.0)
                continue
            # (bytes, message info): rclpy passes both to two-argument callbacks
            callback: Any = self._queuer(topic, type_name in HEADER_FIRST)
            if type_name in HEADER_FIRST:  # a hole in its stamps (a stream on a simulator's steps) is reported
                self.lockstep.gaps[topic] = Gaps(None)
            # raw, every queued message per wake-up (one executor turn per batch)
            self._subs[topic] = subscribe_draining(self, cls, topic, callback, self._qos_for(topic), info=True)
            self.get_logger().info(f"recording {topic} [{type_name}]")

    def _queuer(self, topic: str, stamped: bool) -> Callable[[bytes, dict], None]:
        """The subscription callback of ``topic``: queue the raw message with the receive time (the
        node's clock) and how long it waited in the middleware; ``stamped``: a per-step stream whose header
        stamp is acknowledged to a lockstep plant."""
        put, clock, took = self.recording.put, self.get_clock(), self.lockstep.took

        def queue(data: bytes, info: dict) -> None:
            received = info.get("received_timestamp", 0) if isinstance(info, dict) else 0
            lag = (time.time_ns() - received) * 1e-9 if received > 0 else 0.0  # both the system clock
            put(topic, clock.now().nanoseconds, data, lag)
            if stamped:
                took(topic, header_stamp(data))
        return queue

    def _unsubscribe(self) -> None:
        for sub in self._subs.values():
            self.destroy_subscription(sub)
        self._subs.clear()

    def _on_failure(self) -> None:
        """The writer stopped on a write failure: unsubscribe, report (once; the status repeats it)."""
        if self._failed_handled:
            return
        self._failed_handled = True
        self._unsubscribe()
        reason = f"recording stopped: {self.recording.failure}"
        self.exit_code, self.exit_reason = 1, reason
        self.diagnostics.report("write_failed", ERROR, reason, values=self._values())

    def _values(self) -> list[tuple[str, str]]:
        rec = self.recording
        out = [("output", str(self.bag.path)), ("queued_messages", str(rec.queued_messages)),
               ("queued_bytes", str(rec.queued_bytes)), ("flushes", str(rec.flushes)),
               ("receive_lag_s", f"{rec.lag:.3f}")]
        for topic in sorted(rec.received):
            out += [(f"received:{topic}", str(rec.received[topic])), (f"written:{topic}", str(rec.written[topic])),
                    (f"flushed:{topic}", str(rec.flushed.get(topic, 0))), (f"dropped:{topic}", str(rec.dropped[topic]))]
        return out

    def _publish_status(self) -> None:
        """Every second on /diagnostics: recording (OK), dropping (WARN) or stopped (ERROR)."""
        rec = self.recording
        if rec.failure is not None:
            self._on_failure()
            self.diagnostics.publish("recording", ERROR, self.exit_reason, self._values())
            return
        if self._closed:
            return
        dropped = sum(rec.dropped.values())
        if dropped > self._dropped_seen:
            self.diagnostics.report(
                "queue_full", WARN, f"dropped {dropped - self._dropped_seen} message(s): the write queue is full"
                f" ({rec.queued_messages} messages, {rec.queued_bytes / 1e6:.1f} MB); the disk is too slow",
                values=self._values())
            self._dropped_seen = dropped
        lost = self._report_lost()
        level, message = (WARN, f"recording; {dropped} message(s) dropped (queue full)") if dropped else \
            (OK, "recording")
        if lost:
            level, message = WARN, f"{message}; {lost}"
        self.diagnostics.publish("recording", level, message, self._values())

    def _report_lost(self) -> str:
        """The samples lost so far ('' if none): gaps in the stamps of a per-step stream (IMU, joint states) on a
        simulator's steps, i.e. samples that never reached this recorder (paused past the DDS lease, out of the
        graph, or dropped by a lockstep plant that stepped on without it); a growth is a WARN on /diagnostics
        (session 13: a 25 s pause left a 3.7 s hole in the recording that nothing reported)."""
        text = self.lockstep.describe_lost()
        total = sum(self.lockstep.lost().values())
        if total > self._lost_seen:
            self._lost_seen = total
            self.diagnostics.report("samples_lost", WARN, f"{text} (gaps in the stamps): the recording has holes",
                                    values=self._values())
        return text

    def close(self) -> None:
        """Write what is queued and finish the bag (idempotent); after a write failure, only unsubscribe."""
        if self._closed:
            return
        self._closed = True
        self._unsubscribe()
        rec = self.recording
        lost = self.lockstep.lost()
        custom = {"shaper_nodes.recorder.dropped": ",".join(f"{t}={n}" for t, n in sorted(rec.dropped.items())),
                  "shaper_nodes.recorder.lost": ",".join(f"{t}={n}" for t, n in sorted(lost.items()))}
        if rec.close(custom_data=custom):
            counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.bag.counts.items()))
            if lost:
                self.get_logger().warning(f"closed {self.bag.path} ({counts}); {self.lockstep.describe_lost()}"
                                          " (gaps in the stamps): the recording has holes")
            else:
                self.get_logger().info(f"closed {self.bag.path} ({counts})")
            return
        # failed now or before: the log and the exit status say why (the graph may be gone at shutdown)
        self.exit_code, self.exit_reason = 1, f"recording stopped: {rec.failure}"
        if not self._failed_handled:
            self.get_logger().error(self.exit_reason)

    def _on_stop(self, req, resp):
        self.close()
        failure = self.recording.failure
        resp.success = failure is None
        resp.message = str(self.bag.path) if failure is None else f"recording stopped: {failure}"
        return resp


def main(args: list[str] | None = None) -> int:
    return run_node(RecorderNode, "recorder", args)


if __name__ == "__main__":
    raise SystemExit(main())
