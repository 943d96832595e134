# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""The learner node's set-up of a move (core/learning/mrilc/plan.py, sim_plant_node/arm/lifted.py) is the
reproduction's (reproductions/arm_mrilc.py): the same grid, basis, weights and operator, and the same error in the
residual window, so the node runs the reproduction's law on the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from reproductions import arm_mrilc
from shaper_nodes.core.learning.mrilc.plan import PlanSettings, plan_move, residual_error
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.lifted import arm_operator


@pytest.fixture(scope="module")
def plans():
    model = ArmModel()
    rep = arm_mrilc.plan_moves(arm_mrilc.modal_zv(model), model, moves=1)[0]
    mine = plan_move(rep.times, rep.positions, rep.velocities, rep.accelerations, rep.start,
                     PlanSettings(spacing=arm_mrilc.SPACING, tail=arm_mrilc.TAIL, output_period=arm_mrilc.OUTPUT_PERIOD,
                                  skip=arm_mrilc.SKIP, trend_degree=arm_mrilc.TREND_DEGREE))
    return rep, mine


def test_the_plan_and_operator_are_the_reproductions(plans):
    rep, mine = plans
    assert mine.motion_end == rep.motion_end
    np.testing.assert_array_equal(mine.grid, rep.grid)
    np.testing.assert_array_equal(mine.weights, rep.weights)
    for b_rep, b_mine in zip(rep.profile.basis, mine.profile.basis, strict=True):
        np.testing.assert_array_equal(b_mine, b_rep)
    g = arm_operator(rep.positions[-1], mine.count, mine.grid.size, mine.first, arm_mrilc.SPACING,
                     arm_mrilc.OUTPUT_PERIOD)
    np.testing.assert_allclose(g, rep.operator, rtol=0, atol=1e-12 * np.max(np.abs(rep.operator)))


def test_the_error_in_the_residual_window_is_the_reproductions(plans):
    rep, mine = plans
    rng = np.random.default_rng(1)
    t = 1e-3 * np.arange(1, int(rep.grid[-1] / 1e-3) + 2)
    y = np.interp(t, rep.grid, rep.reference[:, 0])[:, None] + 0.01 * rng.standard_normal((t.size, 3))
    want = arm_mrilc.tracking_error(rep, np.column_stack([np.interp(rep.grid, t, y[:, i]) for i in range(3)]))
    got = residual_error(mine, t, y, arm_mrilc.TREND_DEGREE)
    w = rep.weights > 0
    # the rigid reference is at rest after the motion (a constant the trend absorbs; 1e-9 m/s^2: its rounding)
    np.testing.assert_allclose(got[w], want[w], atol=1e-9)
