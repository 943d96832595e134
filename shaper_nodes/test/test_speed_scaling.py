"""Time-scaling a planned trajectory, its joint-limit check and the tolerance's accelerometer level
(shaper_nodes.core.learning.speed): what the learner node's speed_moves mode applies to each goal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.learning.speed import (
    SpeedError,
    acceleration_tolerance,
    limit_breach,
    limit_ceiling,
    motion_end_index,
    time_scale,
)


def _trapezoid(dist: float = 1.0, vmax: float = 1.0, amax: float = 4.0, dt: float = 0.01, dwell: float = 1.5):
    """A one-joint trapezoid sampled every dt, then a hold point dwell s after its end."""
    ta = vmax / amax
    total = dist / vmax + ta
    t = np.arange(dt, total + dt / 2, dt)
    t[-1] = total

    def pos(x: float) -> float:
        if x < ta:
            return 0.5 * amax * x * x
        if x < total - ta:
            return 0.5 * amax * ta * ta + vmax * (x - ta)
        return dist - 0.5 * amax * (total - x) ** 2

    q = np.array([[pos(x)] for x in t])
    v = np.gradient(q, t, axis=0)
    a = np.gradient(v, t, axis=0)
    t = np.append(t, total + dwell)
    return t, np.vstack([q, q[-1:]]), np.vstack([v, [[0.0]]]), np.vstack([a, [[0.0]]]), total


def test_the_motion_runs_s_times_faster_and_the_dwell_keeps_its_length():
    t, q, v, a, total = _trapezoid()
    st, sv, sa = time_scale(t, q, v, a, 1.6)
    m = motion_end_index(q)
    assert m == len(t) - 2  # the last point is the hold
    assert st[m] == pytest.approx(total / 1.6)
    assert st[-1] - st[m] == pytest.approx(t[-1] - t[m])  # the dwell as planned
    np.testing.assert_allclose(st[: m + 1], t[: m + 1] / 1.6)
    np.testing.assert_allclose(sv, v * 1.6)
    np.testing.assert_allclose(sa, a * 1.6**2)
    assert np.all(np.diff(st) > 0)
    # the same path: q(s t) is the planned q at t; the scaled velocities are the scaled positions' derivative
    np.testing.assert_allclose(np.gradient(q[: m + 1], st[: m + 1], axis=0)[5:-5], sv[5:m - 4], rtol=0.02, atol=1e-3)
    t1, v1, a1 = time_scale(t, q, None, None, 1.0)
    np.testing.assert_array_equal(t1, t)
    assert v1 is None and a1 is None


def test_a_factor_must_be_positive():
    t, q, v, a, _ = _trapezoid()
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(SpeedError, match="factor"):
            time_scale(t, q, v, a, bad)


def test_the_scaled_plan_holds_the_limits_up_to_the_ceiling_and_the_breach_is_named():
    t, q, v, a, _ = _trapezoid(vmax=1.0, amax=4.0)
    vmax, amax = [1.5], [16.0]
    ceiling = limit_ceiling(v, a, vmax, amax)
    assert ceiling == pytest.approx(1.5, rel=0.02)  # the velocity limit binds first (acceleration allows 2)
    st, sv, sa = time_scale(t, q, v, a, ceiling)
    assert limit_breach(st, sv, sa, vmax, amax, ["elbow"]) is None
    st, sv, sa = time_scale(t, q, v, a, ceiling * 1.05)
    why = limit_breach(st, sv, sa, vmax, amax, ["elbow"])
    assert why is not None and why.startswith("joint elbow: velocity") and "above its limit 1.5 rad/s" in why
    assert "\n" not in why


def test_the_tolerance_at_the_flange_is_the_acceleration_of_that_amplitude_at_the_mode():
    # a sinusoid x sin(2 pi f t) has the acceleration amplitude x (2 pi f)^2
    f, x = 10.0, 5e-5
    t = np.linspace(0.0, 1.0, 20001)
    acc = -x * (2 * math.pi * f) ** 2 * np.sin(2 * math.pi * f * t)
    assert acceleration_tolerance(x, f) == pytest.approx(np.max(np.abs(acc)), rel=1e-6)
    assert acceleration_tolerance(5e-5, 10.0) == pytest.approx(0.1974, abs=1e-4)
    with pytest.raises(SpeedError, match="frequency_hz"):
        acceleration_tolerance(5e-5, 0.0)
