"""The arm demo's cycle events name the joints (a learner per move keys its moves and asks the scheduler with
them): received over DDS by a peer, every event of a cycle carries the arm's joint names and the move's start and
goal, one position per joint, as shaper_msgs/CycleEvent's invariant says."""

from __future__ import annotations

import numpy as np

from shaper_msgs.msg import CycleEvent
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME, PICK
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.conductor import Conductor


def test_the_demos_cycle_events_carry_the_joint_names_and_the_moves_poses(ros_context):
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    got: list[CycleEvent] = []
    peer = conductor.create_subscription(CycleEvent, "/cycle_events", got.append, 10)
    try:
        conductor.spin_until(lambda: client.events.get_subscription_count() >= 2, 60.0, "the peer's subscription")
        for kind, t in ((CycleEvent.START, 1.0), (CycleEvent.MOTION_END, 2.0), (CycleEvent.END, 3.0)):
            client._event(kind, 4, t, HOME, PICK)
        conductor.spin_until(lambda: len(got) >= 3, 60.0, "the three events")
        assert [m.event for m in got] == [CycleEvent.START, CycleEvent.MOTION_END, CycleEvent.END]
        for m in got:
            assert list(m.joint_names) == list(JOINT_NAMES) and m.cycle == 4
            assert len(m.start_positions) == len(m.goal_positions) == len(JOINT_NAMES)
            np.testing.assert_array_equal(m.start_positions, HOME)
            np.testing.assert_array_equal(m.goal_positions, PICK)
    finally:
        conductor.destroy_subscription(peer)
        conductor.close()
