"""The per-move keep rule weighs residual AND move + settle time; LIST's band keeps a factor on its mode."""

from __future__ import annotations

import math

import pytest

from shaper_nodes.core.learning.list import ListConfig, ListError, ListLearner, ListParams
from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S, MoveStore, keep_when_it_pays, pays

A0, A1 = [0.0, -1.57, 1.0], [0.5, -1.2, 1.4]


def _entry():
    entry, _ = MoveStore().entry(A0, A1)
    return entry


def test_pays_needs_a_lower_residual_and_no_longer_time():
    base = {"residual_rms": 0.010, "move_settle_s": 1.000}
    assert pays({"residual_rms": 0.005, "move_settle_s": 1.000}, base)
    assert pays({"residual_rms": 0.005, "move_settle_s": 1.000 + TIME_TOLERANCE_S}, base)  # within the tolerance
    assert not pays({"residual_rms": 0.005, "move_settle_s": 1.010}, base)  # less vibration, but slower
    assert not pays({"residual_rms": 0.010, "move_settle_s": 0.900}, base)  # faster, but not less vibration
    assert pays({"residual_rms": 0.005}, base)  # time not measured: the residual alone
    assert pays({"residual_rms": 0.005, "move_settle_s": 1.010}, base, time_tolerance_s=0.02)


def test_a_slower_factor_is_not_kept_even_when_it_vibrates_less():
    entry = _entry()
    assert keep_when_it_pays(entry, 0.010, False, move_settle_s=1.000) == "learn"  # the schedule alone: the base
    assert entry.base == entry.best == {"residual_rms": 0.010, "move_settle_s": 1.000}
    # a quarter of the residual, 0.1 s slower: it does not pay, and nothing paid before: the base alone
    assert keep_when_it_pays(entry, 0.0025, True, move_settle_s=1.100) == "base"
    assert entry.best == entry.base


def test_a_move_falls_back_to_its_best_kept_factor():
    entry = _entry()
    keep_when_it_pays(entry, 0.010, False, move_settle_s=1.000)
    assert keep_when_it_pays(entry, 0.006, True, move_settle_s=0.998) == "learn"  # pays: the best kept
    assert entry.best == {"residual_rms": 0.006, "move_settle_s": 0.998}
    assert keep_when_it_pays(entry, 0.008, True, move_settle_s=0.999) == "learn"  # pays, not better: best stays
    assert entry.best == {"residual_rms": 0.006, "move_settle_s": 0.998}
    # less residual than the best, but slower than the base: stop at the best kept factor (not this one)
    assert keep_when_it_pays(entry, 0.001, True, move_settle_s=1.050) == "best"
    assert entry.best == {"residual_rms": 0.006, "move_settle_s": 0.998}


def test_without_time_the_rule_is_the_residual_alone():
    entry = _entry()
    keep_when_it_pays(entry, 0.010, False)
    assert keep_when_it_pays(entry, 0.012, True, 0.005) == "best"  # a learner's best that beat the base
    other = _entry()
    keep_when_it_pays(other, 0.010, False)
    assert keep_when_it_pays(other, 0.012, True, 0.011) == "base"
    late = _entry()  # a learner's best is not used once time is weighed: it may have cost time
    keep_when_it_pays(late, 0.010, False, move_settle_s=1.0)
    assert keep_when_it_pays(late, 0.012, True, 0.005, move_settle_s=1.0) == "base"


def test_t2_band_keeps_the_learned_frequency_near_the_start():
    start = ListParams(0.52, 1.0 / (2.0 * 12.15))
    lo, hi = start.t2_band(0.1)
    assert 1.0 / (2.0 * hi) == pytest.approx(0.9 * 12.15) and 1.0 / (2.0 * lo) == pytest.approx(1.1 * 12.15)
    learner = ListLearner(ListConfig(t2_bounds=(lo, hi)), start)
    assert learner.t2_bounds == (lo, hi)
    for bad in (0.0, 1.0, -0.1, math.nan):
        with pytest.raises(ListError, match="band"):
            start.t2_band(bad)
