# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""A move's MRILC set-up from its commanded profile (core/learning/mrilc/plan.py): the motion end, the grid, the
basis inside the tail of the motion, the weights, the error with its trend taken out, the limit named."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.learning.mrilc.model import MrilcError
from shaper_nodes.core.learning.mrilc.plan import (
    PlanSettings,
    limit_breach,
    motion_end,
    plan_move,
    plan_operator,
    residual_error,
)
from shaper_nodes.core.learning.mrilc.profile import JointLimits

PERIOD = 2e-3


def profile(duration: float = 0.8, dwell: float = 1.5, joints: int = 2):
    """A smooth rest-to-rest move of ``joints`` joints (0 -> 1 rad), points every 2 ms, then held."""
    t = PERIOD * np.arange(1, int(round((duration + dwell) / PERIOD)) + 1)
    s = np.clip(t / duration, 0.0, 1.0)
    q1 = 10 * s**3 - 15 * s**4 + 6 * s**5
    v1 = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration * (t <= duration)
    a1 = (60 * s - 180 * s**2 + 120 * s**3) / duration**2 * (t <= duration)
    rep = np.ones((1, joints))
    return t, q1[:, None] * rep, v1[:, None] * rep, a1[:, None] * rep


def test_the_plan_places_the_basis_in_the_tail_of_the_motion():
    t, q, v, a = profile()
    plan = plan_move(t, q, v, a, np.zeros(2))
    assert plan.motion_end == pytest.approx(0.8, abs=PERIOD)
    s = PlanSettings()
    out = s.output_period
    assert plan.grid[0] == pytest.approx(out) and plan.grid[-1] == pytest.approx(plan.motion_end + 1.0, abs=out)
    coarse, fine = plan.families
    assert coarse.count == int(round(s.tail / s.spacing)) - 3 and coarse.spacing == s.spacing
    assert fine.count == int(round(s.fine_tail / s.fine_spacing)) - 3 and fine.spacing == s.fine_spacing
    assert plan.count == coarse.count + fine.count and plan.profile.basis[0].shape[1] == plan.count
    assert plan.first == coarse.first == int(round((plan.motion_end - s.tail) / out))
    assert fine.first == int(round((plan.motion_end - s.fine_tail) / out))
    b0, b1, b2 = plan.profile.basis
    support = np.any(b0 != 0, axis=1)
    assert t[support].min() > plan.motion_end - s.tail - 1e-9 and t[support].max() < plan.motion_end + 1e-9
    fine_support = np.any(b0[:, coarse.count:] != 0, axis=1)
    assert t[fine_support].min() > plan.motion_end - s.fine_tail - 1e-9
    assert len(plan_move(t, q, v, a, np.zeros(2), PlanSettings(fine_tail=0.0)).families) == 1
    # the correction and its first two derivatives vanish at the motion's end: the goal and timing stay
    end = np.searchsorted(t, plan.motion_end)
    assert np.all(b0[end:] == 0) and np.all(b1[end:] == 0) and np.all(b2[end:] == 0)
    w = plan.weights.reshape(-1, 3)
    assert np.all(w[plan.grid < plan.motion_end + s.skip] == 0) and np.all(w[plan.grid >= plan.motion_end + s.skip]
                                                                            == 1)


def test_the_operator_is_assembled_per_family_in_the_learners_order():
    t, q, v, a = profile()
    plan = plan_move(t, q, v, a, np.zeros(2))
    calls = []

    def provider(goal, count, samples, first, spacing, period):
        calls.append((count, samples, first, spacing, period))
        # column j * count + i of the family holds the marker (family spacing, joint, index)
        g = np.zeros((samples * 3, count * 2))
        for j in range(2):
            for i in range(count):
                g[0, j * count + i] = 1000 * spacing + 10 * j + i / 100
        return g

    g = plan_operator(plan, provider, [1.0, 1.0], 2, plan.grid[0])
    assert len(plan.families) == 2
    assert calls == [(f.count, plan.grid.size, f.first, f.spacing, plan.grid[0]) for f in plan.families]
    want = [1000 * f.spacing + 10 * j + i / 100 for j in range(2) for f in plan.families for i in range(f.count)]
    np.testing.assert_allclose(g[0], want)
    with pytest.raises(MrilcError, match="finite values expected"):
        plan_operator(plan, lambda *args: np.zeros((3, 3)), [1.0, 1.0], 2, plan.grid[0])


