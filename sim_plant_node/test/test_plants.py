"""The simulated plant integrates exactly; the task runs its cycles in order."""

import math

import numpy as np
import pytest
from scipy import signal

from shaper_nodes.core.cycles import END, MOTION_END, START
from shaper_nodes.core.shaping.families import Mode, design
from shaper_nodes.core.shaping.fir import StreamingShaper, discretize, fir_impulses
from shaper_nodes.core.shaping.vibration import percentage_vibration
from sim_plant_node.models.plants import CycleTask, MckPlant, mck_from_mode, trapezoid


def simulate(plant, commands):
    tip, acc = [], []
    for u in commands:
        plant.step([u])
        tip.append(plant.tip_position[0])
        acc.append(plant.tip_acceleration[0])
    return np.array(tip), np.array(acc)


def test_matches_an_independent_solver():
    """x2/x1 = (c s + k)/(m s^2 + c s + k) under linear interpolation of the command (lsim)."""
    m, c, k = 2.0, 3.0, 500.0
    rate = 200.0
    plant = MckPlant([m], [c], [k], rate)
    t = np.arange(400) / rate
    u = np.where(t < 0.5, t, 0.5) + 0.1 * np.sin(7 * t)
    u[0] = 0.0
    tip, _ = simulate(plant, u[1:])
    _, y, _ = signal.lsim(signal.lti([c, k], [m, c, k]), u, t, interp=True)
    np.testing.assert_allclose(tip, y[1:], atol=1e-9)


def test_mode_parameters():
    m, c, k = mck_from_mode(2 * math.pi * 5, 0.02, 3.0)
    plant = MckPlant([m], [c], [k], 500.0)
    assert plant.natural_frequency[0] == pytest.approx(2 * math.pi * 5)
    assert plant.damping_ratio[0] == pytest.approx(0.02)


@pytest.mark.parametrize("bad", [dict(mass=[0.0]), dict(stiffness=[-1.0]), dict(damping=[np.nan]),
                                 dict(mass=[1.0, 2.0])])
def test_invalid_parameters(bad):
    args = dict(mass=[1.0], damping=[0.1], stiffness=[10.0]) | bad
    with pytest.raises(ValueError):
        MckPlant(args["mass"], args["damping"], args["stiffness"], 100.0)


def test_shaped_residual_vibration_follows_v():
    """Residual amplitude with a shaper / without = V of the discretised shaper at the true mode."""
    rate, true = 500.0, Mode.from_hz(5.0, 0.01)
    task = CycleTask([0.0], [0.5], 1.0, 10.0, 3.0, rate, 1)
    raw = np.array([task.step()[0][0] for _ in range(task.samples_per_cycle)])
    for design_hz in (5.0, 6.0):
        fir = discretize(design("zv", [Mode.from_hz(design_hz, 0.01)]), rate)
        shaped = StreamingShaper(fir, 1).process(raw[:, None])[:, 0]
        amp = {}
        for name, cmd in (("raw", raw), ("shaped", shaped)):
            plant = MckPlant(*mck_from_mode(true.omega, true.zeta), rate=rate)
            _, acc = simulate(plant, cmd)
            # amplitude of the free vibration at the same time, 2 s after the start
            window = acc[int(2.0 * rate):int(2.4 * rate)]
            amp[name] = np.max(np.abs(window))
        v = percentage_vibration(*fir_impulses(fir, rate), true.omega, true.zeta)
        assert amp["shaped"] / amp["raw"] == pytest.approx(v, rel=0.02, abs=2e-4)


def test_task_events_and_profile():
    task = CycleTask([0.0, 1.0], [0.5, 0.0], 1.0, 10.0, 0.5, 100.0, 2)
    duration, ta = trapezoid(0.5, 1.0, 10.0)
    assert duration == pytest.approx(0.6) and ta == pytest.approx(0.1)
    log = []
    commands = []
    while not task.done:
        cmd, events = task.step()
        commands.append(cmd)
        log += [(e.kind, e.cycle, len(commands) - 1) for e in events]
    assert [(k, c) for k, c, _ in log] == [(START, 0), (MOTION_END, 0), (END, 0), (START, 1), (MOTION_END, 1),
                                           (END, 1)]
    commands = np.array(commands)
    i_end = log[1][2]
    np.testing.assert_allclose(commands[i_end], [0.5, 0.0])
    np.testing.assert_allclose(commands[log[4][2]], [0.0, 1.0])
    vel = np.diff(commands[:, 0]) * 100.0
    assert np.max(np.abs(vel)) <= 1.0 + 1e-9
    assert np.max(np.abs(np.diff(vel) * 100.0)) <= 10.0 + 1e-6


@pytest.mark.parametrize("profile", ["trapezoid", "step", "ramp"])
def test_round_trip_cycles_are_identical_and_end_where_they_start(profile):
    task = CycleTask([0.0], [1.0], 2.0, 10.0, 0.2, 100.0, 3, profile=profile, round_trip=True)
    steps = [task.step() for _ in range(3 * task.samples_per_cycle)]
    cmd = np.array([c[0] for c, _ in steps]).reshape(3, -1)
    assert np.array_equal(cmd[0], cmd[1]) and np.array_equal(cmd[0], cmd[2])
    assert cmd[0, -1] == 0.0 and cmd[0].max() == 1.0
    kinds = [(i, e.kind) for i, (_, evs) in enumerate(steps[: task.samples_per_cycle]) for e in evs]
    assert kinds[0] == (0, START) and kinds[-1] == (task.samples_per_cycle - 1, END)
    motion_end = [i for i, k in kinds if k == MOTION_END]
    assert motion_end == [task.motion_end_sample] and cmd[0, motion_end[0]] == 0.0
    assert np.all(cmd[0, motion_end[0]:] == 0.0) and cmd[0, motion_end[0] - 1] > 0.0


def test_step_and_ramp_profiles():
    step = CycleTask([0.0], [2.0], 1.0, 10.0, 0.1, 100.0, 2, profile="step")
    assert step.move_samples == 0 and step.step()[0][0] == 2.0
    ramp = CycleTask([0.0], [2.0], 4.0, 10.0, 0.1, 100.0, 1, profile="ramp")
    cmd = np.array([ramp.step()[0][0] for _ in range(ramp.samples_per_cycle)])
    assert ramp.move_duration == 0.5 and np.allclose(np.diff(cmd[:51]), 0.04)
    with pytest.raises(ValueError, match="profile"):
        CycleTask([0.0], [1.0], 1.0, 1.0, 0.1, 100.0, 1, profile="sine")
