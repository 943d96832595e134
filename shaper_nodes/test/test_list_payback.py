"""A factor over a move's base shaper chosen to pay: its time cost predicted from the command alone, its residual
from the components identified (core/learning/list/payback.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.learning.list import ListError, ListParams
from shaper_nodes.core.learning.list.payback import (
    Component,
    component_energy,
    components,
    paying_factor,
    predicted_residual,
    settle_crossing,
    time_cost,
)
from shaper_nodes.core.shaping import Mode, design
from shaper_nodes.core.shaping.vibration import settle_time

RATE = 500.0
TOL = 5e-5  # rad


def _ramp(distance: float = 1.0, duration: float = 1.0,
          step: float = 0.01) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth one-joint move (a cycloid): times, positions (N, 1), velocities (N, 1)."""
    t = np.arange(0.0, duration + step / 2, step)
    u = t / duration
    p = distance * (u - np.sin(2 * math.pi * u) / (2 * math.pi))
    v = distance / duration * (1 - np.cos(2 * math.pi * u))
    return t, p[:, None], v[:, None]


def test_a_zero_vibration_pair_cancels_its_component_and_leaves_the_others():
    ring = Component(2 * math.pi * 10.0, 0.03, 0.01)
    other = Component(2 * math.pi * 25.0, 0.05, 0.005)
    zv = ListParams.from_mode(Mode(ring.omega, ring.zeta))
    assert predicted_residual([ring], zv) < 1e-12
    assert predicted_residual([ring, other], zv) == pytest.approx(predicted_residual([other], zv), rel=1e-9)
    assert predicted_residual([ring, other], None) == pytest.approx(
        math.sqrt(component_energy(ring) + component_energy(other)))
    # a decaying sinusoid's mean square over the window: amplitude^2 / 2 when it does not decay
    assert component_energy(Component(10.0, 0.0, 2.0)) == pytest.approx(2.0)


def test_the_time_cost_grows_with_the_late_impulse_and_is_nothing_for_the_identity():
    t, p, v = _ramp()
    base = design("zv", [Mode(2 * math.pi * 12.0, 0.03)])
    full = time_cost(t, p, v, base, ListParams.from_mode(Mode(2 * math.pi * 10.0, 0.03)), RATE, TOL)
    partial = time_cost(t, p, v, base, ListParams(0.9, 0.05), RATE, TOL)
    tiny = time_cost(t, p, v, base, ListParams(0.99, 0.002), RATE, TOL)
    # a full pair at 10 Hz costs a good part of its T2 (50 ms), a partial one less, a 2 ms one at most a sample
    assert 0.02 < full <= 0.05 + 1 / RATE
    assert 0.0 < partial < full
    assert abs(tiny) <= 1 / RATE + 1e-12
    # with no base the cost is the pair's own against the unshaped move
    assert time_cost(t, p, v, None, ListParams.from_mode(Mode(2 * math.pi * 10.0, 0.03)), RATE, TOL) > 0.02


def test_the_chosen_factor_is_the_least_residual_within_the_time_allowed():
    ring = Component(2 * math.pi * 10.0, 0.03, 0.01)
    other = Component(2 * math.pi * 25.0, 0.05, 0.002)

    def cost(p: ListParams) -> float:  # a stand-in: the late impulse's share of its delay
        return p.a2 * p.t2

    roomy = paying_factor([ring, other], cost, 1.0)
    assert roomy is not None and roomy.full and roomy.component == ring  # the most residual, fully cancelled
    assert roomy.params == ListParams.from_mode(Mode(ring.omega, ring.zeta))
    assert roomy.cost_s == pytest.approx(cost(roomy.params))
    tight = paying_factor([ring, other], cost, 0.004)
    assert tight is not None and not tight.full  # a partial pair: what the time allows
    assert tight.cost_s <= 0.004 and tight.predicted < 0.95 * tight.without
    assert tight.predicted > roomy.predicted
    # T2 stays within the band of the component it was designed on
    zv = ListParams.from_mode(Mode(tight.component.omega, tight.component.zeta))
    assert zv.t2 / 1.1 - 1e-12 <= tight.params.t2 <= zv.t2 / 0.9 + 1e-12
    # a pair on a mode delays a heavily damped component's response past its decay: not chosen over one on it
    loop = Component(2 * math.pi * 50.0, 0.6, 0.5)
    on_loop = paying_factor([ring, loop], cost, 1.0)
    assert on_loop is not None and on_loop.component == loop
    # nothing predicted to lower the residual enough within the time: no factor
    assert paying_factor([ring], lambda p: 1.0, 0.01) is None
    assert paying_factor([], cost, 1.0) is None


