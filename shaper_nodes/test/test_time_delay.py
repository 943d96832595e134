"""Seed 001: the time-delay feedback controller's stability analysis against an independent check."""

import math

import numpy as np
import pytest

from shaper_nodes.core.time_delay import (
    TimeDelayError,
    assumed_frequency_range,
    change_points,
    characteristic,
    controller_response,
    exact_step_response,
    g_ff,
    growth_rate,
    ppusmd_gains,
    stable_interval,
)

WA = 3.0
T = math.pi / (3 * WA)


def test_gains_sum_to_one_and_cancel_the_assumed_mode():
    for t in (0.2, T, 0.5, 1.7, 3.0):
        a0, a1, a2 = ppusmd_gains(WA, t)
        assert a0 + a1 + a2 == pytest.approx(1.0)
        assert a0 == a2
        assert abs(g_ff(1j * WA, WA, t)) < 1e-12


def test_paper_gains_at_t_pi_over_3wa():
    # cos(w_A T) = 1/2: A0 = A2 = 1, A1 = -1 (step response reaches 1 at 2T without overshoot)
    assert ppusmd_gains(WA, T) == pytest.approx((1.0, -1.0, 1.0))


def test_gains_undefined_at_multiples_of_two_pi():
    with pytest.raises(TimeDelayError, match="multiple of 2 pi"):
        ppusmd_gains(WA, 2 * math.pi / WA)
    with pytest.raises(TimeDelayError, match="w_A"):
        ppusmd_gains(float("nan"), T)
    with pytest.raises(TimeDelayError, match="delay T"):
        ppusmd_gains(WA, -1.0)


def test_change_points_are_roots_of_the_characteristic_equation():
    for t in (T, 0.5, 1.3, 2.5):
        for x in change_points(WA, t, 12):
            f = characteristic(1j * x.phi, WA, t, x.omega_r)
            scale = abs(x.phi) ** 4 + x.omega_r**2 * WA**2
            assert abs(f) < 1e-9 * scale, (t, x)


def test_controller_is_the_imc_structure():
    s = np.array([0.3 + 2j, 1j * 7.0, 2.0 + 0.5j])
    g = g_ff(s, WA, T)
    assert np.allclose(controller_response(s, WA, T), g / (1 - g * WA**2 / (s**2 + WA**2)))


@pytest.mark.parametrize("t", [T, 0.5, 0.8, 1.2, 2.5])
def test_stable_interval_edges_agree_with_the_sampled_data_loop(t):
    """Just inside the interval of eq. (27) the sampled-data loop decays, just outside it grows."""
    si = stable_interval(WA, t)
    assert si.lower == WA and si.upper > WA
    n = 100
    assert growth_rate(WA, t, 1.03 * si.lower, n) < 0
    assert growth_rate(WA, t, 0.97 * si.lower, n) > 0
    assert growth_rate(WA, t, 0.98 * si.upper, n) < 0
    assert growth_rate(WA, t, 1.02 * si.upper, n) > 0


def test_paper_cases():
    si = stable_interval(WA, T)
    assert si.upper_k == 1 and si.upper == pytest.approx(5.0455, abs=1e-4)
    assert growth_rate(WA, T, 4.0, 100) < 0   # Fig. 8: stable
    assert growth_rate(WA, T, 2.9, 100) > 0   # Fig. 9: unstable


def test_selection_rules_give_a_stable_design():
    wr, t = 3.0, 0.5  # Fig. 6
    ranges = assumed_frequency_range(wr, t)
    assert ranges and all(r.low <= r.high <= wr for r in ranges)
    for r in ranges:
        wa = 0.5 * (r.low + r.high) if r.low > 0 else 0.9 * r.high
        si = stable_interval(wa, t)
        assert si.lower <= wr <= si.upper
        assert growth_rate(wa, t, wr, 100) < 0


def test_exact_step_response_matched_model_is_the_shaped_step():
    """w_R = w_A: the loop is the feedforward shaper; the exact response is at 1 from 2T on, no overshoot."""
    t = math.pi / (3 * WA)
    r = exact_step_response(WA, t, WA, intervals=8)
    assert r.overshoot <= 1e-12
    assert np.abs(r.y[r.t >= 2 * t - 1e-12] - 1.0).max() < 1e-12
    assert r.y[r.t < 2 * t - 0.02].max() < 1.0 - 1e-4  # and not before


def test_exact_step_response_peak_and_input_errors():
    r = exact_step_response(WA, math.pi / (3 * WA), 4.0)
    # the peak is a stationary point of the exact solution, above every grid value
    assert r.peak >= r.y.max() - 1e-15
    assert r.t[0] <= r.peak_time <= r.t[-1]
    # more intervals do not move a peak that lies in the first ones
    assert exact_step_response(WA, math.pi / (3 * WA), 4.0, intervals=40).peak == pytest.approx(r.peak, abs=1e-13)
    for bad in ({"omega_r": 0.0}, {"omega_r": math.nan}, {"intervals": 0}):
        kw = {"omega_a": WA, "delay": 0.3, "omega_r": 4.0, **bad}
        with pytest.raises(TimeDelayError):
            exact_step_response(**kw)
