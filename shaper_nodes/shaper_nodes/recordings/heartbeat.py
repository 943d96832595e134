"""A recorder's heartbeat, and how much a recording that was not closed lost.

The suite's recorder flushes its recording to the operating system every ``flush_period`` s
(MCAP chunks closed by time as well as by size). Right before each flush it writes a
*heartbeat* into the recording itself, as the last message of the chunk it closes: a
``diagnostic_msgs/DiagnosticStatus`` on ``<recorder node>/heartbeat`` whose key values give, per
topic, the messages received and written so far, those dropped (queue full), the receive rate
over the last period, and the flush period. Its log time is the recorder's receive clock (the
same clock as the messages' log times).

A recording that was not closed (the recorder killed, the machine off) ends with complete chunks
up to the last flush, and maybe part of the next one. Its last heartbeat says that the recorder
was alive at its stamp and that everything received until then is in the file (apart from the
few messages ``queued`` at that instant); the next flush was due ``flush_period`` s later and did
not complete, so the recorder stopped before then. :func:`loss_bound` turns that into an upper
bound: at most one flush interval (as measured at the last heartbeat, plus the time the last flush
took, plus the time the cut chunk covers, plus the receive lag the recorder measured) of data, and
at most the messages received at the measured rates in that time. The bound assumes the writer
kept the pace it had at its last heartbeat; a writer starved of CPU after it flushes later and can
lose more.

Nothing here imports rclpy or message types.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

#: the heartbeat's message type and status name; its topic is ``<recorder node>/heartbeat``
HEARTBEAT_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"
HEARTBEAT_NAME = "recorder heartbeat"
HEARTBEAT_SUFFIX = "/heartbeat"
#: key prefixes of the per-topic values (``received:/tip_imu``)
_PER_TOPIC = ("received", "written", "dropped", "rate_hz")


def is_heartbeat_topic(topic: str, msgtype: str) -> bool:
    """Whether a topic of a recording is a recorder's heartbeat."""
    return msgtype == HEARTBEAT_TYPE and topic.endswith(HEARTBEAT_SUFFIX)


@dataclass(frozen=True)
class Heartbeat:
    """What the recorder knew when it flushed (see the module docstring).

    Attributes
    ----------
    stamp_ns : int
        Log time of the heartbeat, ns (the recorder's receive clock).
    flush_period : float
        Time between two flushes, s.
    received, written, dropped : dict of str to int
        Per topic: messages received, written to the file (this chunk included) and dropped
        because the queue was full, since the recording started.
    rates : dict of str to float
        Per topic: messages received per second over the last period, Hz.
    interval : float
        Time since the previous flush, s (the period as kept; longer when the writer is late).
    flush_time : float
        How long the previous flush took (chunk closed, written, flushed, fsync), s.
    lag : float
        Largest receive lag over the last period, s: from the middleware's receiving a message to
        the recorder's queuing it (messages waiting in the recorder's process, unseen).
    """

    stamp_ns: int
    flush_period: float
    received: dict[str, int] = field(default_factory=dict)
    written: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    rates: dict[str, float] = field(default_factory=dict)
    interval: float = 0.0
    flush_time: float = 0.0
    lag: float = 0.0

    @property
    def queued(self) -> dict[str, int]:
        """Per topic: received but not yet written at the heartbeat (lost if no later flush)."""
        return {t: max(0, n - self.written.get(t, 0) - self.dropped.get(t, 0)) for t, n in self.received.items()}

    def to_values(self) -> list[tuple[str, str]]:
        """The key values of the heartbeat's DiagnosticStatus."""
        out = [("flush_period_s", f"{self.flush_period:.6g}"), ("interval_s", f"{self.interval:.6g}"),
               ("flush_time_s", f"{self.flush_time:.6g}"), ("lag_s", f"{self.lag:.6g}")]
        for topic in sorted(self.received):
            out += [(f"received:{topic}", str(self.received[topic])),
                    (f"written:{topic}", str(self.written.get(topic, 0))),
                    (f"dropped:{topic}", str(self.dropped.get(topic, 0))),
                    (f"rate_hz:{topic}", f"{self.rates.get(topic, 0.0):.6g}")]
        return out

    @classmethod
    def from_values(cls, stamp_ns: int, values: Iterable[tuple[str, str]]) -> Heartbeat:
        """A heartbeat from its DiagnosticStatus key values.

        Raises
        ------
        ValueError
            A value does not parse, or the flush period is missing.
        """
        period = None
        extra = {"interval_s": 0.0, "flush_time_s": 0.0, "lag_s": 0.0}
        per: dict[str, dict[str, Any]] = {k: {} for k in _PER_TOPIC}
        for key, value in values:
            if key == "flush_period_s":
                period = float(value)
            elif key in extra:
                extra[key] = max(0.0, float(value))
            kind, sep, topic = key.partition(":")
            if sep and kind in per:
                per[kind][topic] = float(value) if kind == "rate_hz" else int(value)
        if period is None or not math.isfinite(period) or period <= 0.0:
            raise ValueError("a recorder heartbeat without a valid flush_period_s")
        return cls(int(stamp_ns), period, per["received"], per["written"], per["dropped"], per["rate_hz"],
                   extra["interval_s"], extra["flush_time_s"], extra["lag_s"])


