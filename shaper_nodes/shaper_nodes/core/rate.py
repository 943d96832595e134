"""How a streamed input arrives against its nominal rate: rate, gaps, bursts, drops and lag.

A streamed command (one sample per message at the command rate) is only shaped right if every
sample arrives: a lost sample is a step the filter never sees. :class:`RateWatch` keeps, per
input, the statistics of one reporting window from what the middleware says about each message:

``source`` (ns)
    when the publisher sent it (its clock): the *input rate* is measured on these stamps (the window's
    messages less one over the span from its first source stamp to its last), and a *gap* is an interval
    from one source stamp to the next present one, when forward in time, longer than ``gap_factor``
    command periods (the sender paused or messages were lost before us); the *largest gap* is the longest
    such forward interval.
``received`` (ns)
    when our middleware received it (our clock). A *burst* is an interval from one reception stamp to the
    next present one of at least zero and shorter than ``burst_factor`` periods: messages bunched on the
    way (network, sender).
``handled`` (ns)
    when the node took it (our clock): the *lag* ``handled - received`` is how long it waited in
    the subscription's queue, i.e. how far the node fell behind (the window's largest, over the messages
    with a reception stamp, and at least 0).
``sequence``
    the publisher's sequence number: a number more than one above the highest seen before it counts the
    numbers skipped as *drops* (a full queue, or loss in transport); a number at or below the highest (a
    repeat, a reorder, a restarted publisher) counts none. Sequence numbers are per publisher, so drops are counted
    only while one publisher is seen (``publishers == 1``); while several are, the highest is forgotten.

A stamp of 0 (or None), a sequence number of 0 or below (or None) is absent: the message counts in the
window's messages but in no interval of that field. The intervals and the highest sequence number run on
across windows; the counts are per window, with running totals of gaps and drops. :meth:`RateWatch.arrivals`
takes the messages in batches, as int64 arrays: the node keeps them as they come and passes them at each
summary (ros/stream_watch.py), so the statistics cost a few numpy calls per batch, not Python per message.

Nothing here reads a clock: the node passes the stamps in, so the statistics are the same in a
replay or a test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class RateWindow:
    """The statistics of one window (see the module docstring)."""

    messages: int
    rate_hz: float  # from the source stamps; nan with fewer than two messages
    gaps: int
    largest_gap_s: float  # largest interval between source stamps (0 with fewer than two)
    bursts: int
    drops: int
    drops_counted: bool  # False while several publishers were seen (no sequence check)
    largest_lag_s: float

    @property
    def trouble(self) -> bool:
        """Whether the window saw gaps or drops (a WARN)."""
        return self.gaps > 0 or self.drops > 0

    def values(self, prefix: str) -> list[tuple[str, str]]:
        """Key-value pairs for a diagnostics status."""
        return [(f"{prefix}.messages", str(self.messages)),
                (f"{prefix}.rate_hz", "n/a" if math.isnan(self.rate_hz) else f"{self.rate_hz:.1f}"),
                (f"{prefix}.gaps", str(self.gaps)),
                (f"{prefix}.largest_gap_ms", f"{1e3 * self.largest_gap_s:.2f}"),
                (f"{prefix}.bursts", str(self.bursts)),
                (f"{prefix}.drops", str(self.drops) if self.drops_counted else "n/a (several publishers)"),
                (f"{prefix}.largest_lag_ms", f"{1e3 * self.largest_lag_s:.2f}")]


class RateWatch:
    """The arrival statistics of one streamed input, window by window.

    Parameters
    ----------
    rate : float
        The nominal rate (the node's ``command_rate``), Hz.
    gap_factor : float
        An interval between source stamps longer than this many periods is a gap.
    burst_factor : float
        An interval between receptions shorter than this many periods is a burst.
    """

    def __init__(self, rate: float, gap_factor: float = 1.5, burst_factor: float = 0.25) -> None:
        if not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"rate must be finite and > 0 Hz, got {rate!r}")
        for name, factor in (("gap_factor", gap_factor), ("burst_factor", burst_factor)):
            if not (math.isfinite(factor) and factor > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {factor!r}")
        self.period_ns = 1e9 / rate
        self.gap_ns = gap_factor * self.period_ns
        self.burst_ns = burst_factor * self.period_ns
        # the thresholds as integers, so that integer intervals compare exactly: x > gap_ns is x >= _gap_from,
        # x < burst_ns is x < _burst_below
        self._gap_from = math.floor(self.gap_ns) + 1
        self._burst_below = math.ceil(self.burst_ns)
        self._last_source: int | None = None
        self._last_received: int | None = None
        self._last_seq: int | None = None
        self.total_drops = 0
        self.total_gaps = 0
        self._reset_window()

    def _reset_window(self) -> None:
        self._n = 0
        self._first_source: int | None = None
        self._end_source: int | None = None
        self._gaps = 0
        self._largest_gap = 0
        self._bursts = 0
        self._drops = 0
        self._several = False
        self._lag = 0

    def arrival(self, source: int | None, received: int | None, handled: int, sequence: int | None,
                publishers: int = 1) -> None:
        """One message: its stamps (ns; None or 0 where the middleware gives none) and sequence number (None
        or <= 0: none); :meth:`arrivals` of a batch of one."""
        self.arrivals(np.array([source or 0], np.int64), np.array([received or 0], np.int64),
                      np.array([handled], np.int64), np.array([sequence or 0], np.int64), publishers)

    def arrivals(self, source: npt.ArrayLike, received: npt.ArrayLike, handled: npt.ArrayLike,
                 sequence: npt.ArrayLike, publishers: int = 1) -> None:
        """A batch of messages in the order they were taken, as one array per field (int64, ns), the same as
        :meth:`arrival` on each in turn.

        Parameters
        ----------
        source, received : array_like of int
            The middleware's stamps, ns; 0 where it gives none (that message then counts in no interval).
        handled : array_like of int
            When the node took each message, ns (our clock).
        sequence : array_like of int
            The publisher's sequence numbers; 0 (or below) where there is none.
        publishers : int
            The number of publishers seen during the batch: drops are counted only while it is 1.
        """
        src = np.asarray(source, np.int64)
        if not len(src):
            return
        self._n += len(src)
        self._sources(src[src != 0])
        rec = np.asarray(received, np.int64)
        got = rec != 0
        self._receptions(rec[got], np.asarray(handled, np.int64)[got])
        if publishers != 1:
            self._several = True
            self._last_seq = None
        else:
            seq = np.asarray(sequence, np.int64)
            self._sequence(seq[seq > 0])

    @staticmethod
    def _steps(last: int | None, values: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """The differences between consecutive ``values``, the first from ``last`` (when there is one)."""
        if last is None:
            return values[1:] - values[:-1]
        before = np.empty_like(values)
        before[0] = last
        before[1:] = values[:-1]
        return values - before

    def _sources(self, src: npt.NDArray[np.int64]) -> None:
        """The source stamps present: the window's span, the intervals forward in time (gaps, largest)."""
        if not len(src):
            return
        if self._first_source is None:
            self._first_source = int(src[0])
        steps = self._steps(self._last_source, src)
        if len(steps):  # a gap's threshold is above 0: only forward intervals reach it
            self._largest_gap = max(self._largest_gap, int(steps.max()))
            gaps = int(np.count_nonzero(steps >= self._gap_from))
            self._gaps += gaps
            self.total_gaps += gaps
        self._last_source = self._end_source = int(src[-1])

    def _receptions(self, rec: npt.NDArray[np.int64], handled: npt.NDArray[np.int64]) -> None:
        """The reception stamps present and when those messages were taken: bursts, lag."""
        if not len(rec):
            return
        steps = self._steps(self._last_received, rec)
        # 0 <= step < burst_ns in one comparison: a negative step read as unsigned is above any threshold
        self._bursts += int(np.count_nonzero(steps.view(np.uint64) < self._burst_below))
        self._last_received = int(rec[-1])
        self._lag = max(self._lag, int((handled - rec).max()))

    def _sequence(self, seq: npt.NDArray[np.int64]) -> None:
        """The sequence numbers present, one publisher: each one more than one above the highest before it
        counts the numbers between as drops (a number at or below it, a repeat or a reset, counts none)."""
        if not len(seq):
            return
        numbers = seq if self._last_seq is None else np.concatenate(([self._last_seq], seq))
        highest = np.maximum.accumulate(numbers)
        drops = int(np.maximum(numbers[1:] - highest[:-1] - 1, 0).sum())
        self._drops += drops
        self.total_drops += drops
        self._last_seq = int(highest[-1])

    def window(self) -> RateWindow:
        """The statistics since the last call, and a new window."""
        span = (self._end_source - self._first_source) if self._first_source is not None \
            and self._end_source is not None else 0
        rate = (self._n - 1) / (span * 1e-9) if self._n > 1 and span > 0 else math.nan
        w = RateWindow(self._n, rate, self._gaps, self._largest_gap * 1e-9, self._bursts, self._drops,
                       not self._several, max(self._lag, 0) * 1e-9)
        self._reset_window()
        return w
