"""The joint_trajectory_controller emulation without ROS: tolerances, sampling, outcomes."""

import numpy as np
import pytest

from sim_plant_node.controller.jtc import (
    GOAL_TOLERANCE_VIOLATED,
    PATH_TOLERANCE_VIOLATED,
    SUCCESSFUL,
    JointTrajectoryController,
    RawPoint,
    Tolerances,
    TrajectoryRefused,
    goal_tolerances,
    validate,
)

JOINTS = ("a", "b")
DEFAULTS = Tolerances(np.array([0.1, 0.0]), np.array([0.01, 0.02]), 0.0)


def test_goal_tolerances_follow_the_controllers_rules():
    tol, problem = goal_tolerances(DEFAULTS, JOINTS, [("b", 0.5), ("a", -1.0)], [("a", 0.0)], 2.0)
    assert problem is None
    assert tol.path.tolist() == [0.0, 0.5]  # -1 erases, > 0 replaces
    assert tol.goal.tolist() == [0.01, 0.02]  # 0 keeps the default
    assert tol.goal_time == 2.0
    for path, goal_time, words in (([("c", 0.1)], 0.0, "joint 'c' specified in goal.path_tolerance does not exist"),
                                   ([("a", -0.5)], 0.0, "path_tolerance for joint 'a'"),
                                   ([], -3.0, "Specified illegal goal_time_tolerance")):
        tol, problem = goal_tolerances(DEFAULTS, JOINTS, path, [], goal_time)
        assert tol is DEFAULTS and words in problem


def test_validation_order_names_the_first_problem():
    points = [RawPoint(1.0, [0.0]), RawPoint(0.5, [0.0, 1.0])]
    with pytest.raises(TrajectoryRefused, match="Time between points 0 and 1"):  # before the size of point 1
        validate(JOINTS, ["a", "b"], [RawPoint(1.0, [0.0, 0.0]), RawPoint(0.5, [0.0])], 0.0, 0.0)
    with pytest.raises(TrajectoryRefused, match=r"positions \(1\) at point #0"):
        validate(JOINTS, ["a", "b"], points, 0.0, 0.0)


def run(ctl, seconds, period=0.01, follow=True):
    """Step the controller with a perfect plant (measured = last command) or a stuck one."""
    pos = ctl.command.copy()
    for k in range(int(round(seconds / period))):
        out = ctl.update(k * period, pos, np.zeros(2))
        if follow:
            pos = ctl.command.copy()
        if out is not None:
            return k * period, out
    return None, None


def test_goal_succeeds_at_the_end_and_keeps_the_last_point():
    ctl = JointTrajectoryController(JOINTS, 0.01, DEFAULTS, [0.0, 0.0])
    ctl.accept(["b", "a"], [RawPoint(1.0, [2.0, 1.0], [0.0, 0.0])], 0.0)  # the goal's joint order
    ctl.start_goal(DEFAULTS)
    t, out = run(ctl, 3.0)
    assert out.code == SUCCESSFUL and out.text == "Goal successfully reached!"
    assert t == pytest.approx(0.99)  # judged from the sample one period ahead, as the controller does
    assert ctl.command.tolist() == [1.0, 2.0]


def test_path_and_goal_violations_abort_and_hold():
    ctl = JointTrajectoryController(JOINTS, 0.01, DEFAULTS, [0.0, 0.0])
    ctl.accept(list(JOINTS), [RawPoint(1.0, [1.0, 0.0])], 0.0)
    ctl.start_goal(DEFAULTS)
    _, out = run(ctl, 3.0, follow=False)  # the joints do not move: 0.1 rad of path error on a
    assert out.code == PATH_TOLERANCE_VIOLATED
    assert ctl.command.tolist() == [0.0, 0.0] and not ctl.running
    strict = Tolerances(np.zeros(2), np.array([1e-3, 0.0]), 0.5)
    ctl.accept(list(JOINTS), [RawPoint(0.5, [0.5, 0.0])], 0.0)
    ctl.start_goal(strict)
    _, out = run(ctl, 3.0, follow=False)
    assert out.code == GOAL_TOLERANCE_VIOLATED
    assert out.text.startswith("Aborted due to goal_time_tolerance exceeding by")


def test_first_segment_starts_from_the_measured_state_and_a_future_stamp_starts_now():
    ctl = JointTrajectoryController(JOINTS, 0.01, DEFAULTS, [0.0, 0.0])
    ctl.accept(list(JOINTS), [RawPoint(1.0, [1.0, 1.0], [0.0, 0.0])], 5.0)  # stamp 5 s, now 4 s
    ctl.update(4.0, np.array([0.2, 0.0]), np.zeros(2))
    assert ctl.desired[0].tolist() == pytest.approx([0.2, 0.0])  # from the measured positions
    assert 0.2 < ctl.command[0] < 0.21  # moving already, slowly: the cubic runs over 2 s to the point
