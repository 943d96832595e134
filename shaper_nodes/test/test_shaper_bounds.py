"""Bounded shapers: every change does bounded work, and no custom shaper amplifies unless allowed."""

import numpy as np
import pytest

from shaper_nodes.core.shaping import (
    MAX_DESIGN_MODES,
    MAX_GAIN,
    MAX_IMPULSES,
    Mode,
    Shaper,
    ShaperError,
    design,
)

MODE = Mode.from_hz(5.0, 0.05)


def modes(n):
    return [Mode.from_hz(5.0 + k, 0.05) for k in range(n)]


def test_too_many_design_modes_are_refused_before_any_work():
    with pytest.raises(ShaperError, match=f"25 design modes exceed the limit of {MAX_DESIGN_MODES}"):
        design("zvd", modes(25))  # 3^25 impulses if it were attempted


def test_a_convolution_beyond_the_impulse_limit_is_refused():
    ok = design("zvd", modes(6))  # 3^6 = 729 impulses
    assert len(ok) <= MAX_IMPULSES
    with pytest.raises(ShaperError, match=f"zvd for 7 modes needs more than {MAX_IMPULSES} impulses"):
        design("zvd", modes(7))  # 2187


def test_a_custom_shaper_that_amplifies_is_refused_naming_its_gain():
    with pytest.raises(ShaperError,
                       match=r"gain sum \|A\| = 1999 exceeds max_gain 1 \(a unit step would peak at 1000\)"):
        design("custom", amplitudes=[1000.0, -999.0], times=[0.0, 0.1])
    with pytest.raises(ShaperError, match="gain sum"):
        design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.1])


def test_negative_impulses_pass_when_allowed_and_the_bound_is_the_gain():
    s = design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.1], max_gain=3.0)
    assert s.gain == pytest.approx(3.0) and s.step_peak == pytest.approx(2.0)
    # the bound holds for any input: |y| <= gain * max |x|
    x = np.sign(np.sin(np.arange(400) * 0.37))
    y = x[10:] * 2.0 - x[:-10]
    assert np.max(np.abs(y)) <= s.gain * np.max(np.abs(x)) + 1e-12
    for bad in (0.5, MAX_GAIN * 2, float("nan")):
        with pytest.raises(ShaperError, match="max_gain must be in"):
            design("custom", amplitudes=[1.0], times=[0.0], max_gain=bad)


def test_too_many_custom_impulses_are_refused():
    n = MAX_IMPULSES + 1
    with pytest.raises(ShaperError, match=f"{n} impulses exceed the limit of {MAX_IMPULSES}"):
        design("custom", amplitudes=[1.0 / n] * n, times=np.linspace(0.0, 1.0, n).tolist())
    with pytest.raises(ShaperError, match="impulses exceed the limit"):
        Shaper(np.full(n, 1.0 / n), np.linspace(0.0, 1.0, n))


def test_designed_shapers_have_unit_gain():
    for family in ("zv", "zvd", "mzv", "ei", "2hump_ei", "si"):
        assert design(family, [MODE]).gain == pytest.approx(1.0), family
