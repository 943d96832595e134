"""The drift watch's core: the working band of a shaper, a mode rated against it, confirmation."""

from __future__ import annotations

import math

import pytest

from shaper_nodes.core.identification import ModeFit
from shaper_nodes.core.identification.drift import DriftWatch, check_mode, working_band
from shaper_nodes.core.shaping.families import Mode, design


def fit(hz: float, zeta: float = 0.0) -> ModeFit:
    return ModeFit(2 * math.pi * hz, zeta, 0.01, 0.001, 1.0, "fit")


def test_the_working_band_of_an_undamped_zv_is_where_cos_of_pi_r_over_2_stays_under_the_tolerance():
    zv = design("zv", (Mode(2 * math.pi * 4.0, 0.0),))
    lo, hi = working_band(zv.amplitudes, zv.times, 4.0, 0.0, 0.05)
    # V(r) = |cos(pi r / 2)| for the undamped ZV: V = 0.05 at r = 2 acos(0.05) / pi and 2 - that
    r = 2 * math.acos(0.05) / math.pi
    assert lo == pytest.approx(4.0 * r, abs=0.004) and hi == pytest.approx(4.0 * (2 - r), abs=0.004)


def test_a_robust_shaper_has_a_wider_band_and_the_identity_none():
    mode = (Mode(2 * math.pi * 4.0, 0.02),)
    zv, zvd = design("zv", mode), design("zvd", mode)
    (a, b), (c, d) = working_band(zv.amplitudes, zv.times, 4.0, 0.02, 0.05), \
        working_band(zvd.amplitudes, zvd.times, 4.0, 0.02, 0.05)
    assert d - c > 2 * (b - a)
    assert working_band([1.0], [0.0], 4.0, 0.02, 0.05) is None


def test_a_mode_is_rated_against_the_nearest_design_mode_and_named():
    zv = design("zv", (Mode(2 * math.pi * 4.0, 0.02),))
    inside = check_mode(zv.amplitudes, zv.times, [4.0, 11.0], fit(4.05, 0.02), 0.05)
    outside = check_mode(zv.amplitudes, zv.times, [4.0, 11.0], fit(4.6, 0.02), 0.05)
    assert inside.inside and inside.reference_hz == 4.0 and inside.vibration < 0.05
    assert not outside.inside and outside.vibration > 0.05
    assert "mode 4.6 Hz" in outside.describe() and "outside the band" in outside.describe()
    assert "V at the mode" in outside.describe()


def test_the_warning_needs_confirm_checks_in_a_row_and_clears_at_the_first_inside():
    zv = design("zv", (Mode(2 * math.pi * 4.0, 0.02),))
    good = check_mode(zv.amplitudes, zv.times, [4.0], fit(4.0, 0.02), 0.05)
    bad = check_mode(zv.amplitudes, zv.times, [4.0], fit(4.6, 0.02), 0.05)
    watch = DriftWatch(confirm=3)
    assert [watch.update(c) for c in (bad, bad, good, bad, bad, bad, good)] == \
        [False, False, False, False, False, True, False]
    watch.update(bad)
    watch.reset()
    assert not watch.warning and watch.outside_in_a_row == 0
    with pytest.raises(ValueError, match="confirm"):
        DriftWatch(confirm=0)


def test_bad_arguments_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="reference frequency"):
        working_band([0.5, 0.5], [0.0, 0.1], math.nan, 0.0, 0.05)
    with pytest.raises(ValueError, match="tolerance"):
        working_band([0.5, 0.5], [0.0, 0.1], 5.0, 0.0, 1.5)
