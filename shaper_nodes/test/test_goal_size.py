"""WholeShaping.check_size: a whole trajectory too large to shape is refused before any work on its points."""

from __future__ import annotations

import sys

import pytest
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.memory import release_freed_memory
from shaper_nodes.core.shaping import design, discretize
from shaper_nodes.core.shaping.families import Mode
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
from shaper_nodes.ros.whole_trajectory import MAX_TRAJECTORY_VALUES, WholeShaping

JOINTS = ("a", "b", "c")
RATE = 100.0


def how(max_samples: int = 1000) -> WholeShaping:
    fir = discretize(design("zv", [Mode.from_hz(5.0, 0.0)]), RATE)
    return WholeShaping(JOINTS, RATE, fir, JointLimits.unset(JOINTS), 1e6, max_samples)


def point(t: float, values: int = 3) -> JointTrajectoryPoint:
    return JointTrajectoryPoint(positions=[0.0] * values, time_from_start=Duration(sec=int(t),
                                                                                     nanosec=int((t % 1) * 1e9)))


def test_a_long_span_is_refused_from_the_first_and_last_points_alone():
    # every point between the ends is malformed: the refusal names the span, so none of them was read
    msg = JointTrajectory(joint_names=list(JOINTS), points=[point(0.0), *([point(1.0, values=1)] * 5000), point(50.0)])
    with pytest.raises(InputError, match=r"spans 50 s: 5\d\d\d(\.\d+)? samples at 100 Hz exceed the limit of 1000"):
        how().shape(msg)
    # within the span limit the full check sees the malformed points
    msg.points = [point(0.0), point(1.0, values=1), point(5.0)]
    with pytest.raises(InputError, match="expected 3"):
        how().shape(msg)


def test_points_times_joints_above_the_limit_is_refused_before_the_joints_are_read():
    names = [f"n{k}" for k in range(100)]
    many = MAX_TRAJECTORY_VALUES // len(names) + 1
    msg = JointTrajectory(joint_names=names, points=[JointTrajectoryPoint()] * many)
    with pytest.raises(InputError, match=f"{many} points x 100 joints exceed the limits") as err:
        how().check_size(msg)
    assert err.value.kind == "too_large"
    msg = JointTrajectory(joint_names=list(JOINTS), points=[JointTrajectoryPoint()] * (MAX_TRAJECTORY_POINTS + 1))
    with pytest.raises(InputError, match=f"{MAX_TRAJECTORY_POINTS + 1} points x 3 joints"):
        how().check_size(msg)


def test_a_trajectory_within_the_limits_is_shaped_and_a_negative_time_is_named_by_the_full_check():
    out = how().shape(JointTrajectory(joint_names=list(JOINTS), points=[point(0.0), point(1.0)]))
    assert len(out.points) > 100
    msg = JointTrajectory(joint_names=list(JOINTS), points=[point(0.0), point(1.0), point(2.0)])
    msg.points[-1].time_from_start = Duration(sec=-1)
    with pytest.raises(InputError, match="point 2"):
        how().shape(msg)


def test_release_freed_memory_is_made_on_linux():
    assert release_freed_memory() == sys.platform.startswith("linux")
