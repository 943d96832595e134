"""The residual's servo and vibration parts (sim_plant_node.arm.residual_parts, one copy) and the per-move watch the
sim plant node reports from (sim_plant_node.arm.residual_watch); ROS-free."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.shaping.vibration import residual_vibration
from sim_plant_node.arm import residual_watch
from sim_plant_node.arm.metrics import RESIDUAL_WINDOW, motion_end
from sim_plant_node.arm.offline import OfflineArm
from sim_plant_node.arm.residual_parts import SERVO_ZETA, linear_arm, linear_cached, residual_parts, split_response
from sim_plant_node.arm.residual_watch import ResidualWatch, Split
from sim_plant_node.arm.task import HOME, Move, cycle_moves

RATE = 500.0
DWELL = 1.5  # s the goal holds its end (the demo's)


def goal(move: Move, dwell: float = DWELL) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The move's waypoints and a last one ``dwell`` s after its end, at rest (as the demo's client sends it)."""
    zero = np.zeros((1, 6))
    return (np.append(move.times, move.duration + dwell), np.vstack([move.positions, move.positions[-1:]]),
            np.vstack([move.velocities, zero]), np.vstack([move.accelerations, zero]))


def watched(arm: OfflineArm, monkeypatch: pytest.MonkeyPatch) -> tuple[ResidualWatch, list[Split]]:
    """A watch on ``arm``'s plant, called around every period as the sim plant node does."""
    watch, splits = ResidualWatch(arm.plant), []
    step = arm.plant.step

    def stepped(command, cycle_time=None, velocity=None):
        watch.before(arm.time, command)
        step(command, cycle_time=cycle_time, velocity=velocity)
        split = watch.after()
        if split is not None:
            splits.append(split)

    monkeypatch.setattr(arm.plant, "step", stepped)
    return watch, splits


def test_the_watch_gives_each_moves_split_as_the_reproduction_measures_it(monkeypatch):
    """Two moves: one split each, at the commanded end as metrics.motion_end finds it, the parts those of
    residual_parts on the recorded state and IMU (the reproductions' way), the arm's own residual the recorded one."""
    arm = OfflineArm(HOME, RATE, states=True)
    _, splits = watched(arm, monkeypatch)
    moves = cycle_moves()[:2]
    expected = []
    for move in moves:
        times, pos, vel, acc = goal(move)
        start = arm.run(times, pos, vel, acc)
        end = start + float(times[-1])
        ct, cq = arm.record.window("cmd", start, end)
        it, imu = arm.record.window("imu", start, end)
        c_end = motion_end(ct, cq)
        k = int(np.argmin(np.abs(np.asarray(arm.record.state_t) - c_end)))
        # the window's samples by their index from the sample at the commanded end (the stamps, summed period by
        # period, land a rounding error either side of it)
        first = int(np.argmin(np.abs(it - c_end)))
        sel = slice(first, first + int(RESIDUAL_WINDOW * RATE * 2))
        assert abs(it[first] - c_end) < 1e-9 and it[sel].size == 1000
        parts = residual_parts(arm.plant.model, cq[-1], arm.record.state[k], it[sel], it[first])
        own = residual_vibration(it[sel], imu[sel], it[first], np.inf, remove_mean=True)
        expected.append((c_end, cq[-1], parts, own))
    assert len(splits) == len(moves)
    for split, (c_end, held, parts, own) in zip(splits, expected, strict=True):
        assert split.window_start == pytest.approx(c_end, abs=1e-9)
        assert split.window_end == pytest.approx(c_end + RESIDUAL_WINDOW, abs=1e-9)
        np.testing.assert_array_equal(split.goal, held)
        for name in ("servo_rms", "vibration_rms", "linear_rms"):
            assert getattr(split.parts, name) == pytest.approx(getattr(parts, name), rel=1e-9), name
        assert split.own_rms == pytest.approx(own.rms, rel=1e-9)
        assert split.own_peak == pytest.approx(own.peak, rel=1e-9)
        assert split.parts.linear_rms == pytest.approx(split.own_rms, rel=0.03)  # the module docstring's 3 %
        assert np.isfinite([split.parts.servo_rms, split.parts.vibration_rms, split.seconds]).all()
        assert split.parts.servo_rms > 0 and split.parts.vibration_rms > 0


def test_a_window_cut_short_by_the_next_motion_gives_no_split(monkeypatch):
    arm = OfflineArm(HOME, RATE)
    _, splits = watched(arm, monkeypatch)
    first, second = cycle_moves()[:2]
    arm.run(*goal(first, dwell=0.5))  # the goal holds its end 0.5 s: the next motion comes within the window
    arm.run(*goal(second))
    assert [s.goal.tolist() for s in splits] == [second.positions[-1].tolist()]


def test_a_payload_change_within_the_window_gives_no_split(monkeypatch):
    arm = OfflineArm(HOME, RATE)
    _, splits = watched(arm, monkeypatch)
    move = cycle_moves()[0]
    times, pos, vel, acc = goal(move)
    arm.run(times[:-1], pos[:-1], vel[:-1], acc[:-1])  # up to the commanded end
    arm.plant.set_payload(4.5)
    arm.run(np.array([0.0, DWELL]), pos[-2:], vel[-2:], acc[-2:])
    assert splits == []


def test_the_linearisations_are_kept_per_pose_and_payload_and_bounded(monkeypatch):
    arm = OfflineArm(HOME, RATE)
    model = arm.plant.model
    cache: dict = {}
    a = linear_cached(model, HOME, cache)
    assert linear_cached(model, HOME.copy(), cache) is a and len(cache) == 1
    model.set_payload(3.0)
    assert linear_cached(model, HOME, cache) is not a and len(cache) == 2
    monkeypatch.setattr(residual_watch, "CACHE_SIZE", 1)
    watch, splits = watched(arm, monkeypatch)
    for move in cycle_moves()[:2]:
        arm.run(*goal(move))
    assert len(splits) == 2 and len(watch._cache) == 1


def test_the_modal_decomposition_is_the_one_split_response_had():
    """The cached decomposition gives what a fresh eig gives, bit for bit (the reproductions' figures unchanged)."""
    arm = linear_arm(OfflineArm(HOME, RATE).plant.model, HOME)
    z0 = np.linspace(-1e-3, 1e-3, arm.a.shape[0])
    t = np.linspace(0.0, 1.0, 101)
    values, vectors = np.linalg.eig(arm.a)
    eta = np.linalg.solve(vectors, z0.astype(complex))
    gains = (arm.c @ vectors) * eta
    zeta = -values.real / np.maximum(np.abs(values), 1e-300)
    servo = (np.abs(values.imag) <= 1e-9 * np.maximum(1.0, np.abs(values))) | (zeta >= SERVO_ZETA)
    waves = np.exp(t[:, None] * values[None, :])
    s, v = split_response(arm, z0, t)
    np.testing.assert_array_equal(s, np.real(waves[:, servo] @ gains[:, servo].T))
    np.testing.assert_array_equal(v, np.real(waves[:, ~servo] @ gains[:, ~servo].T))
    s2, v2 = split_response(arm, z0, t, servo_zeta=0.5)  # another threshold moves eigenvalues between the parts
    np.testing.assert_allclose(s2 + v2, s + v, atol=1e-12 * np.abs(s + v).max())