def test_bad_components_and_tolerances_are_refused_by_name():
    with pytest.raises(ListError, match="omega"):
        Component(float("nan"), 0.1, 1.0)
    with pytest.raises(ListError, match="zeta"):
        Component(10.0, 1.0, 1.0)
    with pytest.raises(ListError, match="amplitude"):
        Component(10.0, 0.1, -1.0)
    t, p, v = _ramp()
    with pytest.raises(ListError, match="tolerance"):
        time_cost(t, p, v, None, ListParams(0.9, 0.01), RATE, 0.0)


def _decays(t: np.ndarray, parts: list[tuple[float, float, float]]) -> np.ndarray:
    """A sum of damped sinusoids (Hz, zeta, amplitude m/s^2) from t = 0, (N, 1)."""
    y = np.zeros_like(t)
    for hz, zeta, amp in parts:
        w = 2 * math.pi * hz
        y += amp * np.exp(-zeta * w * t) * np.sin(w * math.sqrt(1 - zeta**2) * t + 0.3)
    return y[:, None]


def test_the_loops_transient_is_found_beside_the_modes_that_ring_that_fill_a_fit():
    t = np.arange(-0.2, 1.2, 1 / RATE)
    ring, loop = (10.0, 0.03, 0.01), (50.0, 0.5, 0.06)  # a mode that rings; the loop's transient, a few ms long
    y = np.where(t[:, None] >= 0, _decays(np.maximum(t, 0), [ring, loop]), 0.0)
    # a fit of one mode is filled by the mode that rings: the transient is not among the components
    plain = components(t, y, 0.0, 0.12, max_modes=1)
    assert [round(c.hz) for c in plain] == [10]
    # one more mode from the commanded end finds it, damped as it is; the mode that rings is not found twice
    more = components(t, y, 0.0, 0.12, max_modes=1, extra_damped=1)
    assert len(more) == 2 and more[0] == plain[0]
    found = more[1]
    assert found.hz == pytest.approx(50.0, rel=0.02) and found.zeta == pytest.approx(0.5, abs=0.03)
    assert found.amplitude == pytest.approx(0.06, rel=0.1)
    # its zero-vibration pair is predicted to cancel it, leaving the mode that rings
    zv = ListParams.from_mode(Mode(found.omega, found.zeta))
    assert predicted_residual(more, zv) == pytest.approx(predicted_residual(plain, None), rel=0.05)
    with pytest.raises(ListError, match="extra_damped"):
        components(t, y, 0.0, 0.12, max_modes=3, extra_damped=6)


def test_the_settling_between_samples_is_the_crossing_of_the_band_and_never_before_the_sampled_one_less_a_sample():
    t = np.arange(0.0, 1.0, 0.002)
    # two joints decaying to their goals; the slower one crosses the band between samples
    p = np.stack([np.exp(-t / 0.05), 0.5 * np.exp(-t / 0.1)], axis=1)
    tol = 1e-3
    exact = 0.1 * math.log(0.5 / (tol + p[-1, 1]))  # the slow joint's crossing of the band about its last value, s
    got = settle_crossing(t, p, 0.0, tol)
    assert got == pytest.approx(exact, abs=2e-4)
    sampled = settle_time(t, p, 0.0, tol)
    assert sampled - 0.002 <= got <= sampled
    assert settle_crossing(t, p, 0.9, tol) == 0.9  # not before ``after``
    assert settle_crossing(t, np.zeros((t.size, 2)), 0.3, tol) == 0.3  # nothing outside the band


def test_the_interpolated_time_cost_is_the_sampled_one_to_a_sample_and_not_rounded():
    t, p, v = _ramp()
    base = design("zv", [Mode(2 * math.pi * 12.0, 0.03)])
    for pair in (ListParams(0.9, 0.05), ListParams.from_mode(Mode(2 * math.pi * 10.0, 0.03)), ListParams(0.97, 0.01)):
        sampled = time_cost(t, p, v, base, pair, RATE, TOL)
        fine = time_cost(t, p, v, base, pair, RATE, TOL, interpolate=True)
        assert abs(fine - sampled) < 1 / RATE + 1e-12
    costs = [time_cost(t, p, v, base, ListParams(a1, 0.05), RATE, TOL, interpolate=True) for a1 in (0.97, 0.95, 0.9)]
    assert costs[0] < costs[1] < costs[2]  # more of the late impulse, a longer wait: not rounded to a sample
