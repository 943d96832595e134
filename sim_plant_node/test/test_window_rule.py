"""The measures' window rule (sim_plant_node.arm.metrics.in_window, issue 31): a stamp within STAMP_TOLERANCE of
an edge is on it, so the residual window [commanded end, + 1 s) has the sample at the commanded end whichever side
of it rounding put that stamp; on integer-ns stamps (DDS) it selects as the integers do and as the sim plant node
and the demo's client count. Plain pytest, no rclpy."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim_plant_node.arm.metrics import (
    RESIDUAL_WINDOW,
    SERVO_TRANSIENT,
    STAMP_TOLERANCE,
    in_window,
    late_residual,
    measure_move,
    window_residual,
)
from sim_plant_node.arm.residual_parts import residual_parts

IMU_RATE = 1000.0
C_END = 12.345  # a commanded end, s (a command's stamp)


def grid(first: float, n: int = 1600) -> np.ndarray:
    """IMU stamps every 1 ms from ``first``: the offline arm's, whose first lands a rounding error off C_END."""
    return first + np.arange(n) / IMU_RATE


def transient(t: np.ndarray) -> np.ndarray:
    """A specific force with the loop's transient at its largest at the commanded end, (N, 3) m/s^2."""
    s = np.clip(t - C_END, 0.0, None)
    return np.stack([np.exp(-30.0 * s) * np.cos(60.0 * s), 0.2 * np.sin(9.0 * s), 9.81 + 0.0 * s], axis=1)


@pytest.mark.parametrize("shift", [-1e-15, 1e-15, -2e-12, 2e-12])
def test_a_window_takes_the_same_samples_either_side_of_the_commanded_end(shift):
    exact, off = grid(C_END), grid(C_END + shift)
    sel_exact = in_window(exact, C_END, C_END + RESIDUAL_WINDOW)
    sel_off = in_window(off, C_END, C_END + RESIDUAL_WINDOW)
    assert np.array_equal(sel_exact, sel_off)
    assert int(np.sum(sel_off)) == round(RESIDUAL_WINDOW * IMU_RATE)  # the sample at the end in, at end + 1 s out
    assert sel_off[0] and not sel_off[round(RESIDUAL_WINDOW * IMU_RATE)]
    # the bare float rule, as the measures had it: the first sample depends on the sign of the rounding
    assert bool(off[0] >= C_END) == (shift >= 0)


@pytest.mark.parametrize("shift", [-1e-15, 1e-15])
def test_the_measures_agree_either_side_of_the_commanded_end(shift):
    exact, off = grid(C_END), grid(C_END + shift)
    a = window_residual(exact, transient(exact), C_END, C_END + RESIDUAL_WINDOW)
    b = window_residual(off, transient(exact), C_END, C_END + RESIDUAL_WINDOW)
    assert (a.samples, a.rms, a.peak) == (b.samples, b.rms, b.peak)
    assert late_residual(exact, transient(exact), C_END) == late_residual(off, transient(exact), C_END)
    tool = np.zeros((exact.size, 3))
    tool[:, 0] = 1e-3 * np.exp(-5.0 * np.clip(exact - C_END, 0.0, None))
    ma = measure_move("m", 10.0, 2.345, C_END, float(exact[-1]), exact, transient(exact), exact, tool)
    mb = measure_move("m", 10.0, 2.345, C_END, float(off[-1]), off, transient(exact), off, tool)
    # the same samples: equal but for the stamps' own 1e-15 s (the settling time is a stamp's difference)
    assert dataclasses.astuple(ma)[1:] == pytest.approx(dataclasses.astuple(mb)[1:], rel=1e-9, abs=1e-12,
                                                        nan_ok=True)


def test_the_late_window_starts_at_the_servo_transient_either_side():
    start = C_END + SERVO_TRANSIENT
    for shift in (-1e-15, 1e-15):
        t = grid(C_END + shift)
        sel = in_window(t, start, C_END + RESIDUAL_WINDOW)
        assert int(np.sum(sel)) == round((RESIDUAL_WINDOW - SERVO_TRANSIENT) * IMU_RATE)
        assert sel[round(SERVO_TRANSIENT * IMU_RATE)]


