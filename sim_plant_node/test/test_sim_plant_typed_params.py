"""The sim plant node reads its parameters typed (SimPlantParams): what it builds follows the typed value,
and a change is checked on the values it proposes (``Live.with_changes``) before it is taken."""

from __future__ import annotations

import gc
import os

import numpy as np
import pytest

from shaper_nodes.ros.parameters import flat, table
from sim_plant_node.node.parameters import PARAMETERS, SimPlantParams


def test_the_table_is_the_class_and_keeps_every_default():
    assert table(SimPlantParams) == PARAMETERS
    assert flat(SimPlantParams()) == {spec.name: spec.initial for spec in PARAMETERS}


@pytest.fixture
def node():
    rclpy = pytest.importorskip("rclpy")
    try:
        from shaper_msgs.msg import CycleEvent  # noqa: F401
    except ImportError:
        pytest.skip("shaper_msgs is not built (use ./run test)")
    from rclpy.parameter import Parameter

    from sim_plant_node.node.sim_plant import SimPlantNode

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=1 + int(os.environ.get("ROS_DOMAIN_ID", "30")) % 200)
    n = SimPlantNode(context=ctx, parameter_overrides=[Parameter("joint_names", value=["a", "b"]),
                                                        Parameter("task.start", value=[0.1, 0.2]),
                                                        Parameter("imu.bias", value=[1, 2, 3])])
    yield n
    n.destroy_node()
    gc.collect()
    ctx.try_shutdown()


@pytest.mark.integration
def test_the_node_builds_from_its_typed_parameters(node):
    from sim_plant_node.node.models import NodeValues

    p = node.params.value
    assert p.joint_names == ("a", "b") and p.task.start == (0.1, 0.2) and p.imu.bias == (1.0, 2.0, 3.0)
    assert node.plant.joint_state()[0].tolist() == pytest.approx([0.1, 0.2])
    assert node.sensors._imu_bias.tolist() == [1.0, 2.0, 3.0]
    assert NodeValues(node, {}).params == p  # a node read by name gives the same typed parameters


@pytest.mark.integration
def test_a_change_is_checked_on_the_proposed_values_then_taken(node):
    from rclpy.parameter import Parameter

    bad = node.set_parameters([Parameter("task.goal", value=[0.5, 0.6, 0.7])])[0]
    assert not bad.successful and "task.goal needs 1 or 2 finite values" in bad.reason
    assert node.params.value.task.goal == (0.5,)
    arm = node.set_parameters([Parameter("plant.model", value="arm")])[0]
    assert not arm.successful and arm.reason == "plant.model arm is chosen at start-up only"
    assert node.set_parameters([Parameter("imu.bias", value=[0.5, 0.0, -0.5]),
                                Parameter("joint_states.resolution", value=0.25),
                                Parameter("plant.mass", value=[2, 3])])[0].successful
    assert node.params.value.imu.bias == (0.5, 0.0, -0.5) and node.params.value.plant.mass == (2.0, 3.0)
    assert node.sensors._imu_bias.tolist() == [0.5, 0.0, -0.5]
    assert node.sensors.reported(np.array([0.3, -0.4])).tolist() == [0.25, -0.5]
    assert node.plant.m.tolist() == [2.0, 3.0]
