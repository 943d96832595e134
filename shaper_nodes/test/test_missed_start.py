"""A START a listener missed, stood in for by a later event's start stamp (CycleEvent ``start_stamp``): the rule
(MissedStarts), and each listener's measure of such a cycle (the LIST session, the cycle monitor of the identifier,
the bag analysis's segmentation): the same figures as with its START when its samples reach back to it, else the
exact reason it is not used. Over DDS: tests/test_send_goal.py::test_a_listener_that_missed_start_gets_the_cycle."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.analysis.segment import from_events
from shaper_nodes.analysis.signals import Events
from shaper_nodes.core.cycles import END, MOTION_END, START, CycleMonitor, Event, MissedStarts, unseen_window
from shaper_nodes.core.learning.list.learner import ListLearner
from shaper_nodes.core.learning.list.params import ListConfig
from shaper_nodes.core.learning.list.session import KEEP_BEFORE_START, ListSession

RATE = 500.0
W, Z = 10.0, 0.05


def decay(t):
    wd = W * np.sqrt(1 - Z**2)
    return np.where(t > 1.5, np.exp(-Z * W * (t - 1.5)) * np.sin(wd * (t - 1.5)), 0.0)


# ------------------------------------------------------------------ the rule
def test_a_later_event_with_the_start_stamp_stands_in_for_a_start_missed_once():
    rule = MissedStarts()
    assert rule.events(MOTION_END, 4, 11.5, 10.0) == [Event(START, 4, 10.0, True), Event(MOTION_END, 4, 11.5)]
    assert rule.events(END, 4, 16.0, 10.0) == [Event(END, 4, 16.0)]  # the START stood in for already
    assert rule.events(START, 5, 20.0, 20.0) == [Event(START, 5, 20.0)]
    assert rule.events(MOTION_END, 5, 21.5, 20.0) == [Event(MOTION_END, 5, 21.5)]
    assert rule.events(END, 5, 26.0, 20.0) == [Event(END, 5, 26.0)]
    assert rule.events(END, 6, 36.0, 30.0) == [Event(START, 6, 30.0, True), Event(END, 6, 36.0)]
    assert rule.stood_in == 2


def test_without_the_stamp_an_event_passes_as_it_came():
    rule = MissedStarts()
    assert rule.events(END, 3, 5.0, None) == [Event(END, 3, 5.0)]  # "END without its START", as before
    assert rule.stood_in == 0


def test_the_window_is_seen_only_from_samples_held_at_or_before_start():
    assert unseen_window(10.0, 9.99) == "" and unseen_window(10.0, 10.0) == ""
    why = unseen_window(10.0, 10.4)
    assert "START was missed" in why and "10.000 s" in why and "begin at 10.400 s" in why and "not seen" in why
    assert "no samples held" in unseen_window(10.0, None)


# ------------------------------------------------------------------ the LIST session (the learner)
def session(keep_span: float = 30.0) -> ListSession:
    s = ListSession(ListLearner(ListConfig(highpass_hz=0.5)), "zv2", stale_after=0.1, keep_span=keep_span)
    s.sent(None)
    s.on_shaper([1.0], [0.0], "learner", 1)
    return s


def cycle(s: ListSession, t0: float, missed: bool, samples_from: float = -1.0):
    """One cycle at t0 s, its samples from t0 + samples_from; seen: its START first; missed: the START stood in
    for at MOTION_END."""
    if not missed:
        s.on_event(START, 0, t0, [0.0], [1.0])
    for t in np.arange(samples_from, 1.5, 1.0 / RATE):
        s.on_imu(t0 + t, (float(decay(t)), 0.0, 0.0))
    if missed:
        s.on_event(START, 0, t0, [0.0], [1.0], stood_in=True)
    s.on_event(MOTION_END, 0, t0 + 1.5)
    for t in np.arange(1.5, 6.0 + 1e-9, 1.0 / RATE):
        s.on_imu(t0 + t, (float(decay(t)), 0.0, 0.0))
    return s.on_event(END, 0, t0 + 6.0)


def test_the_learner_measures_a_cycle_whose_start_it_missed_as_if_it_had_seen_it():
    seen, missed = cycle(session(), 10.0, False), cycle(session(), 10.0, True)
    assert seen.learned and missed.learned, (seen.skipped, missed.skipped)
    assert missed.update.m == seen.update.m and missed.update.next == seen.update.next


@pytest.mark.parametrize("samples_from", [0.2, 1.0])
def test_the_learner_refuses_a_cycle_it_was_not_listening_to_from_its_start(samples_from):
    r = cycle(session(), 10.0, True, samples_from=samples_from)
    assert r.update is None and "START was missed" in r.skipped and "not seen" in r.skipped
    assert f"begin at {10.0 + samples_from:.3f} s" in r.skipped


def test_with_keep_span_the_buffer_between_cycles_holds_at_most_twice_the_span():
    s = session(keep_span=30.0)
    peak = 0
    for t in np.arange(0.0, 120.0, 1.0 / 1000.0):
        s.on_imu(t, (0.1, 0.0, 0.0))
        peak = max(peak, s.buffered)
    assert 30_000 <= s.buffered <= peak <= 2 * 30_001  # the last 30 s, cut again once doubled
    assert s.buffered_bytes < 4_000_000
    s = session(keep_span=0.5)  # fewer than KEEP_BEFORE_START in the span: the last KEEP_BEFORE_START kept
    for t in np.arange(0.0, 20.0, 1.0 / 1000.0):
        s.on_imu(t, (0.1, 0.0, 0.0))
        assert s.buffered <= 2 * KEEP_BEFORE_START


# ------------------------------------------------------------------ the cycle monitor (the identifier)
def monitor_cycle(m: CycleMonitor, missed: bool, samples_from: float = -1.0):
    """One cycle at 10 s; seen: its START first, then its samples; missed: the START stood in for at MOTION_END."""
    if not missed:
        m.event(START, 0, 10.0)
    for t in np.arange(samples_from, 1.5, 1.0 / RATE):
        m.add_accel(10.0 + t, (float(decay(t)), 0.0, 9.81))
        m.add_positions(10.0 + t, [max(t, 0.0) / 1.5])
    if missed:
        m.event(START, 0, 10.0, stood_in=True)
    m.event(MOTION_END, 0, 11.5)
    for t in np.arange(1.5, 6.0 + 1e-9, 1.0 / RATE):
        m.add_accel(10.0 + t, (float(decay(t)), 0.0, 9.81))
        m.add_positions(10.0 + t, [1.0])
    return m.event(END, 0, 16.0)


def test_the_identifier_monitor_measures_a_cycle_whose_start_it_missed_as_if_it_had_seen_it():
    seen = monitor_cycle(CycleMonitor(remove_mean=True, keep_before=30.0), False)
    missed = monitor_cycle(CycleMonitor(remove_mean=True, keep_before=30.0), True)
    assert missed.unseen == "" and seen.unseen == ""
    assert missed.residual == seen.residual
    np.testing.assert_array_equal(missed.accel_times, seen.accel_times)
    np.testing.assert_array_equal(missed.position_times, seen.position_times)


def test_the_identifier_monitor_says_why_when_it_was_not_listening_from_start():
    r = monitor_cycle(CycleMonitor(keep_before=30.0), True, samples_from=0.5)
    assert "START was missed" in r.unseen and "begin at 10.500 s" in r.unseen
    r = monitor_cycle(CycleMonitor(), True)  # nothing kept between cycles
    assert "no samples held" in r.unseen


# ------------------------------------------------------------------ the bag analysis (the recorder's recording)
def events(start_stamps) -> Events:
    ev = Events()
    rows = [(MOTION_END, 0, 1.5), (END, 0, 6.0), (START, 1, 10.0), (MOTION_END, 1, 11.5), (END, 1, 16.0)]
    for i, ((kind, cyc, t), start) in enumerate(zip(rows, start_stamps, strict=True)):
        ev.seq.append(i), ev.t.append(t), ev.kind.append(kind), ev.cycle.append(cyc)
        ev.start.append((0.0,)), ev.goal.append((1.0,)), ev.joint_names.append(("j1",))
        ev.start_stamp.append(start)
    return ev


def test_the_analysis_stands_in_for_a_start_the_recording_missed():
    spans, notes = from_events(events([0.0, 0.0, 10.0, 10.0, 10.0]), first_sample=-2.0)
    assert [(s.cycle, s.start, s.motion_end, s.end) for s in spans] == [(0, 0.0, 1.5, 6.0), (1, 10.0, 11.5, 16.0)]
    assert notes == ["cycle 0: START not in the recording; stood in for by the MOTION_END's start stamp (0.000 s)"]


def test_the_analysis_leaves_out_a_cycle_whose_start_the_recording_did_not_reach():
    spans, notes = from_events(events([0.0, 0.0, 10.0, 10.0, 10.0]), first_sample=0.8)
    assert [s.cycle for s in spans] == [1]
    assert len(notes) == 1 and notes[0].startswith("cycle 0: its START was missed") and "left out" in notes[0]


def test_the_analysis_of_events_without_the_stamp_is_as_before():
    spans, notes = from_events(events([np.nan] * 5), first_sample=-2.0)
    assert [s.cycle for s in spans] == [1]
    assert notes == ["cycle 0: MOTION_END without its START; left out", "cycle 0: END without its START; left out"]
    old = events([np.nan] * 5)
    old.start_stamp.clear()  # decoded with a definition older than the field
    assert from_events(old, first_sample=-2.0) == (spans, notes)
