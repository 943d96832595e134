"""A move with no schedule: its move + settle time measured on the accelerometer, a factor's cost predicted against
it, and the next factor on the lowest mode still ringing (core/learning/list/settle.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.learning.list import ListError, ListParams
from shaper_nodes.core.learning.list.payback import Component, lowest_first, paying_factor, predicted_residual
from shaper_nodes.core.learning.list.settle import (
    DEFAULT_BAND,
    HORIZON,
    covered,
    envelope_settle,
    full_pair,
    imu_settle,
    lowest_paying,
    unshaped_time_cost,
)
from shaper_nodes.core.learning.speed import acceleration_tolerance
from shaper_nodes.core.shaping import Mode

RATE = 500.0


def _ringing(amplitude: float, hz: float, zeta: float, after: float = 1.0, end: float = 3.0,
             noise: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Three accelerometer axes at rest (gravity on z) with a decaying mode on x from ``after`` s on."""
    t = np.arange(0.0, end, 1.0 / RATE)
    w = 2 * math.pi * hz
    u = np.clip(t - after, 0.0, None)
    x = np.where(t >= after, amplitude * np.exp(-zeta * w * u) * np.sin(w * np.sqrt(1 - zeta**2) * u), 0.0)
    a = np.column_stack([x, np.zeros_like(t), np.full_like(t, 9.81)])
    if noise:
        a = a + np.random.default_rng(0).normal(0.0, noise, a.shape)
    return t, a


def test_the_default_band_is_the_flanges_005_mm_at_10_hz():
    assert pytest.approx(acceleration_tolerance(5e-5, 10.0)) == DEFAULT_BAND
    assert pytest.approx(0.1974, abs=1e-4) == DEFAULT_BAND


def test_the_accelerometer_settles_when_its_envelope_enters_the_band_for_good():
    amp, hz, zeta = 1.0, 10.0, 0.03
    t, a = _ringing(amp, hz, zeta)
    rate = zeta * 2 * math.pi * hz
    expected = 1.0 + math.log(amp / DEFAULT_BAND) / rate  # the envelope's crossing, s
    got = imu_settle(t, a, 1.0, 3.0, DEFAULT_BAND)
    assert got == pytest.approx(expected, abs=0.02)
    # the noise (0.01 m/s^2 on each axis) moves it by a few ms, not by its peaks
    tn, an = _ringing(amp, hz, zeta, noise=0.01)
    assert imu_settle(tn, an, 1.0, 3.0, DEFAULT_BAND) == pytest.approx(got, abs=0.005)
    # a quieter move settles sooner; one already within the band at once
    assert imu_settle(*_ringing(0.5, hz, zeta), 1.0, 3.0, DEFAULT_BAND) < got
    assert imu_settle(*_ringing(0.1, hz, zeta), 1.0, 3.0, DEFAULT_BAND) == 1.0
    # one that rings to the cycle's end settles there
    assert imu_settle(t, a, 1.0, 1.5, DEFAULT_BAND) == pytest.approx(1.5, abs=1.0 / RATE)
    # a stacked command's decelerating tail after the planned end (2 m/s^2 for 0.2 s) does not bias the settled
    # value: the move settles after the tail and the ringing, not at the cycle's end
    tail = t, a.copy()
    tail[1][(t >= 1.0) & (t < 1.2), 0] -= 2.0
    assert 1.2 < imu_settle(*tail, 1.0, 3.0, DEFAULT_BAND) < 2.5
    with pytest.raises(ListError, match="band"):
        imu_settle(t, a, 1.0, 3.0, 0.0)
    with pytest.raises(ListError, match="no accelerometer sample"):
        imu_settle(t, a, 5.0, 6.0, DEFAULT_BAND)


def test_the_envelope_settles_sooner_with_a_pair_on_the_mode_that_rings_longest():
    slow = Component(2 * math.pi * 10.0, 0.03, 1.0)
    fast = Component(2 * math.pi * 20.0, 0.08, 0.5)
    band = DEFAULT_BAND
    alone = envelope_settle([slow], band)
    assert alone == pytest.approx(math.log(1.0 / band) / (slow.zeta * slow.omega), rel=1e-4)
    both = envelope_settle([slow, fast], band)
    assert both > alone
    zv = ListParams.from_mode(Mode(slow.omega, slow.zeta))
    on_slow = envelope_settle([slow, fast], band, zv)
    on_fast = envelope_settle([slow, fast], band, ListParams.from_mode(Mode(fast.omega, fast.zeta)))
    assert on_slow < on_fast < both + 1e-9
    # the loop's heavily damped transient carried past the late impulse stays bounded (no exp(zeta omega T2))
    loop = Component(2 * math.pi * 50.0, 0.6, 0.5)
    assert envelope_settle([loop], band, zv) < zv.t2 + 0.05
    assert envelope_settle([], band) == 0.0 and envelope_settle([Component(10.0, 0.0, 1.0)], band) == HORIZON


