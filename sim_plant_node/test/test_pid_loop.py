"""The mck_pid plant (seed 000's loop) against the MRILC core's sampled model."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.learning.mrilc import model as M
from sim_plant_node.models.pid_loop import PidLoopPlant
from sim_plant_node.models.plants import mck_from_mode

RATE = 200.0


def _run(plant, r, u2):
    y, u = [], []
    for k in range(r.size):
        y.append(plant.base_position[0])
        plant.feedforward = np.array([u2[k]])
        plant.step([r[k]], k / RATE)
        u.append(plant.effort[0])
    return np.array(y), np.array(u)


@pytest.mark.parametrize("mode", [(10.0, 0.3), (5.0, 0.15), (15.0, 0.45)])
def test_loop_matches_the_sampled_model(mode):
    plant = PidLoopPlant(*([v] for v in mck_from_mode(*mode)), RATE)
    plant.reset([0.5])
    assert plant.base_position[0] == pytest.approx(0.5) and plant.effort[0] == pytest.approx(0.5)
    assert plant.tip_acceleration[0] == pytest.approx(0.0, abs=1e-9)
    rng = np.random.default_rng(3)
    r = 0.5 + np.repeat(rng.uniform(-1, 1, 8), 10)
    u2 = rng.normal(0, 0.1, r.size)
    y, _ = _run(plant, r, u2)
    c, p = M.controller(), M.mck_plant(*mode)
    t = M.SampledFilter(M.zoh_sampled(M.learning_path(c, p, "command"), 1 / RATE))
    h = M.SampledFilter(M.zoh_sampled(M.learning_path(c, p, "effort"), 1 / RATE))
    expected = 0.5 + t(r - 0.5) + h(u2)
    assert np.max(np.abs(y - expected)) < 1e-9


def test_unstable_loop_and_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="does not stabilise"):
        PidLoopPlant([1.0], [0.63], [987.0], RATE)  # 5 Hz, 1 % damped: the paper's PID cannot hold it
    with pytest.raises(ValueError, match="controller"):
        PidLoopPlant([1.0], [6.0], [100.0], RATE, [1.0, 1.0, 1.0], [1.0])
    with pytest.raises(ValueError, match="mass > 0"):
        PidLoopPlant([0.0], [6.0], [100.0], RATE)
