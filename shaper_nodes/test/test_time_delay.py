"""Seed 001: the time-delay feedback controller's stability analysis against an independent check."""

import math

import numpy as np
import pytest

from shaper_nodes.core.closed_loop.time_delay import (
    TimeDelayError,
    assumed_frequency_range,
    change_points,
    characteristic,
    controller_response,
    exact_step_response,
    g_ff,
    growth_rate,
    overshoot_interval,
    ppusmd_gains,
    stable_interval,
    step_performance,
    step_response_with_horizon,
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


# ------------------------------------------------------------------------------------------------
# overshoot and settling: checked against an independent simulation and a closed form


def zoh_step_overshoot(wa, t_delay, wr, per_delay, horizon):
    """Overshoot (fraction) of the loop's unit step by a plain sampled simulation, written here without the
    module: plant and internal model discretised exactly under a zero-order hold of u (scipy), delays of
    ``per_delay`` samples, v = 1 - y + yhat, u_k = A0 v_k + A1 v_{k-N} + A2 v_{k-2N} with eqs. (9)-(11)."""
    from scipy.signal import cont2discrete

    dt = t_delay / per_delay
    c = math.cos(wa * t_delay)
    a0 = 1.0 / (2.0 * (1.0 - c))
    a1 = -2.0 * c * a0

    def disc(w):
        ad, bd, *_ = cont2discrete((np.array([[0.0, 1.0], [-w * w, 0.0]]), np.array([[0.0], [w * w]]),
                                    np.eye(2), np.zeros((2, 1))), dt, method="zoh")
        return ad, bd[:, 0]

    # the recursion on Python floats (numpy's calls on 2-vectors cost more than the arithmetic)
    (ap, bp), (am, bm) = disc(wr), disc(wa)
    p00, p01, p10, p11 = (float(c) for c in ap.ravel())
    m00, m01, m10, m11 = (float(c) for c in am.ravel())
    bp0, bp1, bm0, bm1 = float(bp[0]), float(bp[1]), float(bm[0]), float(bm[1])
    steps = int(round(horizon / dt))
    v = [0.0] * (steps + 1)
    x0 = x1 = z0 = z1 = 0.0
    peak = 0.0
    n, n2 = per_delay, 2 * per_delay
    for k in range(steps + 1):
        if x0 > peak:
            peak = x0
        vk = v[k] = 1.0 - x0 + z0
        u = a0 * vk + (a1 * v[k - n] if k >= n else 0.0) + (a0 * v[k - n2] if k >= n2 else 0.0)
        x0, x1 = p00 * x0 + p01 * x1 + bp0 * u, p10 * x0 + p11 * x1 + bp1 * u
        z0, z1 = m00 * z0 + m01 * z1 + bm0 * u, m10 * z0 + m11 * z1 + bm1 * u
    return peak - 1.0


def independent_overshoot(wa, t_delay, wr, per_delay=1000, horizon=None):
    """The hold adds overshoot at first order in the step (docs/design/closed_loop.md); Richardson extrapolation of
    two step sizes removes it."""
    horizon = horizon or max(40 * t_delay, 15.0)
    coarse = zoh_step_overshoot(wa, t_delay, wr, per_delay, horizon)
    fine = zoh_step_overshoot(wa, t_delay, wr, 2 * per_delay, horizon)
    return 2.0 * fine - coarse


def test_independent_simulation_agrees_with_the_exact_overshoot():
    """The test's own tool first: at w_R = 4 it reproduces the method of steps (which has its own tests)."""
    exact = exact_step_response(WA, T, 4.0).overshoot
    assert independent_overshoot(WA, T, 4.0) == pytest.approx(exact, abs=1e-5)


@pytest.fixture(scope="module")
def paper_interval():
    """Seed 001's 20 % overshoot interval on the default grid, computed once for the module's two tests that
    read it (41 exact step responses and Brent's refinement: 30 s of CPU at a load average of 10)."""
    return overshoot_interval(WA, T, 0.20)


def test_overshoot_interval_for_the_paper_case_20_percent(paper_interval):
    """Seed 001's w_A = 3, T = pi/(3 w_A): the 20 % interval starts at w_R = w_A (no overshoot there) and
    ends where the overshoot reaches 20 %, which lies between the paper's w_R = 3.9 (inside) and its
    w_R = 4 (outside: 'stays within 20 %' does not hold for the exact loop)."""
    oi = paper_interval
    (seg,) = oi.segments
    assert (seg.low, seg.low_edge, seg.high_edge) == (WA, "stability", "overshoot")
    assert 3.9 < seg.high < 4.0
    assert all(c != "unknown" for *_, c in oi.scan)
    # the paper's plants, by the independent simulation: 3.9 meets 20 %, 4 does not
    assert independent_overshoot(WA, T, 3.9) < 0.20 < independent_overshoot(WA, T, 4.0)
    # the edge, by the independent simulation: just inside (0.3 % lower) below 20 %, just outside above
    assert independent_overshoot(WA, T, 0.997 * seg.high) < 0.20 < independent_overshoot(WA, T, 1.003 * seg.high)


def test_overshoot_interval_without_monotonicity():
    """T = 2.5 s (w_A T = 7.5 rad): the overshoot first falls, then rises with w_R (its largest peak moves
    from the first to the third interval of T), so a 51.5 % limit is met only on an inner sub-interval
    with two overshoot edges; both check out against the independent simulation."""
    t = 2.5
    oi = overshoot_interval(WA, t, 0.515)
    (seg,) = oi.segments
    assert (seg.low_edge, seg.high_edge) == ("overshoot", "overshoot")
    assert oi.interval.lower < seg.low < seg.high < oi.interval.upper
    lows = [lo for w, lo, _, c in oi.scan]
    assert lows[1] > lows[2] and lows[-2] > lows[2]  # not monotonic on the scan itself
    d = 0.002 * (seg.high - seg.low) + 1e-4
    sim = {w: independent_overshoot(WA, t, w, per_delay=2000, horizon=20 * t)
           for w in (seg.low - d, seg.low + d, seg.high - d, seg.high + d)}
    assert sim[seg.low - d] > 0.515 > sim[seg.low + d]
    assert sim[seg.high - d] < 0.515 < sim[seg.high + d]


def test_overshoot_interval_reaches_the_stability_edge_when_the_limit_allows():
    oi = overshoot_interval(WA, 0.8, 0.20)  # the overshoot stays near 15 % up to the upper edge
    (seg,) = oi.segments
    assert (seg.low, seg.high) == (oi.interval.lower, oi.interval.upper)
    assert (seg.low_edge, seg.high_edge) == ("stability", "stability")
    assert overshoot_interval(WA, T, 0.001).segments[0].high < 3.1  # a tight limit: a short interval
    (seg,) = overshoot_interval(WA, T, 5.0).segments  # a loose one: the whole stable interval
    assert seg.high == oi.interval.upper or seg.high_edge == "stability"


def test_a_horizon_too_short_to_decide_is_conservative(paper_interval):
    """Capped at a few T (before the peak at about 4 T, and shorter than two periods of w_A), the points
    cannot be decided: they are "unknown", never counted as meeting the limit, and the ends so found are
    named "horizon" and lie inside the interval found with a sufficient horizon."""
    full = paper_interval.segments[0]
    for cap in (2, 4, 8):
        oi = overshoot_interval(WA, T, 0.20, max_intervals=cap)
        assert any(c == "unknown" for *_, c in oi.scan)
        for seg in oi.segments:
            assert full.low <= seg.low <= seg.high <= full.high
            assert "horizon" in (seg.low_edge, seg.high_edge)


def test_settling_time_of_the_matched_loop_is_the_shaped_step_closed_form():
    """w_R = w_A, T = pi/(3 w): y = 1 - cos(w t) on [0, T] and sin(w t - pi/6) on [T, 2T], then 1, so the
    2 % band is entered for good at w t = pi/6 + asin(0.98)."""
    r = exact_step_response(WA, T, WA, intervals=8)
    assert r.settling_time == pytest.approx((math.pi / 6 + math.asin(0.98)) / WA, abs=1e-12)
    r5 = exact_step_response(WA, T, WA, intervals=8, band=0.05)
    assert r5.settling_time == pytest.approx((math.pi / 6 + math.asin(0.95)) / WA, abs=1e-12)
    assert r.peak_captured and r.settled


def test_settling_time_on_a_mismatched_plant_and_not_settled_horizons():
    r = step_response_with_horizon(WA, T, 4.0)
    assert r.settled and r.peak_captured and r.rounding_error < 1e-8
    # the last exit from the band: |y - 1| = band there, inside the band after it and outside just before
    ts = r.settling_time
    assert np.abs(r.y[r.t > ts] - 1.0).max() <= 0.02
    assert np.abs(r.y[(r.t < ts) & (r.t > ts - 0.05)] - 1.0).max() > 0.02
    # a longer horizon changes neither the overshoot nor the settling time
    long = exact_step_response(WA, T, 4.0, intervals=60)
    assert (long.peak, long.settling_time) == pytest.approx((r.peak, ts), abs=1e-10)
    # a horizon too short to settle says so
    short = exact_step_response(WA, T, 4.0, intervals=3)
    assert short.settling_time is None and not short.settled and not short.peak_captured


def test_long_horizons_stop_at_the_rounding_limit():
    """w_A T = 0.3 (gains about 11 and -21): the re-solved history loses accuracy geometrically, so the
    horizon is cut before the estimated rounding error passes 1e-8, and the cut is reported."""
    r = exact_step_response(WA, 0.1, 3.25, intervals=120, max_rounding_error=1e-8)
    assert r.accuracy_limited and r.rounding_error <= 1e-8 and r.horizon < 12.0
    full = exact_step_response(WA, 0.1, 3.25, intervals=round(r.horizon / 0.1))
    assert full.peak == pytest.approx(r.peak, abs=1e-12)


def test_step_performance_paper_cases():
    p4 = step_performance(WA, T, 4.0)
    assert p4.in_stable_interval and p4.growth_rate < 0 and p4.response.overshoot > 0.20
    p29 = step_performance(WA, T, 2.9)
    assert not p29.in_stable_interval and p29.growth_rate > 0


@pytest.mark.parametrize("call, words", [
    (lambda: overshoot_interval(WA, T, 0.0), "overshoot limit"),
    (lambda: overshoot_interval(WA, T, math.nan), "overshoot limit"),
    (lambda: overshoot_interval(WA, T, 0.2, grid=2), "grid"),
    (lambda: overshoot_interval(WA, 2 * math.pi / WA, 0.2), "multiple of 2 pi"),
    (lambda: exact_step_response(WA, T, 4.0, band=0.0), "settling band"),
    (lambda: exact_step_response(WA, T, 4.0, band=1.5), "settling band"),
    (lambda: step_performance(WA, T, -1.0), "w_R"),
    (lambda: step_response_with_horizon(WA, T, 4.0, max_intervals=0), "max_intervals"),
])
def test_bad_input_is_rejected_with_a_clear_message(call, words):
    with pytest.raises(TimeDelayError, match=words):
        call()
