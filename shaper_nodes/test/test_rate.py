"""The rate watch's batches (core/rate.py ``RateWatch.arrivals``, and ros/stream_watch.py's arrays) against a plain
reference written here from the module docstring's definitions, one message at a time: gaps, the largest gap,
bursts, drops (across batches and windows, one publisher or several), lag, totals and the window's rate, over
streams with gaps, reorders, repeats, absent stamps, sequence jumps and restarts, cut into batches and windows
at random points."""

from __future__ import annotations

import math
from dataclasses import astuple

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shaper_nodes.core.rate import RateWatch, RateWindow
from shaper_nodes.ros.stream_watch import StreamWatch, arrival_arrays


class Reference:
    """The module docstring's definitions, message by message, in plain Python."""

    def __init__(self, rate: float, gap_factor: float, burst_factor: float) -> None:
        self.gap_ns = gap_factor * 1e9 / rate  # an interval longer than this is a gap
        self.burst_ns = burst_factor * 1e9 / rate  # an interval in [0, this) is a burst
        self.last_source = self.last_received = self.highest = None
        self.total_gaps = self.total_drops = 0
        self.new_window()

    def new_window(self) -> None:
        self.messages = self.gaps = self.bursts = self.drops = self.largest_gap = self.lag = 0
        self.sources: list[int] = []
        self.several = False

    def message(self, source, received, handled, sequence, publishers):
        self.messages += 1
        if source not in (None, 0):  # absent: 0 or None
            self.sources.append(source)
            if self.last_source is not None and source - self.last_source > 0:  # forward in time
                interval = source - self.last_source
                self.largest_gap = max(self.largest_gap, interval)
                if interval > self.gap_ns:
                    self.gaps += 1
                    self.total_gaps += 1
            self.last_source = source
        if received not in (None, 0):
            if self.last_received is not None and 0 <= received - self.last_received < self.burst_ns:
                self.bursts += 1
            self.last_received = received
            self.lag = max(self.lag, handled - received)
        if publishers != 1:  # several: no drops counted, the highest forgotten
            self.several, self.highest = True, None
        elif sequence is not None and sequence > 0:
            if self.highest is not None and sequence > self.highest + 1:
                self.drops += sequence - self.highest - 1
                self.total_drops += sequence - self.highest - 1
            self.highest = sequence if self.highest is None else max(self.highest, sequence)

    def window(self) -> tuple:
        span = self.sources[-1] - self.sources[0] if self.sources else 0
        rate = (self.messages - 1) / (span * 1e-9) if self.messages > 1 and span > 0 else math.nan
        w = (self.messages, rate, self.gaps, self.largest_gap * 1e-9, self.bursts, self.drops, not self.several,
             max(self.lag, 0) * 1e-9)
        self.new_window()
        return w


def same(window: RateWindow, expected: tuple) -> bool:
    pairs = zip(astuple(window), expected, strict=True)
    return all((isinstance(a, float) and math.isnan(a) and math.isnan(b)) or a == b for a, b in pairs)


MS = 1_000_000
T0 = 1_764_400_000 * 10**9  # a wall clock in ns


