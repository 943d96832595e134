"""Percentage vibration against an independent evaluation, and residual-vibration metrics."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shaper_nodes.core.shaping.families import design
from shaper_nodes.core.shaping.fir import discretize, fir_impulses
from shaper_nodes.core.shaping.types import Mode
from shaper_nodes.core.shaping.vibration import (
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
    y = sum(a * np.exp(-zeta * omega * (t - ti)) * np.sin(wd * (t - ti)) for a, ti in zip(amps, times, strict=True))
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


def _sampled_residual(fir, rate: float, mode: Mode) -> float:
    """Residual amplitude of an oscillator driven through a zero-order hold at ``rate`` by the FIR's
    shaped unit step, over that of the unshaped step: simulated sample by sample (exact discretisation
    of the oscillator, scipy), read from the state after the last tap. Independent of V's formula."""
    from scipy.signal import cont2discrete

    wn, z = mode.omega, mode.zeta
    a = np.array([[0.0, 1.0], [-wn**2, -2 * z * wn]])
    b = np.array([[0.0], [wn**2]])
    ad, bd, *_ = cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), 1.0 / rate, method="zoh")
    n = fir.length + 1

    def transient(u: np.ndarray) -> float:
        x = np.zeros(2)
        for k in range(n):
            x = ad @ x + bd[:, 0] * u[min(k, u.size - 1)]
        # amplitude of the free oscillation about the final value, scaled back to the last tap
        e = x - np.array([1.0, 0.0])
        wd = mode.damped_omega
        amp = math.hypot(e[0], (e[1] + z * wn * e[0]) / wd)
        return amp * math.exp(z * wn * n / rate)

    return transient(np.cumsum(fir.dense())) / transient(np.ones(1))


def test_exact_discretisation_meets_the_conditions_on_the_sample_grid():
    """'exact' leaves the sampled plant exactly the continuous shaper's residual at the design mode
    (zero for the ZV family), where 'split' leaves a floor; taps stay >= 0 and sum to 1."""
    for hz, zeta in ((7.3, 0.05), (12.0, 0.05), (20.0, 0.1)):
        m = Mode.from_hz(hz, zeta)
        for family in ("zv", "zvd", "zvdd", "mzv", "2hump_ei"):
            s = design(family, [m])
            for rate in (125.0, 250.0, 500.0, 1000.0):
                exact, split = discretize(s, rate, "exact"), discretize(s, rate, "split")
                assert abs(exact.gains.sum() - 1.0) < 1e-12 and np.all(exact.gains > 0)
                assert _sampled_residual(exact, rate, m) < 1e-9
                assert percentage_vibration(*fir_impulses(exact, rate), m.omega, m.zeta) < 1e-9
                if _sampled_residual(split, rate, m) > 1e-6:  # split's floor (unless the impulses sit on samples)
                    assert _sampled_residual(exact, rate, m) < 1e-3 * _sampled_residual(split, rate, m)
        for family in ("ei", "3hump_ei", "si"):  # V_tol at the mode by design: kept, not zeroed
            # the residual itself is kept: V times exp(zeta omega t_last) (V is relative to an impulse at
            # the last one, and the FIR's last tap is up to a sample later)
            s = design(family, [m])
            own = float(percentage_vibration(s.amplitudes, s.times, m.omega, m.zeta)) * math.exp(
                m.zeta * m.omega * s.duration)
            a, t = fir_impulses(discretize(s, 500.0, "exact"), 500.0)
            v = float(percentage_vibration(a, t, m.omega, m.zeta)) * math.exp(m.zeta * m.omega * t[-1])
            assert abs(v - own) < 1e-9 * own


def test_exact_zvd_keeps_its_robustness():
    """The ZVD's zero slope is kept too: V of the exact FIR 2 % off the mode is second order, like the
    continuous ZVD's, whereas a FIR meeting only V = 0 would be first order."""
    m = Mode.from_hz(12.0, 0.05)
    s = design("zvd", [m])
    fir = fir_impulses(discretize(s, 250.0, "exact"), 250.0)
    for f in (0.98, 1.02):
        cont = float(percentage_vibration(s.amplitudes, s.times, m.omega * f, m.zeta))
        disc = float(percentage_vibration(*fir, m.omega * f, m.zeta))
        assert abs(disc - cont) < 0.1 * cont


def test_exact_discretisation_refuses_a_rate_too_low_for_the_mode():
    with pytest.raises(ValueError, match=r"exact discretisation of the zvd shaper at 40 Hz .*20 Hz.*use 'split'"):
        discretize(design("zvd", [Mode.from_hz(20.0, 0.05)]), 40.0, "exact")
    with pytest.raises(ValueError, match="use 'split', 'round' or 'exact'"):
        discretize(design("zv", [Mode.from_hz(5.0, 0.05)]), 100.0, "cubic")
    one = discretize(design("none"), 100.0, "exact")
    assert list(one.delays) == [0] and list(one.gains) == [1.0]


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
