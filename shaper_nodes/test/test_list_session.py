"""The learner's bookkeeping (ListSession): which cycles are learned from, and why not."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.cycles import END, MOTION_END, START
from shaper_nodes.core.learning.list.learner import ListLearner
from shaper_nodes.core.learning.list.params import ListConfig, ListError, ListParams
from shaper_nodes.core.learning.list.session import ListSession, list_config

RATE = 200.0
W, Z = 10.0, 0.05


def decay(t):
    wd = W * np.sqrt(1 - Z**2)
    return np.where(t > 1.5, np.exp(-Z * W * (t - 1.5)) * np.sin(wd * (t - 1.5)), 0.0)


def run_cycle(session, cycle, t0, imu=True, end_at=6.0, samples_until=None):
    session.on_event(START, cycle, t0, [0.0], [1.0])
    session.on_event(MOTION_END, cycle, t0 + 1.5)
    if imu:
        stop = end_at if samples_until is None else samples_until
        for t in np.arange(0.0, stop + 1e-9, 1.0 / RATE):
            session.on_imu(t0 + t, (float(decay(t)), 0.0, 0.0))
    return session.on_event(END, cycle, t0 + end_at)


def fresh():
    session = ListSession(ListLearner(ListConfig(highpass_hz=0.5)), "zv2", stale_after=0.1)
    session.sent(None)
    session.on_shaper([1.0], [0.0], "learner", 1)
    return session


def test_unshaped_cycle_is_the_reference_and_the_next_must_use_what_was_sent():
    s = fresh()
    r = run_cycle(s, 0, 0.0)
    assert r.learned and r.update.action == "reference"
    s.sent(r.update.next)
    # the shaper node still reports the identity: the next cycle did not run with what was sent
    r = run_cycle(s, 1, 10.0)
    assert r.update is None and "ran unshaped" in r.skipped
    s.on_shaper([0.5, 0.5], [0.0, 0.2], "user", 7)  # somebody else's shaper
    r = run_cycle(s, 2, 20.0)
    assert r.update is None and "did not set" in r.skipped
    amps, times = s.learner.params.impulses("zv2")
    s.on_shaper(amps, times, "learner", 8)  # the learner's impulses: learned from
    r = run_cycle(s, 3, 30.0)
    assert r.update is not None and r.update.used is not None


@pytest.mark.parametrize("kind, why", [("missing", "no accelerometer data"), ("stale", "stale accelerometer")])
def test_missing_or_stale_sensor_is_skipped(kind, why):
    s = fresh()
    r = run_cycle(s, 0, 0.0, imu=kind != "missing", samples_until=4.0 if kind == "stale" else None)
    assert r.update is None and why in r.skipped


def test_end_without_start_and_shaper_change_mid_cycle_are_skipped():
    s = fresh()
    r = s.on_event(END, 3, 5.0)
    assert r is not None and "without its START" in r.skipped
    s.on_event(START, 4, 10.0, [0.0], [1.0])
    s.on_shaper([0.5, 0.5], [0.0, 0.3], "user", 2)
    s.on_event(MOTION_END, 4, 11.5)
    for t in np.arange(0.0, 6.0, 1.0 / RATE):
        s.on_imu(10.0 + t, (float(decay(t)), 0.0, 0.0))
    r = s.on_event(END, 4, 16.0)
    assert r.update is None and "changed during the cycle" in r.skipped


def test_samples_are_taken_by_stamp_whatever_their_arrival_order():
    a, b = fresh(), fresh()
    ra = run_cycle(a, 0, 0.0)
    # b: the same samples, but the first ones arrive before START is processed
    stamps = np.arange(0.0, 6.0 + 1e-9, 1.0 / RATE)
    for t in stamps[stamps < 0.5]:
        b.on_imu(t, (float(decay(t)), 0.0, 0.0))
    b.on_event(START, 0, 0.0, [0.0], [1.0])
    b.on_event(MOTION_END, 0, 1.5)
    for t in stamps[stamps >= 0.5]:
        b.on_imu(t, (float(decay(t)), 0.0, 0.0))
    rb = b.on_event(END, 0, 6.0)
    assert ra.update.m == rb.update.m and ra.update.next == rb.update.next


def test_list_config_from_node_parameters():
    cfg = list_config({"rule": "paper", "window_delay": 0.0, "t2_bounds": [0.0, 0.0], "saturation": 0.0,
                       "a1_bounds": [0.3, 0.9], "patience": 2})
    assert cfg.rule == "paper" and cfg.window_delay is None and cfg.t2_bounds is None
    assert cfg.saturation == float("inf") and cfg.a1_bounds == (0.3, 0.9) and cfg.patience == 2
    with pytest.raises(ListError, match="rule"):
        list_config({"rule": "magic"})
    assert ListParams(0.5, 0.3).shaper("zv2").duration == pytest.approx(0.3)
