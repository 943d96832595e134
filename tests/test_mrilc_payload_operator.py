"""The MRILC learner told the payload (``mrilc_moves.payload_mass``) relearns on the operator of that payload, over DDS.

On the operator of the old payload the relearned MRILC does not converge after a 2 -> 4.5 kg change
(docs/results/arm_mrilc_payload.md); told the payload, the node passes it to the operator's provider
(``sim_plant_node.arm.lifted:arm_operator(..., payload=)``) when it next builds a move's operator: at the drift
warning's relearn. The learner runs as its own process with the peer of the relearn test (tests/relearn_peer.py)
and that test's move cycle (tests/test_learning_mrilc_relearn.py: START, the goal through the learner's proxy, the
accelerometer's window, END).

Shown: the move's first operator is the provider's own (one line on /rosout); the payload set through the node's
parameter service (as ``ros2 param set /learner mrilc_moves.payload_mass 4.5``) is accepted and changes nothing
until the drift WARN (the move goes on learning with its correction); after it the move's next goal runs as
planned and its learner, started again, is built on the operator for 4.5 kg (one line). A value the range refuses
is refused through the service.
"""

from __future__ import annotations

import pytest
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from relearn_peer import Peer
from test_learning_mrilc_relearn import INPUTS, KEYS, run_cycle

from shaper_nodes.ros.diagnostics import WARN
from sim_plant_node.arm.task import MAX_ACCELERATION, MAX_VELOCITY

pytestmark = pytest.mark.integration

CONTROLLER = "/mrilc_payload_controller/follow_joint_trajectory"
OWN = f"move {KEYS[0]}: operator built for the provider's own payload"
TOLD = f"move {KEYS[0]}: operator built for a payload of 4.5 kg"


def set_payload(peer: Peer, value: float) -> bool:
    """``mrilc_moves.payload_mass`` of the running learner through its parameter service; whether it was taken."""
    params = AsyncParameterClient(peer.node, "/learner")
    peer.spin_until(params.services_are_ready, "the learner's parameter services")
    future = params.set_parameters([Parameter("mrilc_moves.payload_mass", value=value)])
    peer.spin_until(future.done, "the answer to setting mrilc_moves.payload_mass")
    (result,) = future.result().results
    return bool(result.successful)


def test_told_the_payload_the_learner_relearns_on_its_operator(start_node, ros_context, tmp_path):
    params = {"mode": "mrilc_moves", "state_file": str(tmp_path / "learner_state.json"), "topics.imu_reliable": True,
              "end_wait": 10.0, "mrilc_moves.operator": "sim_plant_node.arm.lifted:arm_operator",
              "mrilc_moves.controller": CONTROLLER, "mrilc_moves.velocity": [MAX_VELOCITY],
              "mrilc_moves.acceleration": [MAX_ACCELERATION], "mrilc_moves.match_timeout": 30.0,
              "mrilc_moves.action_timeout": 60.0}
    start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, CONTROLLER, imu=True)
    try:
        peer.spin_until(lambda: peer.learner_up(INPUTS, set()), "the learner's subscriptions and action server")
        m, moved = run_cycle(peer, 0, 0)
        assert (m["iteration"], moved) == (1.0, 0.0)
        peer.spin_until(lambda: OWN in peer.logs, "the line of the move's first operator")

        # told the payload: taken, and nothing changes until the drift warning (the move learns on)
        assert set_payload(peer, 4.5)
        assert not set_payload(peer, -1.0)  # outside the range: refused
        m, moved = run_cycle(peer, 1, 0)
        assert m["iteration"] == 2.0 and moved > 0.0 and m["limit_excess"] == 0.0, (m, moved)
        assert TOLD not in peer.logs

        peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                " (2 cycles in a row)", [("cycle", "3"), ("mode_hz", "8.5")])
        peer.spin_until(lambda: peer.status("learner: moves", 1, "relearning the correction of") is not None,
                        "the relearn's status on /diagnostics")

        # the next goal as planned; its learner started again on the operator for 4.5 kg
        m, moved = run_cycle(peer, 2, 0)
        assert (m["iteration"], m["max_correction_rad"], moved) == (1.0, 0.0, 0.0), (m, moved)
        peer.spin_until(lambda: TOLD in peer.logs, "the line of the operator built for the payload told")
        assert peer.logs.count(OWN) == 1
        m, moved = run_cycle(peer, 3, 0)  # and it learns on it
        assert m["iteration"] == 2.0 and moved > 0.0 and m["limit_excess"] == 0.0, (m, moved)
    finally:
        peer.destroy()
