"""A lockstep reader's side on the wire: its acknowledgements to the sim plant, and its lost samples.

A node that the sim plant waits for (named in the plant's ``lockstep.readers``) makes one
:class:`LockstepReader` and calls :meth:`LockstepReader.took` with the stamp of every sample it takes on
its per-step streams (joint states, tip state, reference, IMU). It publishes on ``<node>/lockstep_ack``
(rosgraph_msgs/Clock, reliable, transient local, depth 1) the simulated time it has processed, the
oldest of its streams' latest stamps, every :data:`~shaper_nodes.core.lockstep.ACK_PERIOD` s of simulated
time, and every :data:`FLUSH_PERIOD` s of wall time the time processed if it went further (the last samples
before the plant rests: a client that waits for this reader to have taken a run's end sees it); at
construction it announces itself (``clock.sec`` -1: nothing taken yet). It also counts each
stream's lost samples from gaps in the stamps (:class:`~shaper_nodes.core.lockstep.Gaps`), for the
reader to report beside the numbers they touch. The rules are :mod:`shaper_nodes.core.lockstep`'s.

The QoS a reader's per-step streams need: :data:`STREAM_QOS` (reliable, deep enough for the plant's lead).

:func:`subscribe_draining` subscribes a reader to a per-step stream raw and hands its callback every message
queued, in order, on a wall-clock poll (:data:`POLL_PERIOD`; the subscription is out of the executor's wait set,
:class:`OutOfWaitSet`): rclpy's executor otherwise builds a wait set for every message, the most of what a Python
reader pays per message, and a reader that keeps up with a lockstep plant would pay it for every one.
"""

from __future__ import annotations

import contextlib
import functools
import math
import struct
import weakref
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from ..core.lockstep import ACK_PERIOD, ANNOUNCE, Acks, Gaps
from .conversions import sec_to_time
from .qos import LATCHED

__all__ = ["ACK_QOS", "ACK_SUFFIX", "BATCH", "FLUSH_PERIOD", "HEADER_FIRST", "IMU_RELIABLE_DOC", "POLL_PERIOD",
           "STREAM_QOS", "AckWatch", "LockstepReader", "OutOfWaitSet", "ack_topic", "header_stamp",
           "subscribe_draining", "subscribes", "take_all"]

#: the acknowledgement topic is the reader node's fully qualified name plus this
ACK_SUFFIX = "/lockstep_ack"
#: the acknowledgements: the latest one is what counts (a late-joining plant gets it)
ACK_QOS = LATCHED
#: a reader's per-step streams in lockstep: reliable, 10000 samples (10 s of a 1 kHz IMU; the plant's lead,
#: ``lockstep.lead``, is well inside it)
STREAM_QOS = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

#: what a node's ``topics.imu_reliable`` parameter means (the identifier's and the learner's)
IMU_RELIABLE_DOC = ("Subscribe to the accelerometer RELIABLE (lossless from a reliable publisher such as the simulator"
                    " in lockstep, which then waits for this node when it is in lockstep.readers; a best-effort sensor"
                    " driver does not match it). Default best effort, deep queue.")

#: wall s between two checks for samples taken since the last acknowledgement (a wall-clock timer: the simulated
#: clock stands still while the plant rests)
FLUSH_PERIOD = 0.1

#: s under the next acknowledgement's time below which a sample is known not to complete it (LockstepReader.took; wider
#: than Acks' own slack, so Acks decides every sample near the boundary)
_QUIET_SLACK = 1e-6

#: the per-step stream types whose serialized message begins with a std_msgs/Header (:func:`header_stamp`)
HEADER_FIRST = frozenset({"sensor_msgs/msg/Imu", "sensor_msgs/msg/JointState"})


#: the most messages one wake-up of a draining subscription hands its callback (the rest wait for the executor's
#: next turn, so a stream that never runs dry cannot starve the node's other callbacks); the plant's lead,
#: ``lockstep.lead`` (0.25 s: 250 samples of a 1 kHz stream), fits in one batch
BATCH = 1000
#: wall s between two drains of a polled draining subscription (:func:`subscribe_draining`): 200 wake-ups a second
#: for all of a node's polled streams; the plant's lead, 0.25 simulated s, is 12 ms of wall time even at 20x
POLL_PERIOD = 0.005


