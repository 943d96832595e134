# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""The learner node's set-up of a move (core/learning/mrilc/plan.py, sim_plant_node/arm/lifted.py) is the
reproduction's (reproductions/arm_mrilc.py): the same grid, basis, weights and operator, and the error in the
residual window is the residual as measured, so the node runs the reproduction's law on the same numbers; the
operator predicts the offline arm's response to a B-spline of either family."""

from __future__ import annotations

import numpy as np
import pytest

from reproductions import arm_mrilc
from shaper_nodes.core.learning.mrilc.plan import PlanSettings, plan_move, plan_operator, residual_error
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.lifted import arm_operator
from sim_plant_node.arm.offline import OfflineArm


@pytest.fixture(scope="module")
def plans():
    model = ArmModel()
    rep = arm_mrilc.plan_moves(arm_mrilc.modal_zv(model), model, moves=1)[0]
    mine = plan_move(rep.times, rep.positions, rep.velocities, rep.accelerations, rep.start,
                     PlanSettings(spacing=arm_mrilc.SPACING, tail=arm_mrilc.TAIL, fine_spacing=arm_mrilc.FINE_SPACING,
                                  fine_tail=arm_mrilc.FINE_TAIL, output_period=arm_mrilc.OUTPUT_PERIOD,
                                  skip=arm_mrilc.SKIP, trend_degree=arm_mrilc.TREND_DEGREE))
    return rep, mine


def test_the_plan_and_operator_are_the_reproductions(plans):
    rep, mine = plans
    assert mine.motion_end == rep.motion_end
    np.testing.assert_array_equal(mine.grid, rep.grid)
    np.testing.assert_array_equal(mine.weights, rep.weights)
    for b_rep, b_mine in zip(rep.profile.basis, mine.profile.basis, strict=True):
        np.testing.assert_array_equal(b_mine, b_rep)
    g = plan_operator(mine, arm_operator, rep.positions[-1], 6, arm_mrilc.OUTPUT_PERIOD)
    np.testing.assert_allclose(g, rep.operator, rtol=0, atol=1e-12 * np.max(np.abs(rep.operator)))


def test_the_operator_predicts_the_arms_response_to_a_fine_and_a_coarse_b_spline(plans):
    """A column of G against the offline arm's measured response to that one B-spline (the goal pose's
    linearisation, no extra delay): in the residual window they correlate 0.98 or more."""
    rep, mine = plans
    nb = mine.count
    coarse = mine.families[0].count

    def run(c):
        arm = OfflineArm(rep.start, arm_mrilc.RATE)
        dq, dv, da = rep.profile.correction(c)
        s = arm.run(rep.times, rep.positions + dq, rep.velocities + dv, rep.accelerations + da)
        it, imu = arm.record.window("imu", s, s + float(rep.times[-1]))
        return np.column_stack([np.interp(rep.grid, it - s, imu[:, i]) for i in range(3)])

    base = run(np.zeros((nb, 6)))
    w = mine.weights[::3] > 0
    for i in (coarse - 2, nb - 1):  # a 40 ms B-spline and the last 4 ms one, on the shoulder
        c = np.zeros((nb, 6))
        c[i, 1] = 1e-6
        measured = ((run(c) - base) / 1e-6)[w].ravel()
        model = rep.operator[:, nb + i].reshape(-1, 3)[w].ravel()
        assert np.corrcoef(measured, model)[0, 1] > 0.97


def test_the_error_in_the_residual_window_is_the_measured_residual(plans):
    rep, mine = plans
    rng = np.random.default_rng(1)
    t = 1e-3 * np.arange(1, int(rep.grid[-1] / 1e-3) + 2)
    y = 9.81 + 0.01 * rng.standard_normal((t.size, 3))
    got = residual_error(mine, t, y, arm_mrilc.TREND_DEGREE).reshape(-1, 3)
    w = mine.weights[::3] > 0
    on_grid = np.column_stack([np.interp(mine.grid, t, y[:, i]) for i in range(3)])[w]
    # the rigid reference is at rest in the window: the error there is the samples less their mean
    np.testing.assert_allclose(got[w], -(on_grid - on_grid.mean(axis=0)), atol=1e-12)
