"""Sim plant and shaper in separate processes, a test node in this one, over real DDS."""

import math

import pytest

from sim_plant_node.clients.conductor import Conductor, rms

pytestmark = pytest.mark.integration

HZ, ZETA = 5.0, 0.01


def test_zvd_at_the_design_mode_removes_residual_vibration(start_node, ros_context):
    omega = 2 * math.pi * HZ
    plant = start_node("sim_plant_node", "sim_plant", {
        "joint_names": ["joint_1"], "rate": 500.0, "mode": "lockstep", "imu.noise_stddev": 0.0,
        "task.dwell": 1.5, "task.preroll": 0.5})
    shaper = start_node("shaper_nodes", "shaper_node", {"joint_names": ["joint_1"], "command_rate": 500.0})
    conductor = Conductor(context=ros_context)
    try:
        conductor.wait_ready(60.0, {"/shaper/commands": 1, "/forward_position_controller/commands": 1})
        conductor.set_plant_mode(omega, ZETA)
        conductor.set_shaper("none")
        unshaped = conductor.run_cycles(2, timeout=120.0)
        conductor.set_shaper("zvd", omega, ZETA)
        shaped = conductor.run_cycles(2, timeout=120.0)
    finally:
        conductor.close()
    assert plant.running() and shaper.running()
    assert all(r.residual.samples > 300 for r in unshaped + shaped)
    assert rms(unshaped) > 1.0  # the unshaped move does vibrate (m/s^2)
    assert rms(shaped) <= 0.05 * rms(unshaped), (rms(shaped), rms(unshaped))
