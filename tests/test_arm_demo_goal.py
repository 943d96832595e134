"""The arm demo's goal through the shaper node's path is the command the ROS-free reproductions run (issue 31).

The demo's client sends each move to the shaper node's FollowJointTrajectory action; the node shapes the goal's
points as they come (``WholeShaping.shape``) and the controller runs them from the arm's measured state. A goal whose
first point is later than time 0 leaves the motion from the start to that point to the controller's interpolation,
unshaped, and shapes the rest from a held first point: over DDS the schedule then left the arm 2-20 times the
vibration part the reproductions (``goal_waypoints``, shaped from the move's start) found, with the same servo part
(docs/results/arm_demo.md, "issue 31, session 13, H6 ddsgap"). Here, without DDS: the client's goal starts at the
move's start at time 0; shaped by the node's code it is, point for point, the reproductions' command; and on the
offline arm the goal without that point leaves the vibration part 20 times larger.
"""

from __future__ import annotations

import numpy as np
import pytest

from reproductions import arm_mrilc
from reproductions.arm_calibration import goal_waypoints
from shaper_nodes.core.shaping.fir import discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_SAMPLES
from shaper_nodes.ros.conversions import duration_to_sec
from shaper_nodes.ros.whole_trajectory import WholeShaping
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.task import HOME, cycle_moves
from sim_plant_node.clients.arm_client import DWELL, goal_trajectory

RATE = 500.0


def node_shaped(msg, shaper):
    """``msg`` shaped as the shaper node's action path shapes it (its default discretisation, no limits)."""
    how = WholeShaping(tuple(JOINT_NAMES), RATE, discretize(shaper, RATE), JointLimits.unset(JOINT_NAMES), 1e6,
                       MAX_TRAJECTORY_SAMPLES)
    out = how.shape(msg)
    times = np.array([duration_to_sec(p.time_from_start) for p in out.points])
    fields = [np.array([getattr(p, f) for p in out.points]) for f in ("positions", "velocities", "accelerations")]
    return times, *fields


def controller_points(times, *fields):
    """What the controller runs of a trajectory started at its first update: the points after time 0 (the first
    segment starts from the measured state)."""
    keep = times > 0.0
    return times[keep], *(f[keep] for f in fields)


def parts_on_offline_arm(times, pos, vel, acc):
    """The move from HOME at rest on the offline arm: the servo and vibration parts of its residual."""
    from reproductions.residual_split import residual_parts
    from sim_plant_node.arm.metrics import motion_end
    from sim_plant_node.arm.offline import OfflineArm

    arm = OfflineArm(HOME, RATE, states=True)
    start = arm.run(times, pos, vel, acc)
    ct, cq = arm.record.window("cmd", start, start + times[-1])
    it, _ = arm.record.window("imu", start, start + times[-1])
    end = motion_end(ct, cq)
    k = int(np.argmin(np.abs(np.asarray(arm.record.state_t) - end)))
    return residual_parts(arm.plant.model, cq[-1], arm.record.state[k], it, end)


@pytest.mark.parametrize("index", [0, 4])  # home->rotated, home->pick
def test_the_clients_goal_shaped_by_the_node_is_the_reproductions_command(index):
    move = cycle_moves()[index]
    msg = goal_trajectory(move)
    first = msg.points[0]
    assert duration_to_sec(first.time_from_start) == 0.0
    np.testing.assert_array_equal(first.positions, move.positions[0])
    assert duration_to_sec(msg.points[-1].time_from_start) == pytest.approx(move.duration + DWELL, abs=1e-9)
    shaper = arm_mrilc.modal_zv(ArmModel())(move.positions[-1])
    got = controller_points(*node_shaped(msg, shaper))
    want = goal_waypoints(move, shaper, RATE, DWELL)
    assert got[0].shape == want[0].shape
    # the message's times are whole nanoseconds: the waypoints' resampling moves the positions by under 1e-9 rad and
    # the differentiated velocities and accelerations by under 1e-6 of their largest
    np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[1], want[1], rtol=0, atol=1e-9)
    for g, w in zip(got[2:], want[2:], strict=True):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-6 * float(np.abs(w).max()))


def test_a_goal_without_its_start_leaves_the_arm_vibrating_more():
    """The goal as the client sent it before (its first point 10 ms in): the same servo part, the vibration part
    20 times the whole goal's (home->rotated, the modal schedule's shaper at its goal: ZV on three modes)."""
    from reproductions.arm_learning.runs import Context, modal_calibration

    move = cycle_moves()[0]
    shaper = Context(modal_calibration()).schedule()(move.positions[-1])
    whole = goal_trajectory(move)
    late = goal_trajectory(move)
    late.points = late.points[1:]
    full = parts_on_offline_arm(*controller_points(*node_shaped(whole, shaper)))
    cut = parts_on_offline_arm(*controller_points(*node_shaped(late, shaper)))
    assert cut.servo_rms == pytest.approx(full.servo_rms, rel=0.01)
    assert cut.vibration_rms > 10.0 * full.vibration_rms  # (0.0139 against 0.0007 m/s^2)
