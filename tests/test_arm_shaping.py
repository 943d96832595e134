"""Shaping on the arm, end to end: a move through the shaper's FollowJointTrajectory proxy to the
controller emulation, unshaped and with ZVD at the home pose's lowest mode.

The move is the demo's base rotation that ends at the home configuration. What ZVD can leave is
set by physics (docs/design/arm.md): the rotation excites the lowest mode (9.96 Hz, the design mode) and
the base's mode at 12.16 Hz, of which a ZVD at 9.96 Hz passes about 11 %; so the residual must
drop to well under a fifth of the unshaped one, and the shaped motion must end later by the ZVD's
duration.
"""

from __future__ import annotations

import math

import pytest

from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.metrics import measure_move, motion_end
from sim_plant_node.arm.modal import lowest
from sim_plant_node.arm.task import HOME, ROTATED, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.conductor import Conductor

RATE = 500.0


def test_zvd_at_the_home_mode_removes_most_of_the_rotations_residual(start_node, ros_context):
    start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME.tolist(), "rate": RATE})
    start_node("shaper_nodes", "shaper_node", {"joint_names": list(JOINT_NAMES), "command_rate": RATE,
                                               "use_sim_time": True, "action.server_timeout": 30.0})
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    try:
        client.wait_ready(listeners=1)
        mode = lowest(ArmModel(), HOME)
        results = {}
        for family, move in (("none", trapezoid_move("home->rotated", HOME, ROTATED)),
                             ("zvd", trapezoid_move("rotated->home", ROTATED, HOME))):
            conductor.set_shaper(family, mode.omega, mode.zeta)
            run = client.run_move(0, move)
            ct, cq = client.window("cmd", run.start, run.end)
            commanded_end = motion_end(ct, cq)
            it, imu = client.window("imu", run.start, run.end)
            lt, tool = client.tool_path("link", run.start, run.end)
            results[family] = measure_move(move.name, run.start, run.planned, commanded_end, run.end, it, imu, lt,
                                           tool)
        zvd_duration = 1.0 / (mode.hz * math.sqrt(1 - mode.zeta**2))
        assert results["none"].delay_s == pytest.approx(0.0, abs=2.5 / RATE)
        assert results["zvd"].delay_s == pytest.approx(zvd_duration, abs=2.5 / RATE)
        ratio = results["zvd"].residual_rms / results["none"].residual_rms
        assert ratio < 0.2, f"ZVD left {100 * ratio:.1f} % of the unshaped residual"
        assert results["zvd"].peak_mm < 0.2 * results["none"].peak_mm
    finally:
        conductor.close()
