"""How a streamed input arrives against its nominal rate: rate, gaps, bursts, drops and lag.

A streamed command (one sample per message at the command rate) is only shaped right if every
sample arrives: a lost sample is a step the filter never sees. :class:`RateWatch` keeps, per
input, the statistics of one reporting window from what the middleware says about each message:

``source`` (ns)
    when the publisher sent it (its clock): the *input rate* is measured on these stamps, and a
    *gap* is an interval between two of them longer than ``gap_factor`` command periods (the
    sender paused or messages were lost before us).
``received`` (ns)
    when our middleware received it (our clock). A *burst* is an interval between two receptions
    shorter than ``burst_factor`` periods: messages bunched on the way (network, sender).
``handled`` (ns)
    when the node took it (our clock): the *lag* ``handled - received`` is how long it waited in
    the subscription's queue, i.e. how far the node fell behind.
``sequence``
    the publisher's sequence number: a jump of more than one is that many *drops* (a full queue, or
    loss in transport). Sequence numbers are per publisher, so drops are counted only while one
    publisher is seen (``publishers == 1``).

Nothing here reads a clock: the node passes the stamps in, so the statistics are the same in a
replay or a test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


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
        self.period_ns = 1e9 / rate
        self.gap_ns = gap_factor * self.period_ns
        self.burst_ns = burst_factor * self.period_ns
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
        """One message: its stamps (ns; None where the middleware gives none) and sequence number."""
        self._n += 1
        if source:
            if self._first_source is None:
                self._first_source = source
            if self._last_source is not None and source > self._last_source:
                interval = source - self._last_source
                self._largest_gap = max(self._largest_gap, interval)
                if interval > self.gap_ns:
                    self._gaps += 1
                    self.total_gaps += 1
            self._last_source = source
            self._end_source = source
        if received:
            if self._last_received is not None and 0 <= received - self._last_received < self.burst_ns:
                self._bursts += 1
            self._last_received = received
            self._lag = max(self._lag, handled - received)
        if publishers != 1:
            self._several = True
            self._last_seq = None
        elif sequence is not None and sequence > 0:
            if self._last_seq is not None and sequence > self._last_seq + 1:
                self._drops += sequence - self._last_seq - 1
                self.total_drops += sequence - self._last_seq - 1
            if self._last_seq is None or sequence > self._last_seq:
                self._last_seq = sequence

    def window(self) -> RateWindow:
        """The statistics since the last call, and a new window."""
        span = (self._end_source - self._first_source) if self._first_source is not None \
            and self._end_source is not None else 0
        rate = (self._n - 1) / (span * 1e-9) if self._n > 1 and span > 0 else math.nan
        w = RateWindow(self._n, rate, self._gaps, self._largest_gap * 1e-9, self._bursts, self._drops,
                       not self._several, max(self._lag, 0) * 1e-9)
        self._reset_window()
        return w
