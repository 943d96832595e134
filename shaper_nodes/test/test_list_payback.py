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
    paying_factor,
    predicted_residual,
    time_cost,
)
from shaper_nodes.core.shaping import Mode, design

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
