"""Percentage vibration against an independent evaluation, and residual-vibration metrics."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shaper_nodes.core.fir import discretize, fir_impulses
from shaper_nodes.core.shapers import Mode, design
from shaper_nodes.core.vibration import (
    insensitivity_width,
    percentage_vibration,
    residual_vibration,
    settle_time,
)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0.05, 1.0), st.floats(0.0, 0.5)), min_size=1, max_size=5),
       st.floats(2.0, 60.0), st.floats(0.0, 0.3))
def test_v_is_the_ratio_of_residual_amplitudes(impulses, omega, zeta):
    """V equals the residual amplitude of the impulse train's response over that of one impulse.

    Independent of the C/S formula: the responses of a damped oscillator to each impulse are
    summed in time and the envelope ratio read off one period after the last impulse.
    """
    amps = np.array([a for a, _ in impulses])
    amps /= amps.sum()
    times = np.array(sorted(t for _, t in impulses))
    times -= times[0]
    wd = omega * math.sqrt(1 - zeta**2)
    tn = times[-1]
    t = tn + np.linspace(0.0, 2 * math.pi / wd, 4001)
    y = sum(a * np.exp(-zeta * omega * (t - ti)) * np.sin(wd * (t - ti)) for a, ti in zip(amps, times))
    single = np.exp(-zeta * omega * (t - tn))  # envelope of one unit impulse applied at t_n
    measured = np.max(np.abs(y) / single)
    assert abs(measured - percentage_vibration(amps, times, omega, zeta)) < 2e-3 * max(1.0, measured)


def test_splitting_between_samples_removes_the_rounding_error():
    """At 250 Hz to 1 kHz, rounding impulse times to samples leaves measurable V; splitting does not."""
    m = Mode.from_hz(7.3, 0.05)
    for family in ("zv", "zvd", "ei"):
        s = design(family, [m])
        for rate in (250.0, 500.0, 1000.0):
            v = {}
            for method in ("round", "split"):
                a, t = fir_impulses(discretize(s, rate, method), rate)
                v[method] = float(percentage_vibration(a, t, m.omega, m.zeta))
            # split is second order in omega Ts: below (omega Ts)^2 / 4 in excess of the design's own V
            own = float(percentage_vibration(s.amplitudes, s.times, m.omega, m.zeta))
            assert v["split"] - own <= (m.omega / rate) ** 2 / 4
    s = design("zv", [m])
    rounded = fir_impulses(discretize(s, 500.0, "round"), 500.0)
    split = fir_impulses(discretize(s, 500.0, "split"), 500.0)
    assert percentage_vibration(*rounded, m.omega, m.zeta) > 0.01  # 1.2 %: measurable
    assert percentage_vibration(*split, m.omega, m.zeta) < 0.001  # 0.04 %


def test_residual_metrics():
    t = np.arange(0, 2, 0.001)
    acc = np.column_stack([np.sin(2 * np.pi * 5 * t), np.zeros_like(t), np.zeros_like(t)])
    r = residual_vibration(t, acc, 1.0, 2.0)
    assert r.rms == np.float64(r.rms) and abs(r.rms - 1 / math.sqrt(2)) < 1e-3
    assert abs(r.peak - 1.0) < 1e-3 and r.samples == 1000
    assert math.isnan(residual_vibration(t, acc, 5.0, 6.0).rms)
    offset = residual_vibration(t, acc + 3.0, 1.0, 2.0, remove_mean=True)
    assert abs(offset.rms - r.rms) < 1e-3


def test_settle_time():
    t = np.arange(10) * 0.1
    p = np.array([0, 1, 2, 3, 4, 5, 5, 5, 5, 5], float)[:, None]
    assert settle_time(t, p, 0.0, 1e-9) == t[5]
    assert settle_time(t, p, 0.7, 1e-9) == 0.7


@pytest.mark.parametrize("level", [0.01, 0.05, 0.2])
def test_insensitivity_width_of_undamped_zv_and_zvd_is_the_analytic_one(level):
    """Undamped, V_ZV = |cos(pi r / 2)| and V_ZVD = cos^2(pi r / 2), r = omega / omega_design."""
    m = Mode(3.0, 0.0)
    zv, zvd = design("zv", [m]), design("zvd", [m])
    assert insensitivity_width(zv.amplitudes, zv.times, m.omega, 0.0, level) == pytest.approx(
        4 * math.asin(level) / math.pi, abs=1e-9)
    assert insensitivity_width(zvd.amplitudes, zvd.times, m.omega, 0.0, level) == pytest.approx(
        4 * math.asin(math.sqrt(level)) / math.pi, abs=1e-9)


@pytest.mark.parametrize("family, zeta", [("zvd", 0.1), ("ei", 0.05), ("3hump_ei", 0.1), ("si", 0.2)])
def test_insensitivity_width_agrees_with_a_dense_scan(family, zeta):
    """Brute force: the run of grid points with V <= 5 % (V_tol humps count as inside)."""
    m = Mode(10.0, zeta)
    s = design(family, [m])
    r = np.linspace(0.0, 5.0, 500001)
    inside = percentage_vibration(s.amplitudes, s.times, r * m.omega, zeta) <= 0.05 * (1 + 1e-6)
    centre = 100000
    out = np.flatnonzero(~inside)
    lo = r[out[out < centre].max()]
    hi = r[out[out > centre].min()] if np.any(out > centre) else 5.0
    assert insensitivity_width(s.amplitudes, s.times, m.omega, zeta) == pytest.approx(hi - lo, abs=2e-5)


def test_insensitivity_width_is_zero_when_the_design_frequency_is_above_the_level():
    m = Mode(10.0, 0.05)
    s = design("none")
    assert insensitivity_width(s.amplitudes, s.times, m.omega, m.zeta) == 0.0
    ei = design("ei", [m], vibration_tolerance=0.1)
    assert insensitivity_width(ei.amplitudes, ei.times, m.omega, m.zeta, level=0.05) == 0.0
    assert insensitivity_width(ei.amplitudes, ei.times, m.omega, m.zeta, level=0.1) > 0.4


@pytest.mark.parametrize("kwargs", [dict(design_omega=0.0), dict(design_omega=float("nan")), dict(zeta=1.0),
                                    dict(level=0.0), dict(level=float("nan"))])
def test_insensitivity_width_rejects_bad_arguments(kwargs):
    args = {"design_omega": 1.0, "zeta": 0.0, "level": 0.05, **kwargs}
    with pytest.raises(ValueError):
        insensitivity_width([0.5, 0.5], [0.0, math.pi], **args)