def test_the_error_is_the_residual_vibration_without_its_trend():
    t, q, v, a = profile()
    plan = plan_move(t, q, v, a, np.zeros(2))
    ts = 1e-3 * np.arange(0, int((plan.grid[-1] + 0.01) / 1e-3))
    rel = ts - plan.motion_end
    gravity_and_drift = np.column_stack([0.0 * ts + 9.81, 0.02 * rel, 0.01 * rel**2])
    ring = 0.05 * np.exp(-rel.clip(0) * 3) * np.sin(2 * np.pi * 8 * rel) * (rel > 0)
    e = residual_error(plan, ts, gravity_and_drift + ring[:, None], 2).reshape(-1, 3)
    rest = plan.weights[::3] > 0
    want = -np.interp(plan.grid, ts, ring)
    # with degree 2 the constant and the quadratic drift are gone; the ring stays (less what a quadratic fit over
    # the window, which starts where the ring is largest, takes of it)
    assert np.max(np.abs(residual_error(plan, ts, gravity_and_drift, 2)[plan.weights > 0])) < 1e-9
    assert np.corrcoef(e[rest, 0], want[rest])[0, 1] > 0.97
    # by default (degree 0) the error in the window is the residual as measured: the samples less their mean
    y = gravity_and_drift + ring[:, None]
    e0 = residual_error(plan, ts, y).reshape(-1, 3)
    on_grid = np.column_stack([np.interp(plan.grid, ts, y[:, i]) for i in range(3)])[rest]
    np.testing.assert_allclose(e0[rest], -(on_grid - on_grid.mean(axis=0)), atol=1e-12)
    with pytest.raises(MrilcError, match="do not cover"):
        residual_error(plan, ts[: ts.size // 2], gravity_and_drift[: ts.size // 2])


def test_a_breach_names_the_joint_and_the_limit():
    _, q, v, a = profile()
    lim = JointLimits(np.full(2, -6.0), np.full(2, 6.0), np.full(2, 10.0), np.full(2, 100.0))
    assert limit_breach(q, v, a, lim, ["j1", "j2"]) is None
    v2 = v.copy()
    v2[10, 1] = 12.0
    assert limit_breach(q, v2, a, lim, ["j1", "j2"]) == "j2 velocity 12 above its limit 10"
    assert limit_breach(q - 7.0, v, a, lim).startswith("joint 0 position -7 below its minimum -6")
    # a profile already past a limit: only what the correction adds beyond it counts
    assert limit_breach(q, v2, a, lim, base=(q, v2, a)) is None
    v3 = v2.copy()
    v3[10, 1] = 12.5
    assert limit_breach(q, v3, a, lim, ["j1", "j2"], base=(q, v2, a)) == "j2 velocity 12.5 above its limit 12"


def test_bad_profiles_are_refused_with_the_reason():
    t, q, v, a = profile()
    with pytest.raises(MrilcError, match="points of 2 joints"):
        plan_move(t, q[:, :1], v, a, np.zeros(2))
    with pytest.raises(MrilcError, match="increasing"):
        plan_move(t[::-1], q, v, a, np.zeros(2))
    with pytest.raises(MrilcError, match="too short"):
        plan_move(*profile(0.05, 1.5), np.zeros(2))
    assert motion_end([0.0, 1.0, 2.0], [[0.0], [1.0], [1.0]]) == 1.0
