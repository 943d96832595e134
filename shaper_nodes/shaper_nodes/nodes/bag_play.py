"""bag_play node: publish a recording's topics with their original timing, for machines without rosbag2.

Reads a rosbag2 folder or a bare .mcap file (a damaged MCAP too, up to where it is readable; see
:mod:`shaper_nodes.recordings`) and publishes each message's recorded CDR bytes unchanged
(rclpy's raw publishing, so nothing is lost in a conversion) at its recorded log time divided by
``rate``. Before playing, the first message of every topic is deserialised with the installed
message class: a topic whose type is not installed, or whose recorded layout does not match the
installed one, is skipped with an error naming it. Topics of type shaper_msgs/Shaper, /tf_static
and those in ``latched_topics`` are published RELIABLE + TRANSIENT_LOCAL (depth 1), as the nodes
that own them do; the others RELIABLE + VOLATILE, which best-effort subscribers accept too.
Topic names can be remapped as usual (``--ros-args -r /tip_imu:=/other``).

To replay into a running learner, ``await_reports`` names the learner's report topic
(shaper_msgs/CycleReport): once a cycle END is played, the next cycle event or active shaper
(shaper_msgs/Shaper) waits until the learner has reported as many cycles as ENDs were played (it
reports each one after its update was answered), so that the active shaper its update produced
(logged at the END's time in a lockstep recording) and the next START never reach the learner while
it is still handling the END. Other topics play on meanwhile: the samples the learner waits for at
an END may be logged just after it. Whatever the setting, an active shaper logged at the same time as
a later END is played just after that END (:func:`shaper_nodes.recordings.shaper_after_end`).

When the recording is done (or on ``~/stop``) the node logs what it published and exits,
unless ``loop`` is set.

``ros2 run shaper_nodes bag_play --ros-args -p bag:=my_bag -p rate:=2.0 -p topics:="[/tip_imu]"``
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_nodes.recordings import Bag, BagError, describe_damage, shaper_after_end
from shaper_nodes.recordings.cdr import empty_sequence_appended
from shaper_nodes.ros.conversions import ns_to_time
from shaper_nodes.ros.message_types import message_class
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import Spec, declare, param, table
from shaper_nodes.ros.qos import SERVICE_QOS

LATCHED_TYPES = ("shaper_msgs/msg/Shaper",)
LATCHED_NAMES = ("/tf_static",)
#: types whose older recorded layouts are played converted to the installed one (CycleEvent before start_stamp)
OLDER_LAYOUTS: dict[str, Callable[[bytes], bytes]] = {"shaper_msgs/msg/CycleEvent": empty_sequence_appended}


@dataclass(frozen=True)
class BagPlayParams:
    """The bag_play node's parameters."""

    bag: str = param("", "rosbag2 folder or .mcap file to play.", read_only=True)
    rate: float = param(1.0, "Playback speed factor (2 = twice as fast).", (1e-3, 1e3), read_only=True)
    topics: tuple[str, ...] = param([""], "Topics to play (empty: all).", read_only=True)
    latched_topics: tuple[str, ...] = param(
        [""], "Further topics to publish TRANSIENT_LOCAL (depth 1).", read_only=True)
    min_interval: float = param(0.0, "Least wall time between two published messages, s: spreads messages that were"
         " logged at the same time (a lockstep simulation's clock stands still while it waits), so that they arrive"
         " in order.", (0.0, 1.0), read_only=True)
    pause_after_topics: tuple[str, ...] = param(
        [""], "After a message on one of these topics, pause for pause_after before the"
        " next message.", read_only=True)
    pause_after: float = param(0.0, "Pause after a message on pause_after_topics, s of wall time: gives the nodes that"
         " act on it (a learner at a cycle's END) time to finish before the recording's later messages arrive,"
         " which in a lockstep recording may follow at once.", (0.0, 60.0), read_only=True)
    await_reports: str = param("", "A learner's report topic (shaper_msgs/CycleReport): once a cycle END is played, the"
         " next cycle event or shaper_msgs/Shaper message waits until as many reports have arrived as ENDs were"
         " played (at most await_timeout); other topics play on. Empty: do not wait.", read_only=True)
    await_timeout: float = param(30.0, "Longest wait for a report, s; then play on with a warning.",
                                 (0.1, 600.0), read_only=True)
    wait_for_subscribers: int = param(0, "Before playing, wait until every played topic has this many subscribers (0:"
                                      " do not wait).", (0, 100), read_only=True)
    start_timeout: float = param(30.0, "Longest wait for the subscribers, s; then play anyway.", (0.0, 600.0),
                                 read_only=True)
    start_delay: float = param(0.0, "Wait this long before the first message, s (lets discovery settle).", (0.0, 60.0),
                               read_only=True)
    publish_clock: bool = param(False, "Also publish /clock with the messages' log times.", read_only=True)
    loop: bool = param(False, "Start again at the end.", read_only=True)