class OutOfWaitSet(CallbackGroup):
    """A callback group whose entities the executor never waits on (rclpy's executors leave an entity out of the
    wait set while its group's ``can_execute`` is false): their data is taken by the node itself, on a timer
    (:func:`subscribe_draining` with ``poll``) or when it needs it (the sim plant's reader acknowledgements). With
    ``waited`` true the entities are waited on as any other (the plant held by a reader wakes on its next
    acknowledgement)."""

    def __init__(self, waited: bool = False) -> None:
        super().__init__()
        self.waited = waited

    def can_execute(self, entity: Any) -> bool:
        return self.waited

    def beginning_execution(self, entity: Any) -> bool:
        return self.waited

    def ending_execution(self, entity: Any) -> None:
        pass


class _Poller:
    """A node's polled draining subscriptions, drained in turn on one wall-clock timer of ``period`` s."""

    def __init__(self, node: Any, period: float) -> None:
        self.period = period
        self.drains: list[Callable[[], bool]] = []
        self._timer = node.create_timer(period, self.poll, clock=RosClock(clock_type=ClockType.STEADY_TIME))

    def poll(self) -> None:
        self.drains = [drain for drain in self.drains if drain()]


#: per node, its poller (one timer for all its polled subscriptions)
_POLLERS: weakref.WeakKeyDictionary[Any, _Poller] = weakref.WeakKeyDictionary()


def take_all(sub: Any, msg_type: Any, on_message: Callable[[Any], None], limit: int) -> bool:
    """Take up to ``limit`` messages queued on subscription ``sub`` (raw, with their info), handing each to
    ``on_message`` (a ``(bytes, info)`` pair) in order. Returns False once the subscription is destroyed (also by
    ``on_message``), else True."""
    handle = sub.handle
    for _ in range(limit):
        try:
            with handle:
                got = handle.take_message(msg_type, True)
        except InvalidHandle:  # destroyed (by the callback, or the node)
            return False
        if got is None:
            return True
        on_message(got)
    return True


def subscribe_draining(node: Any, msg_type: Any, topic: str, callback: Callable[..., None], qos: Any, *,
                       info: bool = False, batch: int = BATCH, poll: float = POLL_PERIOD, **kwargs: Any) -> Any:
    """Subscribe ``node`` to ``topic`` raw and hand ``callback`` every message queued, a batch at a time.

    Parameters
    ----------
    node : rclpy Node
        The reader.
    msg_type : message class
        The topic's type (the bytes are not converted to it).
    topic : str
        The topic.
    callback : callable
        Called with each message's serialized bytes (and its message info, a dict, with ``info``), in the
        order they arrived, one call per message.
    qos : QoSProfile or int
        The subscription's QoS.
    info : bool
        Pass the message info too (``received_timestamp``, ns, ...).
    batch : int
        At most this many messages per wake-up (:data:`BATCH`).
    poll : float
        Wall s between two drains of the queue (:data:`POLL_PERIOD`): the subscription is out of the executor's
        wait set (:class:`OutOfWaitSet`) and one steady-clock timer of the node takes every queued message of
        each of its polled subscriptions, so a stream wakes its reader ``1 / poll`` times a second whatever its
        rate. 0: the subscription wakes the executor as any other, and each wake-up also takes the rest of
        the queue.
    **kwargs
        Passed to ``create_subscription`` (``callback_group``, with ``poll`` 0 only, ...).

    Returns
    -------
    rclpy Subscription
        The subscription (destroyed by the node as any other; a callback may destroy it: the batch stops).

    Notes
    -----
    rclpy's executor takes one message per wake-up and rebuilds its wait set before the next (about 100-170 us
    of a Python reader's CPU per message, docs/results/benchmarks.md); a drain takes the queue itself
    (``take_message`` on the subscription's handle until it returns None, a few us a message). A reader that
    keeps up with a lockstep plant finds one or two messages at each wake-up, so only polling makes it pay the
    executor once per batch; its acknowledgements still follow the samples they cover (a poll adds at most
    ``poll`` s of wall time to them, well inside the plant's ``lockstep.lead`` at its rates). A node's polled
    subscriptions share one timer; the first one made sets its period.
    """
    if batch < 1:
        raise ValueError(f"subscribe_draining: batch must be at least 1, got {batch}")
    if not (math.isfinite(poll) and 0 <= poll <= 1.0):
        raise ValueError(f"subscribe_draining: poll must be in [0, 1] s, got {poll!r}")
    if poll > 0 and "callback_group" in kwargs:
        raise ValueError("subscribe_draining: a polled subscription has a callback group of its own (poll=0 to"
                         " give one)")
    subs: list[Any] = []
    if info:
        def hand(got: Any) -> None:
            callback(got[0], got[1])
    else:
        def hand(got: Any) -> None:
            callback(got[0])

    if poll > 0:
        sub = node.create_subscription(msg_type, topic, callback, qos, raw=True, callback_group=OutOfWaitSet(),
                                       **kwargs)
        poller = _POLLERS.get(node)
        if poller is None:
            poller = _POLLERS[node] = _Poller(node, poll)
        poller.drains.append(functools.partial(take_all, sub, msg_type, hand, batch))
        return sub

    def drain() -> None:
        take_all(subs[0], msg_type, hand, batch - 1)

    if info:
        def on_message_info(raw: bytes, message_info: Any) -> None:
            callback(raw, message_info)
            drain()
        subs.append(node.create_subscription(msg_type, topic, on_message_info, qos, raw=True, **kwargs))
    else:
        def on_message(raw: bytes) -> None:
            callback(raw)
            drain()
        subs.append(node.create_subscription(msg_type, topic, on_message, qos, raw=True, **kwargs))
    return subs[0]