def test_a_factor_that_cancels_what_rings_longest_costs_negative_time_and_one_on_a_weak_mode_does_not():
    slow = Component(2 * math.pi * 10.0, 0.03, 1.0)
    weak = Component(2 * math.pi * 30.0, 0.05, 0.05)

    def command(factors: tuple[ListParams, ...]) -> float:  # a stand-in: the command settles at its last impulse
        return float(sum(p.t2 for p in factors))

    cost = unshaped_time_cost([slow, weak], DEFAULT_BAND, (), command)
    on_slow = cost(ListParams.from_mode(Mode(slow.omega, slow.zeta)))
    on_weak = cost(ListParams.from_mode(Mode(weak.omega, weak.zeta)))
    # the pair on the slow mode ends its ringing; the one on the weak mode only takes 13 % off the slow one (a
    # 30 Hz pair at 10 Hz: |cos(pi 10 T2)| = 0.87), which then crosses the band ln(1/0.87) / 1.88 s = 74 ms sooner
    assert on_slow < -0.5 and on_weak == pytest.approx(-math.log(1 / 0.866) / (slow.zeta * slow.omega), abs=0.01)
    # the kept factors' delay: the reference's commanded end is their T2 after the planned end
    kept = (ListParams(0.6, 0.04),)
    later = unshaped_time_cost([weak], DEFAULT_BAND, kept, command)
    assert later(ListParams(0.9, 0.01)) == pytest.approx(0.01, abs=1e-9)  # only the command's tail: its 10 ms


def test_the_next_factor_goes_on_the_lowest_mode_still_ringing_not_the_strongest():
    low = Component(2 * math.pi * 7.9, 0.025, 0.14)
    strong = Component(2 * math.pi * 30.0, 0.13, 0.4)  # the loop's transient: damped, stronger
    high = Component(2 * math.pi * 20.8, 0.08, 0.3)
    order = lowest_first([strong, high, low], 0.12)
    assert order == [low, high, strong]

    def free(p: ListParams) -> float:
        return 0.0

    pick = lowest_paying([strong, high, low], free, 0.0021, 0.12)
    assert pick is not None and pick.component == low and pick.predicted < 0.5 * pick.without
    assert paying_factor([strong, high, low], free, 0.0021).component != low  # the strongest otherwise
    # where the lowest has no factor predicted to pay (too slow), the next one up
    def costly_on_low(p: ListParams) -> float:
        return 1.0 if p.t2 > 0.05 else 0.0

    nxt = lowest_paying([strong, high, low], costly_on_low, 0.0021, 0.12)
    assert nxt is not None and nxt.component == high
    assert lowest_paying([strong, high, low], lambda p: 1.0, 0.0021, 0.12) is None


def test_with_no_schedule_each_ringing_mode_gets_one_full_pair_lowest_first_then_the_partial_ones_tune():
    low = Component(2 * math.pi * 9.95, 0.03, 0.5)
    high = Component(2 * math.pi * 12.2, 0.04, 0.3)
    loop = Component(2 * math.pi * 50.0, 0.6, 0.4)  # damped: no full pair
    comps = [loop, high, low]

    def free(p: ListParams) -> float:
        return 0.0

    first = lowest_paying(comps, free, 0.0021, 0.12, kept=())
    zv_low = ListParams.from_mode(Mode(low.omega, low.zeta))
    assert first is not None and first.component == low and first.full and first.params == zv_low
    assert covered(low, [zv_low]) and not covered(high, [zv_low])
    # the next reference: the lowest is covered, so the full pair goes on the next ringing mode up
    second = lowest_paying(comps, free, 0.0021, 0.12, kept=[zv_low])
    assert second is not None and second.component == high and second.full
    assert second.params == ListParams.from_mode(Mode(high.omega, high.zeta))
    # every ringing mode covered: the partial pairs' rule, on the lowest still ringing (what tunes it)
    both = [zv_low, second.params]
    assert full_pair(comps, free, 0.0021, 0.12, both) is None
    tune = lowest_paying(comps, free, 0.0021, 0.12, kept=both)
    assert tune is not None and tune == lowest_paying(comps, free, 0.0021, 0.12)
    # a full pair predicted to cost too much is not chosen: the next mode's, then none
    def slow_low(p: ListParams) -> float:
        return 1.0 if p.t2 > 0.045 else 0.0

    assert full_pair(comps, slow_low, 0.0021, 0.12, ()).component == high  # type: ignore[union-attr]
    assert full_pair(comps, lambda p: 1.0, 0.0021, 0.12, ()) is None


def test_the_residual_from_the_shaped_commands_end_stays_bounded_on_the_loops_pole():
    loop = Component(2 * math.pi * 50.0, 0.6, 0.5)
    ring = Component(2 * math.pi * 10.0, 0.03, 1.0)
    zv = ListParams.from_mode(Mode(ring.omega, ring.zeta))
    # carried back to before the late impulse, the loop's transient grows as exp(zeta omega T2) (e^9)...
    assert predicted_residual([loop, ring], zv) > 100.0
    # ...from the shaped command's end it is at most what it was, and the pair cancels the mode
    assert predicted_residual([loop, ring], zv, shifted=True) < predicted_residual([loop, ring], None)
    assert predicted_residual([ring], zv, shifted=True) < 1e-9