@st.composite
def streams(draw):
    """(rate, gap factor, burst factor, messages, cuts): messages as (source, received, handled, sequence,
    publishers) and cuts as (index, new window?) in increasing index order."""
    rate = draw(st.sampled_from([1000.0, 100.0, 333.3, 1234.5]))
    gap_factor = draw(st.sampled_from([1.5, 1.0, 2.0, 1.37]))
    burst_factor = draw(st.sampled_from([0.25, 0.5, 0.1, 0.333]))
    period = round(1e9 / rate)
    # intervals about the thresholds (exactly on them and one ns either side), backwards, repeats, large
    steps = st.one_of(st.just(period), st.integers(-2, 6).map(lambda k: k * period // 4),
                      st.sampled_from([round(gap_factor * 1e9 / rate) + d for d in (-1, 0, 1)]),
                      st.sampled_from([math.ceil(burst_factor * 1e9 / rate) + d for d in (-1, 0, 1)]),
                      st.integers(-5 * MS, 50 * MS))
    sequence_steps = st.one_of(st.just(1), st.integers(-3, 5), st.integers(6, 10_000))
    n = draw(st.integers(0, 120))
    src = rec = T0 + draw(st.integers(0, 10**12))
    seq = draw(st.integers(1, 10**6))
    several = draw(st.sampled_from([0.0, 0.0, 0.2]))
    messages = []
    for _ in range(n):
        src += draw(steps)
        rec += draw(steps)
        lag = draw(st.integers(-10_000, 5 * MS))
        seq += draw(sequence_steps)
        if draw(st.integers(0, 49)) == 0:
            seq = draw(st.integers(1, 3))  # a restarted publisher
        publishers = 2 if several and draw(st.floats(0, 1)) < several else 1
        messages.append((draw(st.sampled_from([src] * 8 + [0, None])), draw(st.sampled_from([rec] * 8 + [0, None])),
                         rec + lag, draw(st.sampled_from([seq] * 8 + [0, None, -seq])), publishers))
    cuts = sorted(set(draw(st.lists(st.integers(0, n), max_size=8))))
    return rate, gap_factor, burst_factor, messages, [(c, draw(st.booleans())) for c in cuts]


def batches(messages, cuts):
    """The messages cut at ``cuts``: (batch, new window after it?), each batch of one publisher count."""
    out, start = [], 0
    for at, window in [*cuts, (len(messages), True)]:
        part = messages[start:at]
        while part:  # the publisher count is per batch: cut where it changes
            same_count = next((i for i, m in enumerate(part) if m[4] != part[0][4]), len(part))
            out.append((part[:same_count], False))
            part = part[same_count:]
        out.append(([], window))
        start = at
    return out


@settings(max_examples=400, deadline=None)
@given(streams())
def test_batches_give_the_statistics_of_one_message_at_a_time(stream):
    rate, gap_factor, burst_factor, messages, cuts = stream
    ref, watch = Reference(rate, gap_factor, burst_factor), RateWatch(rate, gap_factor, burst_factor)
    for batch, window in batches(messages, cuts):
        for m in batch:
            ref.message(*m)
        if batch:
            watch.arrivals(*(np.array([m[i] or 0 for m in batch], np.int64) for i in range(4)), batch[0][4])
        if window:
            expected, got = ref.window(), watch.window()
            assert same(got, expected), (got, expected)
        assert (watch.total_gaps, watch.total_drops) == (ref.total_gaps, ref.total_drops)


@settings(max_examples=100, deadline=None)
@given(streams())
def test_one_arrival_at_a_time_is_a_batch_of_one(stream):
    rate, gap_factor, burst_factor, messages, cuts = stream
    ref, watch = Reference(rate, gap_factor, burst_factor), RateWatch(rate, gap_factor, burst_factor)
    windows = {c for c, w in cuts if w}
    for i, m in enumerate(messages):
        if i in windows:
            assert same(watch.window(), ref.window())
        ref.message(*m)
        watch.arrival(*m)
    assert same(watch.window(), ref.window())
    assert (watch.total_gaps, watch.total_drops) == (ref.total_gaps, ref.total_drops)


@settings(max_examples=100, deadline=None)
@given(streams(), st.data())
def test_the_stream_watch_batches_its_kept_infos(stream, data):
    """The node's bookkeeping: infos as rclpy gives them, or missing a key, or None, kept by ``arrived`` and
    watched at random points, give the reference's windows in the summaries."""
    rate, _, _, messages, cuts = stream
    publishers = data.draw(st.sampled_from([1, 2]))
    ref, watch = Reference(rate, 1.5, 0.25), StreamWatch(rate, None, lambda k: publishers)
    watch.summary("quiet")  # asks the publisher count
    watched = {c for c, _ in cuts}
    for i, (source, received, handled, sequence, _) in enumerate(messages):
        if i in watched:
            watch.watch()
        info = data.draw(st.sampled_from([
            {"source_timestamp": source, "received_timestamp": received, "publication_sequence_number": sequence,
             "reception_sequence_number": 7},
            {"received_timestamp": received}, None]))
        if info is None:
            ref.message(None, None, handled, None, publishers)
        else:
            ref.message(info.get("source_timestamp"), info.get("received_timestamp"), handled,
                        info.get("publication_sequence_number"), publishers)
        watch.arrived("stream", info, handled)
    assert same(watch.watched("stream").window(), ref.window())
    assert watch.rate_watch["stream"].total_drops == ref.total_drops


def test_arrival_arrays_read_absent_fields_as_zero():
    kept = [({"source_timestamp": 5, "received_timestamp": 6, "publication_sequence_number": 7}, 8),
            (None, 9), ({"source_timestamp": None}, 10)]
    assert [a.tolist() for a in arrival_arrays(kept)] == [[5, 0, 0], [6, 0, 0], [8, 9, 10], [7, 0, 0]]
    assert all(a.dtype == np.int64 for a in arrival_arrays(kept))


def test_the_factors_must_be_finite_and_positive():
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="gap_factor"):
            RateWatch(1000.0, gap_factor=bad)
        with pytest.raises(ValueError, match="burst_factor"):
            RateWatch(1000.0, burst_factor=bad)