def header_stamp(raw: bytes) -> float:
    """The header stamp, s, of a serialized (CDR) message that begins with a std_msgs/Header."""
    sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)
    return sec + nanosec * 1e-9


def ack_topic(reader: str) -> str:
    """The acknowledgement topic of reader node ``reader`` (its fully qualified name, e.g. ``/recorder``)."""
    return "/" + reader.strip("/") + ACK_SUFFIX


class LockstepReader:
    """Acknowledge the simulated time a node processed; count its streams' lost samples.

    Parameters
    ----------
    node : rclpy Node
        The reader.
    periods : mapping of str to float or None, optional
        Per stream the sample period, s, for loss detection (None: learned, the smallest spacing seen);
        a stream not listed is acknowledged but not checked for gaps.
    period : float
        Simulated s between two acknowledgements.
    ready : callable, optional
        When given, the reader announces itself only once ``ready()`` is true (checked on the wall-clock
        timer), e.g. once its subscriptions have matched the plant's publishers: a plant that names it waits
        for it from then on, and a client that waits for the announcement then knows samples will reach it.
    """

    def __init__(self, node: Any, periods: Mapping[str, float | None] | None = None,
                 period: float = ACK_PERIOD, ready: Callable[[], bool] | None = None) -> None:
        self._acks = Acks(period)
        self.gaps: dict[str, Gaps] = {name: Gaps(p) for name, p in (periods or {}).items()}
        self._pub = node.create_publisher(Clock, ack_topic(node.get_fully_qualified_name()), ACK_QOS)
        self._ready = ready
        self.announced = ready is None
        if self.announced:
            self._send(ANNOUNCE)
        self._timer = node.create_timer(FLUSH_PERIOD, self._flush, clock=RosClock(clock_type=ClockType.STEADY_TIME))

    def _flush(self) -> None:
        if not self.announced:
            if self._ready is None or not self._ready():
                return
            self.announced = True
            self._send(ANNOUNCE)
        ack = self._acks.flush()
        if ack is not None:
            self._send(ack)

    def _send(self, t: float) -> None:
        msg = Clock()
        if t < 0:
            msg.clock.sec, msg.clock.nanosec = -1, 0
        else:
            msg.clock = sec_to_time(t)
        self._pub.publish(msg)

    def took(self, stream: str, t: float) -> None:
        """A sample of ``stream`` stamped ``t`` (simulated s) was taken."""
        gaps = self.gaps.get(stream)
        if gaps is not None:
            gaps.add(t)
        self.announced = True  # (samples come: the announcement is past)
        acks = self._acks
        sent, latest = acks.sent, acks.latest
        if sent is not None and latest.get(stream, -math.inf) < t < sent + acks.period - _QUIET_SLACK:
            # a sample that advances its stream short of the next acknowledgement: none can come of it (the time
            # processed, the oldest of the streams' latest stamps, is at most this one), so it is kept as Acks.took
            # keeps it, without that call's look at every stream (took 0.44 -> 0.36 us a sample, benchmarks.md)
            latest[stream] = t
            return
        ack = acks.took(stream, t)
        if ack is not None:
            self._send(ack)

    @property
    def processed(self) -> float | None:
        """The simulated time processed on every stream, s (None before any sample)."""
        return self._acks.processed

    @property
    def heard(self) -> bool:
        """Whether a subscriber (a lockstep plant) has matched this reader's acknowledgements: its announcement,
        kept by the topic's durability, then reaches it (a plant holds only for a reader it has heard)."""
        return bool(self._pub.get_subscription_count() > 0)

    def lost(self, t0: float = float("-inf"), t1: float = float("inf")) -> dict[str, int]:
        """Per checked stream, the samples lost with stamps in (t0, t1] s (streams with none left out)."""
        out = {name: g.lost(t0, t1) for name, g in self.gaps.items()}
        return {name: n for name, n in out.items() if n}

    def describe_lost(self, t0: float = float("-inf"), t1: float = float("inf")) -> str:
        """The samples lost in (t0, t1] as one phrase ('' if none): ``"lost 12 samples of /tip_imu, ..."``."""
        lost = self.lost(t0, t1)
        return ("lost " + ", ".join(f"{n} sample{'s' if n != 1 else ''} of {name}" for name, n in lost.items())
                if lost else "")


