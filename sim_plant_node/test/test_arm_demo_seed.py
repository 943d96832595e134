"""The arm demo's ``--seed``: another draw of the accelerometer noise, passed to the sim plant as its ``imu.seed``;
the default is the plant's own default, so the default run (the README's table) is the same noise draw as before."""

from __future__ import annotations

from shaper_nodes.ros.launching import ros_args
from sim_plant_node.clients.arm_demo import IMU_SEED, parse_args, sim_plant_params
from sim_plant_node.node.parameters import PARAMETERS, ImuParams


def test_the_seed_reaches_the_sim_plants_command_line_as_its_imu_seed():
    assert parse_args([]).seed == IMU_SEED == ImuParams().seed == 1  # the default run: the noise draw it had
    params = sim_plant_params(parse_args(["--seed", "3", "--noise", "0.02"]))
    assert params["imu.seed"] == 3 and params["imu.noise_stddev"] == 0.02
    assert set(params) <= {spec.name for spec in PARAMETERS}  # every name one the sim plant declares
    argv = ros_args(params)
    assert argv[argv.index("imu.seed:=3") - 1] == "-p"
    assert "imu.seed:=1" in ros_args(sim_plant_params(parse_args([])))
