"""The rules a FollowJointTrajectory goal meets at the shaper node's proxy (:mod:`.trajectory_action`), apart from
the proxy: its tolerances (one per joint at most, finite), the warning for a goal that does not start at time 0,
and the goal sent on (a shaped trajectory with the request's tolerances)."""

from __future__ import annotations

from typing import TypeAlias

from control_msgs.action import FollowJointTrajectory
from trajectory_msgs.msg import JointTrajectory

from shaper_nodes.core.checks import InputError, finite_array

__all__ = ["check_tolerance_counts", "check_tolerances", "late_start_warning", "with_trajectory"]

Goal: TypeAlias = FollowJointTrajectory.Goal


def check_tolerance_counts(goal: Goal) -> None:
    """Refuse a tolerance list with more entries than the trajectory has joints (one per joint at most).

    Raises
    ------
    InputError
        ``too_large``, naming the list and the counts.
    """
    joints = len(goal.trajectory.joint_names)
    for field in ("path_tolerance", "goal_tolerance", "component_path_tolerance", "component_goal_tolerance"):
        count = len(getattr(goal, field))
        if count > joints:
            raise InputError("too_large", f"{field} has {count} entries, more than the trajectory's {joints}"
                             " joints (one per joint at most)")


def check_tolerances(goal: Goal) -> None:
    """Refuse non-finite tolerances: joint_trajectory_controller compares with them unchecked.

    Raises
    ------
    InputError
        ``non_finite``, naming the tolerance list and joint.
    """
    lists = {"path_tolerance": goal.path_tolerance, "goal_tolerance": goal.goal_tolerance}
    for field, tols in lists.items():
        for tol in tols:
            finite_array(f"{field} of joint {tol.name!r}", [tol.position, tol.velocity, tol.acceleration])
    lists = {"component_path_tolerance": goal.component_path_tolerance,
             "component_goal_tolerance": goal.component_goal_tolerance}
    for field, ctols in lists.items():
        for ctol in ctols:
            finite_array(f"{field} of joint {ctol.joint_name!r}",
                         [ctol.position, ctol.velocity, ctol.acceleration])


def late_start_warning(first_s: float, points: int) -> str:
    """The warning for a goal whose first point is ``first_s`` s after its start (``points`` points)."""
    what = "the whole motion" if points == 1 else "the motion to its first point"
    return (f"goal's first point is at {first_s:.3f} s, not 0: {what} is the controller's interpolation from the"
            " robot's state and is not shaped; start the trajectory at the current state at time 0 (as planners"
            " do; send_goal --from-current)")


def with_trajectory(goal: Goal, trajectory: JointTrajectory) -> Goal:
    """``goal`` with ``trajectory`` and the same tolerances and goal_time_tolerance."""
    return Goal(trajectory=trajectory,
                path_tolerance=goal.path_tolerance, component_path_tolerance=goal.component_path_tolerance,
                goal_tolerance=goal.goal_tolerance, component_goal_tolerance=goal.component_goal_tolerance,
                goal_time_tolerance=goal.goal_time_tolerance)