#: the bag_play node's parameters (derived from BagPlayParams)
PARAMETERS: tuple[Spec, ...] = table(BagPlayParams)


def _cdr(raw: object) -> bytes:
    """The recorded CDR bytes of one message, as :meth:`Bag.messages` yields it (bytes, or another buffer).

    Raises
    ------
    TypeError
        ``raw`` is not a buffer (worded as ``bytes(raw)`` words it).
    """
    if isinstance(raw, bytes | bytearray | memoryview):
        return bytes(raw)
    raise TypeError(f"cannot convert '{type(raw).__name__}' object to bytes")


class BagPlayNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("bag_play", *args, **kwargs)
        self.params = declare(self, BagPlayParams)
        p = self.params.value
        path = str(p.bag)
        if not path:
            raise ValueError("parameter 'bag' is required: a rosbag2 folder or .mcap file")
        try:
            self.bag = Bag(path)
        except BagError as err:
            raise ValueError(str(err)) from None
        for note in self.bag.notes:
            self.get_logger().warning(note)
        for dmg in self.bag.damage:
            self.get_logger().warning(f"damaged recording: {describe_damage(dmg)}; playing what is readable")
        self.rate = float(p.rate)
        self.min_interval = float(p.min_interval)
        self.pause_topics = {t for t in p.pause_after_topics if t}
        self.pause = float(p.pause_after)
        infos = self.bag.topics
        self._older: dict[str, Callable[[bytes], bytes]] = {}  # topic -> its bytes in the installed layout
        wanted = [t for t in p.topics if t]
        missing = [t for t in wanted if t not in infos]
        if missing:
            self.get_logger().error(f"not in the recording, not played: {missing} (it has {sorted(infos)})")
        selected = [t for t in (wanted or sorted(infos)) if t in infos]
        latched = set(LATCHED_NAMES) | {t for t in p.latched_topics if t}
        self._pubs: dict[str, Publisher] = {}
        for topic in selected:
            msgtype = infos[topic].msgtype
            why = self._check(topic, msgtype)
            if why and msgtype in OLDER_LAYOUTS and not self._check(topic, msgtype, OLDER_LAYOUTS[msgtype]):
                self._older[topic] = OLDER_LAYOUTS[msgtype]
                self.get_logger().info(f"{topic} [{msgtype}] recorded with an older definition: played with the"
                                       " fields added since empty")
                why = ""
            if why:
                self.get_logger().error(f"{topic} [{msgtype}] not played: {why}")
                continue
            keep = msgtype in LATCHED_TYPES or topic in latched
            qos = QoSProfile(depth=1 if keep else 1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if keep else DurabilityPolicy.VOLATILE)
            self._pubs[topic] = self.create_publisher(message_class(msgtype), topic, qos)
        if not self._pubs:
            raise ValueError(f"{path}: nothing to play (topics asked for: {wanted or 'all'}; in the recording:"
                             f" {sorted(infos)})")
        self._clock_pub = self.create_publisher(Clock, "/clock", 10) if p.publish_clock else None
        self._event_topics = {t for t in self._pubs if infos[t].msgtype == "shaper_msgs/msg/CycleEvent"}
        self._shaper_topics = {t for t in self._pubs if infos[t].msgtype == "shaper_msgs/msg/Shaper"}
        self._gated = self._event_topics | self._shaper_topics  # what waits for the reports (await_reports)
        self._reports = threading.Condition()
        self._reported = 0  # reports received on await_reports
        self._ends = 0  # cycle ENDs played (this pass)
        self._await_timeout = float(p.await_timeout)
        self._await = str(p.await_reports)
        if self._await:
            self.create_subscription(CycleReport, self._await, self._on_report, 100)
        self.published: dict[str, int] = {t: 0 for t in self._pubs}
        self.finished = threading.Event()
        self._stop = threading.Event()
        self.create_service(Trigger, "~/stop", self._on_stop, qos_profile=SERVICE_QOS)
        self._thread = threading.Thread(target=self._run, name="bag-play", daemon=True)
        self._thread.start()
        self.get_logger().info(f"playing {sorted(self._pubs)} from {path} at {self.rate:g}x ({self.bag.reader_name})")

    def _data(self, topic: str, raw: object) -> bytes:
        """A recorded message's bytes as published (in the installed layout)."""
        older = self._older.get(topic)
        return _cdr(raw) if older is None else older(_cdr(raw))

    def _check(self, topic: str, msgtype: str, convert: Callable[[bytes], bytes] = bytes) -> str:
        """Why ``topic`` cannot be played ("" if it can): type not installed, or layout mismatch (after
        ``convert``)."""
        from rclpy.serialization import deserialize_message

        try:
            cls = message_class(msgtype)
        except (ImportError, AttributeError, ValueError) as err:
            return f"message type not installed here ({err})"
        for _, _, _, raw in self.bag.messages([topic]):
            try:
                deserialize_message(convert(_cdr(raw)), cls)
            except Exception as err:
                return f"the recorded messages do not match the installed {msgtype} ({err})"
            break
        return ""

    # ----------------------------------------------------------------- playing
    def _wait_subscribers(self) -> None:
        need = int(self.params.value.wait_for_subscribers)
        deadline = time.monotonic() + float(self.params.value.start_timeout)
        while need and not self._stop.is_set():
            short = [t for t, pub in self._pubs.items() if pub.get_subscription_count() < need]
            if not short:
                break
            if time.monotonic() > deadline:
                self.get_logger().warning(f"fewer than {need} subscribers on {short}; playing anyway")
                break
            time.sleep(0.05)
        end = time.monotonic() + float(self.params.value.start_delay)
        while time.monotonic() < end and not self._stop.is_set():
            time.sleep(0.02)

    def _on_report(self, _msg: CycleReport) -> None:
        with self._reports:
            self._reported += 1
            self._reports.notify_all()

    def _is_end(self, topic: str, raw: object) -> bool:
        from rclpy.serialization import deserialize_message

        return bool(deserialize_message(self._data(topic, raw), CycleEvent).event == CycleEvent.END)

    def _await_reports(self) -> float:
        """Before a cycle event or an active shaper: wait for the report of every END played so far (at most
        ``await_timeout``). Returns the wall time waited, s."""
        if self._reported >= self._ends:  # (read without the lock: it only grows within a pass)
            return 0.0
        began = time.monotonic()
        deadline = began + self._await_timeout
        with self._reports:
            while self._reported < self._ends and not self._stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    self.get_logger().warning(f"no report on {self._await} for END {self._ends} within"
                                              f" {self._await_timeout:g} s; playing on")
                    self._reported = self._ends  # the next END waits for its own report
                    break
                self._reports.wait(min(left, 0.05))
        return time.monotonic() - began

    def _run(self) -> None:
        try:
            self._wait_subscribers()
            while not self._stop.is_set():
                self._play_once()
                if not self.params.value.loop:
                    break
        except Exception as err:
            self.get_logger().error(f"playback failed: {err}")
        finally:
            self.finished.set()
            counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.published.items()))
            self.get_logger().info(f"done ({counts})")
            if not self._stop.is_set():
                self.context.try_shutdown()  # the spin in main returns: the process ends

    def _play_once(self) -> None:
        first_ns, wall0, last = None, 0.0, -1e9
        with self._reports:  # a pass counts its own ENDs and the reports that come with them
            self._reported = self._ends = 0
        ordered = shaper_after_end(self.bag.messages(list(self._pubs)), lambda m: m[2],
                                   lambda m: m[0] in self._shaper_topics,
                                   lambda m: m[0] in self._event_topics and self._is_end(m[0], m[3]))
        for topic, _, log_ns, raw in ordered:
            if first_ns is None:
                first_ns, wall0 = log_ns, time.monotonic()
            due = max(wall0 + (log_ns - first_ns) * 1e-9 / self.rate, last + self.min_interval)
            while not self._stop.is_set():
                left = due - time.monotonic()
                if left <= 0:
                    break
                time.sleep(min(left, 0.05))
            if self._stop.is_set():
                return
            if self._await and topic in self._gated:
                waited = self._await_reports()
                wall0 += waited  # the rest of the recording keeps its spacing, later
                last += waited
            if self._clock_pub is not None:
                self._clock_pub.publish(Clock(clock=ns_to_time(log_ns)))
            self._pubs[topic].publish(self._data(topic, raw))
            self.published[topic] += 1
            last = time.monotonic()
            if topic in self.pause_topics and self.pause > 0.0:
                wall0 += self.pause  # the rest of the recording keeps its spacing, later
                last += self.pause
            if self._await and topic in self._event_topics and self._is_end(topic, raw):
                self._ends += 1

    def _on_stop(self, req, resp):
        self._stop.set()
        resp.success, resp.message = True, "stopped"
        return resp

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.bag.close()



def main(args: list[str] | None = None) -> int:
    return run_node(BagPlayNode, "bag_play", args, examples=(
        "ros2 run shaper_nodes bag_play --ros-args -p bag:=recording -p rate:=2.0",))


if __name__ == "__main__":
    raise SystemExit(main())
