"""Seed 004's two-mass system: integration, equilibrium, and the TS model's modes against it."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reproductions.scheduler_rules import rule_base_spec
from shaper_nodes.core.identification.modes import identify
from shaper_nodes.core.scheduling.fuzzy import rule_base_from_dict
from sim_plant_node.models.two_mass import (
    C0,
    M0,
    STEP_LEVELS,
    STEP_POSES,
    C,
    K,
    StaircaseTask,
    TwoMassPlant,
    m1_of,
)


def eq1(t, s, f):
    """Seed 004 eq. (1) as written, state (x0, x0', x1, x1'), force f, m1 = 10 x0 + 1."""
    x0, x0d, x1, x1d = s
    spring = K * (x0 - x1) + C * (x0d - x1d)
    return [x0d, (f - spring - C0 * x0d) / M0, x1d, spring / m1_of(x0)]


def test_integration_matches_an_adaptive_solver_of_eq1():
    rate = 50.0
    plant = TwoMassPlant(1, rate)
    plant.reset(0.0)
    v = np.concatenate([np.full(20, 3.0), np.linspace(3.0, 12.0, 200), np.full(300, 12.0)])
    s = np.zeros(4)
    v_prev = 0.0
    worst = 0.0
    for vk in v:
        plant.step([vk])
        f = (vk - v_prev) * rate  # the command ramps over the period: f = dv/dt is constant
        s = solve_ivp(eq1, (0, 1 / rate), s, args=(f,), method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
        v_prev = vk
        got = [plant.base_position[0], plant.base_velocity[0], plant.tip_position[0], plant.tip_velocity[0]]
        worst = max(worst, float(np.max(np.abs(np.array(got) - s))))
    assert worst < 1e-7 * 0.4  # peak positions ~0.4 m


def test_rest_under_a_velocity_command_is_close_to_v_over_c0():
    plant = TwoMassPlant(2, 50.0)
    plant.reset([0.0, 3.0])
    assert plant.base_position.tolist() == [0.0, 0.1] and plant.tip_position.tolist() == [0.0, 0.1]
    for _ in range(50 * 400):
        plant.step([STEP_LEVELS[2], STEP_LEVELS[4]])
    # v / c0 exactly for a constant m1; m1(x0) changing on the way (m1 x1'' is not d(m1 x1')/dt)
    # leaves a small offset that depends on the path
    np.testing.assert_allclose(plant.base_position, [STEP_POSES[2], STEP_POSES[4]], rtol=0.01)
    np.testing.assert_allclose(plant.tip_position, plant.base_position, atol=2e-4)  # still ringing a little


def test_ts_modes_match_the_plants_free_vibration_at_the_operating_points():
    """The interpolated model's mode at each operating point against the mode identified from the
    nonlinear plant's free vibration there (x1 released 1 mm off x0, so m1 stays put)."""
    base = rule_base_from_dict(rule_base_spec(np.linspace(0.0, 0.7, 5), with_modes=False))
    rate = 10.0
    for x in np.linspace(0.0, 0.7, 5):
        (mode,) = base.evaluate([x]).modes
        plant = TwoMassPlant(1, rate)
        plant.reset(C0 * x)
        plant.state[0, 2] += 1e-3
        t = np.arange(1, int(120 * rate) + 1) / rate
        acc = []
        for _ in t:
            plant.step([C0 * x])
            acc.append(plant.tip_acceleration[0])
        (fit,) = identify(t, np.array(acc), max_modes=1)
        assert mode.omega == pytest.approx(fit.omega, rel=2e-3), x
        assert mode.zeta == pytest.approx(fit.zeta, rel=0.03), x


def test_staircase_task_events_and_levels():
    task = StaircaseTask([0.0], [1.0, 2.0], dwell=0.1, rate=50.0)
    out = [task.step() for _ in range(10)]
    assert task.done and task.cycles == 2
    assert [c[0] for c, _ in out] == [1.0] * 5 + [2.0] * 5
    kinds = [(e.kind, e.cycle) for _, evs in out for e in evs]
    assert kinds == [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)]
    with pytest.raises(ValueError, match="finite"):
        StaircaseTask([0.0], [1.0, float("nan")], 1.0, 50.0)