def test_the_tolerance_is_below_half_a_nanosecond_and_far_below_a_sample():
    assert 1e-12 < STAMP_TOLERANCE < 0.5e-9
    assert STAMP_TOLERANCE < 1e-6 / IMU_RATE


@pytest.mark.parametrize("base_ns", [0, 7_000_000_000, 3_600_000_000_000, 10_000_000_000_000])
def test_integer_ns_stamps_select_as_their_integers_and_as_the_node_counts(base_ns):
    """DDS stamps (sec + 1e-9 nanosec, as shaper_nodes.core.stamps.stamp_to_sec) up to 1e4 s of simulated time:
    the rule selects exactly what integer comparison does, stamps 1 ns either side of an edge included; on the
    IMU's 1 ms grid that is the node's count (ResidualWatch: the window's samples from the one at the end)."""
    end_ns = base_ns + 2_345_000_000
    ns = np.concatenate([end_ns + np.arange(-300, 1300) * 1_000_000,
                         end_ns + np.array([-1, 1, 1_000_000_000 - 1, 1_000_000_000 + 1])])

    def sec(n: np.ndarray) -> np.ndarray:
        return np.array([float(x // 1_000_000_000) + 1e-9 * float(x % 1_000_000_000) for x in n])

    t, c_end = sec(ns), float(sec(np.array([end_ns]))[0])
    want = (ns >= end_ns) & (ns < end_ns + 1_000_000_000)
    assert np.array_equal(in_window(t, c_end, c_end + RESIDUAL_WINDOW), want)
    on_grid = want[:1600]
    assert int(np.sum(on_grid)) == round(RESIDUAL_WINDOW * IMU_RATE) and on_grid[300]
    # the demo's client's (t0, t1] for the IMU and [t0, t1) for the commands: the same as the rule's
    t1_ns = end_ns + 1_500_000_000
    t1 = float(sec(np.array([t1_ns]))[0])
    assert np.array_equal(in_window(t, c_end, t1, "right"), (ns > end_ns) & (ns <= t1_ns))
    assert np.array_equal(in_window(t, c_end, t1, "left"), (ns >= end_ns) & (ns < t1_ns))


def test_residual_parts_takes_the_window_by_the_rule():
    """The parts' window is the measure's: the same samples either side of the commanded end."""
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.task import HOME

    model = ArmModel()
    goal = np.asarray(HOME, dtype=float)
    n = goal.size
    state = np.concatenate([goal, goal, np.full(n, 0.01), np.full(n, 0.01)])
    cache: dict = {}
    a = residual_parts(model, goal, state, grid(C_END - 1e-15), C_END, cache)
    b = residual_parts(model, goal, state, grid(C_END + 1e-15), C_END, cache)
    # the same samples (their times from the commanded end differ by the 1e-15 s only)
    assert dataclasses.astuple(a) == pytest.approx(dataclasses.astuple(b), rel=1e-9)
    # and a sample fewer is far more than that: the window's first sample carries the transient at its largest
    t = grid(C_END)
    fewer = residual_parts(model, goal, state, t[1:], C_END, cache)
    assert abs(fewer.servo_rms - a.servo_rms) > 1e-4 * a.servo_rms


def test_the_demo_clients_windows_are_the_rules_on_integer_ns_stamps():
    """The demo's client (sim_plant_node.clients.arm_client.Streams.window, over DDS) selects a move's samples as
    the offline arm's Record.window does with the rule: commands [t0, t1), the other streams (t0, t1]."""
    from sim_plant_node.arm.offline import Record
    from sim_plant_node.clients.arm_client import Streams

    ns = 7_000_000_000 + np.arange(-40, 3000) * 1_000_000  # 1 ms apart from 40 ms before t0
    t = [float(x // 1_000_000_000) + 1e-9 * float(x % 1_000_000_000) for x in ns]
    t0 = 7.0
    t1 = t[2500]
    s, r = Streams(), Record()
    for name in ("imu", "cmd", "link"):
        setattr(s, name + "_t", list(t))
        setattr(s, name, [[float(i)] for i in range(len(t))])
        setattr(r, name + "_t", list(t))
        setattr(r, name, [np.array([float(i)]) for i in range(len(t))])
        a, b = s.window(name, t0, t1), r.window(name, t0, t1)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]), name
