"""The payback rule's pieces of the learner per move (nodes/learner_payback.py), without a ROS graph: the goals the
learner's proxy records and the planned motion it gives back, a move's phase from its saved entry, the residual M.

The node over DDS: tests/test_learning_per_move.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.learning.list import ListParams
from shaper_nodes.core.learning.moves import MoveStore, keep_when_it_pays
from shaper_nodes.nodes.learner_payback import Captured, GoalRecorder, factor_of, phase, residual_m

NAMES = ["a", "b"]


def _goal(names, times, positions) -> JointTrajectory:
    pts = [JointTrajectoryPoint(positions=[float(x) for x in q], velocities=[0.0] * len(q),
                                time_from_start=Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9))))
           for t, q in zip(times, positions, strict=True)]
    return JointTrajectory(joint_names=list(names), points=pts)


def test_the_recorded_goal_is_its_motion_from_the_start_pose_in_the_events_joint_order():
    t = np.linspace(0.01, 0.5, 50)
    q = np.stack([np.linspace(0.0, 1.0, 50), np.linspace(0.0, -0.5, 50)], axis=1)
    hold_t, hold_q = np.r_[t, 1.5], np.vstack([q, q[-1]])  # a hold at the goal after the motion (the demo's dwell)
    rec = GoalRecorder()
    rec.record(_goal(["b", "a"], hold_t, hold_q[:, ::-1]))  # the goal's joints in another order
    start, goal = np.array([0.0, 0.0]), q[-1]
    planned = rec.lookup(NAMES, start, goal)
    assert planned is not None
    assert planned.times[0] == 0.0 and planned.times[-1] == pytest.approx(0.5)  # the hold left out
    np.testing.assert_allclose(planned.positions[0], start)
    np.testing.assert_allclose(planned.positions[1:], q)
    assert rec.lookup(NAMES, start, goal + 0.01) is None  # another move's goal
    assert rec.lookup(["a", "c"], start, goal) is None  # other joints


def test_a_goal_that_is_not_a_move_is_refused_with_the_reason():
    with pytest.raises(InputError, match="at least two points"):
        GoalRecorder().record(_goal(NAMES, [0.1], [[0.0, 0.0]]))


def test_a_moves_phase_follows_its_saved_entry():
    store = MoveStore()
    entry, _ = store.entry([0.0, 0.0], [1.0, 0.5])
    assert phase(entry, False) == "reference" and factor_of(entry) is None
    keep_when_it_pays(entry, 0.01, False)  # the reference: the base
    pair = ListParams(0.9, 0.01).shaper("zv2")
    entry.correction = (pair.amplitudes.tolist(), pair.times.tolist())
    assert phase(entry, False) == "trial"
    assert factor_of(entry) == ListParams(0.9, 0.01)
    assert keep_when_it_pays(entry, 0.005, True) == "learn"  # it paid
    assert phase(entry, False) == "kept"
    assert phase(entry, True) == "held"


def test_m_is_measured_from_the_shaped_commands_end_over_one_second():
    t = np.arange(0.0, 3.0, 0.002)
    accel = np.zeros((t.size, 3))
    accel[:, 2] = 9.81 + np.where((t >= 1.2) & (t < 2.2), np.sin(2 * np.pi * 10 * t), 0.0)
    cap = Captured(t, accel, motion_end=1.0, end=3.0, used=None)
    m, start = residual_m(cap, 0.2)
    assert start == pytest.approx(1.2)
    assert m == pytest.approx(1 / math.sqrt(2), rel=0.02)  # the sine's RMS, gravity (the mean) removed
    later, _ = residual_m(cap, 1.3)
    assert later == pytest.approx(0.0, abs=1e-9)


def test_a_moves_settled_band_is_the_flanges_tolerance_at_its_lowest_mode_that_rings():
    import math

    from shaper_nodes.core.learning.list.payback import Component
    from shaper_nodes.core.learning.speed import acceleration_tolerance
    from shaper_nodes.nodes.learner_payback import PaybackGroup, settle_band

    g = PaybackGroup()
    low, high = Component(2 * math.pi * 7.9, 0.025, 0.14), Component(2 * math.pi * 20.8, 0.08, 0.3)
    loop = Component(2 * math.pi * 30.0, 0.4, 0.5)  # damped: the loop's transient
    assert settle_band([high, loop, low], g) == pytest.approx(acceleration_tolerance(5e-5, 7.9))
    assert settle_band([loop], g) == pytest.approx(acceleration_tolerance(5e-5, 30.0))  # none rings: the lowest
    assert settle_band([], g) == pytest.approx(acceleration_tolerance(5e-5, 10.0))