def subscribes(node: Any, reader: str, topic: str) -> bool:
    """Whether node ``reader`` (its name, e.g. ``/recorder``) subscribes to ``topic``, as ``node`` sees the graph
    (a recorder subscribes to a topic once it sees it: a lockstep plant would run the first samples past it)."""
    name = reader.strip("/").rsplit("/", 1)[-1]
    return any(i.node_name == name for i in node.get_subscriptions_info_by_topic(topic))


class AckWatch:
    """What a lockstep reader has processed, from its acknowledgements, as another node sees them: for a client
    that must not stop the reader (a recorder) before it has taken every sample up to a time.

    The acknowledgements (the latest one is kept: :data:`ACK_QOS`) are out of the executor's wait set but while
    :meth:`wait_subscribed` or :meth:`wait_processed` spins: reading :attr:`processed` or :attr:`announced` takes
    the one queued. A watch through a run (a driver that sends goals meanwhile) then costs its node no wake-up per
    acknowledgement (50 per simulated s of a reader, each a callback of rclpy's executor, on the cores the plant
    and its readers share).

    Parameters
    ----------
    node : rclpy Node
        The watching node (its executor must spin while a ``wait_*`` method waits).
    reader : str
        The reader's node name, e.g. ``/recorder``.
    """

    def __init__(self, node: Any, reader: str) -> None:
        self.reader = reader
        self._processed = -math.inf
        self._announced = False
        self._node = node
        self._group = OutOfWaitSet()  # (waited on only while a wait_* method spins)
        self._sub = node.create_subscription(Clock, ack_topic(reader), self._on_ack, ACK_QOS, raw=True,
                                             callback_group=self._group)

    def _on_ack(self, raw: bytes) -> None:
        sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)  # rosgraph_msgs/Clock
        self._announced = True
        if sec >= 0:  # not the announcement
            self._processed = max(self._processed, sec + 1e-9 * nanosec)

    def _take(self) -> None:
        take_all(self._sub, Clock, lambda got: self._on_ack(got[0]), 100)

    @property
    def processed(self) -> float:
        """The simulated time the reader has taken every sample up to, s (-inf before its first sample)."""
        self._take()
        return self._processed

    @property
    def announced(self) -> bool:
        """Whether the reader has announced itself (then a lockstep plant that names it waits for it)."""
        self._take()
        return self._announced

    @contextlib.contextmanager
    def _waited(self) -> Iterator[None]:
        """The acknowledgements wake the node's executor meanwhile."""
        self._group.waited = True
        try:
            yield
        finally:
            self._group.waited = False

    def wait_subscribed(self, spin_until: Callable[[Callable[[], bool], float, str], None], topics: Iterable[str],
                        timeout: float) -> None:
        """Spin (``spin_until(done, timeout, what)``, which raises TimeoutError naming ``what``) until the reader
        subscribes to every one of ``topics`` and has announced itself."""
        for topic in topics:
            spin_until(functools.partial(subscribes, self._node, self.reader, topic), timeout,
                       f"{self.reader}'s subscription of {topic}")
        with self._waited():
            spin_until(lambda: self.announced, timeout,
                       f"{self.reader}'s lockstep announcement on {ack_topic(self.reader)}")

    def wait_processed(self, spin_until: Callable[[Callable[[], bool], float, str], None], end: float,
                       timeout: float) -> None:
        """Spin until the reader has taken every sample up to simulated time ``end`` s; on a time-out one
        TimeoutError line says how far it got."""
        try:
            with self._waited():
                spin_until(lambda: self.processed >= end - 1e-6, timeout, "")
        except TimeoutError:
            raise TimeoutError(f"{self.reader} did not take the samples up to t = {end:.3f} s within {timeout:g} s;"
                               f" it has them up to t = {self.processed:.3f} s") from None
