"""The arm demo's task and per-move measures, without ROS."""

import numpy as np
import pytest

from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.metrics import SETTLE_TOLERANCE, measure_move, motion_end, path_deviation
from sim_plant_node.arm.task import CYCLE, MAX_ACCELERATION, MAX_VELOCITY, cycle_moves, trapezoid_move


def test_moves_respect_the_limits_and_end_at_rest_on_their_poses():
    moves = cycle_moves()
    assert len(moves) == len(CYCLE) - 1
    for move, (_, start), (_, goal) in zip(moves, CYCLE[:-1], CYCLE[1:], strict=True):
        np.testing.assert_allclose(move.positions[0], start)
        np.testing.assert_allclose(move.positions[-1], goal)
        assert np.max(np.abs(move.velocities)) <= MAX_VELOCITY + 1e-9
        assert np.max(np.abs(move.accelerations)) <= MAX_ACCELERATION + 1e-9
        assert np.all(move.velocities[-1] == 0.0) and np.all(np.diff(move.times) > 0)
        # the velocities integrate to the positions (trapezoid rule on the waypoints)
        integrated = move.positions[0] + np.concatenate(
            [[np.zeros(6)], np.cumsum(0.5 * (move.velocities[1:] + move.velocities[:-1]) * np.diff(move.times)[:, None],
                                      axis=0)])
        np.testing.assert_allclose(integrated, move.positions, atol=2e-3)


def test_a_short_move_is_triangular():
    move = trapezoid_move("short", np.zeros(6), np.full(6, 0.1))
    assert move.duration == pytest.approx(2 * np.sqrt(0.1 / MAX_ACCELERATION))
    assert np.max(move.velocities) < MAX_VELOCITY


def test_path_deviation_is_the_distance_from_the_polyline():
    line = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert path_deviation(np.array([[0.5, 0.3, 0.0], [0.2, 0.0, 0.1]]), line) == pytest.approx(0.3)
    assert path_deviation(np.array([[2.0, 0.0, 0.0]]), line) == pytest.approx(1.0)  # beyond the end
    assert path_deviation(line, line) == 0.0


def test_measures_of_a_known_decay():
    """A 10 Hz, 5 % decay of 1 mm amplitude at the tool, after a move that ends at 1 s."""
    t = np.arange(0.001, 3.0, 0.001)
    amp = 1e-3 * np.exp(-0.05 * 2 * np.pi * 10 * np.clip(t - 1.0, 0, None))
    x = np.where(t > 1.0, amp * np.cos(2 * np.pi * 10 * (t - 1.0)), 0.0)
    tool = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    accel = np.stack([np.gradient(np.gradient(x, t), t), np.zeros_like(x), np.full_like(x, 9.81)], axis=1)
    cmd_t = np.arange(0.0, 3.0, 0.002)
    assert motion_end(cmd_t, np.minimum(cmd_t, 1.0)[:, None]) == pytest.approx(1.0, abs=0.002)
    m = measure_move("m", 0.0, 1.0, 1.0, 3.0, t, accel, t, tool)
    assert m.peak_mm == pytest.approx(1.0, rel=0.01)
    expected_settle = np.log(1e-3 / SETTLE_TOLERANCE) / (0.05 * 2 * np.pi * 10)  # envelope reaches the band
    assert m.settling_s == pytest.approx(expected_settle, abs=0.05)
    assert m.move_and_settle_s == pytest.approx(1.0 + m.settling_s)
    # RMS of the acceleration magnitude over the 1 s window (gravity removed with the mean)
    sel = (t >= 1.0) & (t < 2.0)
    assert m.residual_rms == pytest.approx(np.sqrt(np.mean((accel[sel, 0] - accel[sel, 0].mean()) ** 2)), rel=0.01)


def test_the_tool_paths_of_the_cycle_are_where_the_arm_reaches():
    model = ArmModel()
    for move in cycle_moves():
        path = model.tool_positions(move.positions)
        reach = np.linalg.norm(path[:, :2], axis=1)
        assert np.all(reach > 0.1) and np.all(reach < 0.95)  # inside the UR5e's 850 mm reach (plus the tool)