@dataclass(frozen=True)
class LossBound:
    """What a recording that was not closed lost after its last flush, at most.

    Attributes
    ----------
    alive_ns : int
        The recorder was alive at least until then, ns (the last heartbeat, or the end of the
        messages of a chunk it had started to write when it stopped).
    stopped_by_ns : int
        It stopped before then, ns, if the writer kept the pace it had at its last heartbeat (the
        next flush due one interval later, taking as long as the last one).
    seconds : float
        Length of the time whose messages may be lost, s: from the last heartbeat to
        ``stopped_by_ns``, plus the receive lag (messages received by the middleware but not yet
        seen by the recorder at the heartbeat).
    messages : dict of str to int
        Per topic: at most this many messages lost (queued at the heartbeat, plus those received
        at the larger of the recent and the mean rate during ``seconds``).
    dropped : dict of str to int
        Per topic: messages the recorder dropped (queue full) while it ran; lost too.
    """

    alive_ns: int
    stopped_by_ns: int
    seconds: float
    messages: dict[str, int]
    dropped: dict[str, int]

    @property
    def total(self) -> int:
        """All topics' messages lost at most after the last flush."""
        return sum(self.messages.values())


def loss_bound(last: Heartbeat, first_ns: int | None = None, cut_chunk_end_ns: int | None = None) -> LossBound:
    """The loss after the last heartbeat of a recording that was not closed.

    Parameters
    ----------
    last : Heartbeat
        The last complete heartbeat in the file.
    first_ns : int, optional
        Log time of the first message of the recording, ns (for the mean rates).
    cut_chunk_end_ns : int, optional
        Log time of the last message of a chunk that was cut (its header survived), ns: the
        recorder was alive then, and stopped before the flush after it.
    """
    alive = max(last.stamp_ns, cut_chunk_end_ns or 0)
    stopped_by = alive + int(round((max(last.flush_period, last.interval) + last.flush_time) * 1e9))
    seconds = (stopped_by - last.stamp_ns) * 1e-9 + last.lag
    span = (last.stamp_ns - first_ns) * 1e-9 if first_ns is not None and last.stamp_ns > first_ns else 0.0
    messages = {}
    for topic, n in last.received.items():
        rate = max(last.rates.get(topic, 0.0), n / span if span > 0.0 else 0.0)
        messages[topic] = last.queued.get(topic, 0) + math.ceil(rate * seconds - 1e-9)
    return LossBound(alive, stopped_by, seconds, messages, {t: n for t, n in last.dropped.items() if n})


def rates_between(before: Mapping[str, int], after: Mapping[str, int], seconds: float) -> dict[str, float]:
    """Per-topic rate from two counts ``seconds`` apart, Hz (0 when ``seconds`` is not positive)."""
    if seconds <= 0.0:
        return {t: 0.0 for t in after}
    return {t: (n - before.get(t, 0)) / seconds for t, n in after.items()}
