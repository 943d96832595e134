"""The payload changed mid-run over DDS: the drift watch warns, the learner relearns, the moves are back within 0.05 mm.

The arm demo's ``payload`` case on a small plan, all real nodes: the sim arm in lockstep, the scheduler on a
schedule of the arm's modes with its 2 kg payload (the modal calibration), the shaper node's proxy shaping each
goal for its final pose, the learner's LIST per move over the scheduler, and the identifier whose drift watch
rates each move against the shaper the scheduler gives for it (``watch.scheduler``). The client is the demo's
(:class:`~sim_plant_node.clients.arm_demo.ArmClient`: every move its own cycle on ``/cycle_events``;
:class:`~sim_plant_node.clients.arm_payload.PayloadWatch`: the payload set through the plant's parameter
service, the drift statuses, the learner's lines on ``/rosout``).

The plan is two moves, rotated -> place and back, one cycle with 2 kg and five with 4.5 kg. Folded in at the
place pose the lowest mode falls most with the payload (12.2 -> 9.7 Hz in the ROS-free reproduction,
docs/results/arm_learning.md), so the schedule for 2 kg leaves rotated -> place outside the tolerance there
(0.11 mm in the reproduction) and the watch has a mode outside its shaper's band to warn on: the property the
issue asks for (the warning, then every move within 0.05 mm within 5 cycles) holds or fails on this plan as it
does on the demo's six moves, in a third of the wall time. Measured here (lockstep, deterministic; the goals from
the move's start at time 0): rotated -> place 0.011 mm with 2 kg; 0.081, 0.156, 0.155 mm with 4.5 kg (the WARN
after the second cycle with it; the relearn; its new reference); 0.0027 mm at its first factor (the 4th cycle),
a ZV at the 9.68 Hz the drift watch identified in its latest cycle (the relearn's start in a warning episode);
0.0029 mm at LIST's next step (the 5th). Started from the schedule's 12.97 Hz it read 0.051 and 0.063 mm
(docs/results/arm_demo.md, session 13, H8 payload3).
"""

from __future__ import annotations

import argparse
import functools
import json
import re

import pytest

from reproductions.arm_learning import modal_calibration
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.metrics import SETTLE_TOLERANCE
from sim_plant_node.arm.task import PLACE, ROTATED, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient, _learned
from sim_plant_node.clients.arm_payload import CASE, PayloadWatch
from sim_plant_node.clients.conductor import Conductor

pytestmark = pytest.mark.integration
RATE = 500.0
WAIT = 300.0  # s of wall time for a state to come (the lockstep arm under two busy cores)
MOVES = [trapezoid_move("rotated->place", ROTATED, PLACE), trapezoid_move("place->rotated", PLACE, ROTATED)]
BEFORE, AFTER = 1, 5  # cycles with 2 kg, then with 4.5 kg (the issue: back within the tolerance within 5 cycles)
TOL_MM = SETTLE_TOLERANCE * 1e3


def test_a_payload_change_warns_relearns_and_every_move_is_back_within_the_tolerance(start_node, ros_context,
                                                                                    tmp_path):
    from reproductions.scheduler_rules import scheduler_parameters

    state = tmp_path / "learner_state.json"
    start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": ROTATED.tolist(), "rate": RATE,
                                               "imu.noise_stddev": 0.01,
                                               "lockstep.readers": ["/learner", "/conductor", "/identifier"]})
    start_node("shaper_nodes", "scheduler", {**scheduler_parameters(modal_calibration()["rule_base"]),
                                             "interpolation": "modes", "family": "zv", "use_sim_time": True})
    start_node("shaper_nodes", "shaper_node", {"joint_names": list(JOINT_NAMES), "command_rate": RATE,
                                               "use_sim_time": True, "action.server_timeout": 30.0,
                                               "action.scheduler": "/scheduler"})
    start_node("shaper_nodes", "identifier", {"use_sim_time": True, "settle_tolerance": 1e-4, "max_modes": 3,
                                              "topics.imu_reliable": True, "watch.scheduler": "/scheduler"})
    learner = start_node("shaper_nodes", "learner", {
        "mode": "list", "use_sim_time": True, "shaper": "/scheduler", "list.structure": "zv2",
        "list.per_move": True, "state_file": str(state), "topics.imu_reliable": True})
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    payload = PayloadWatch(conductor, argparse.Namespace(payload_cycle=BEFORE, payload_mass=4.5), [CASE])
    peaks: list[list[float]] = []  # per cycle, per move: the flange's peak in the residual window, mm
    try:
        client.wait_ready(listeners=3)  # this client's, the learner's and the identifier's /cycle_events
        for reader in ("/learner", "/identifier"):  # every sample of a move, from the first step on
            AckWatch(conductor, reader).wait_subscribed(conductor.spin_until, ["/tip_imu"], 120.0)
        first = 0
        for k in range(BEFORE + AFTER):
            payload.before_cycle(CASE, k, first)  # 2 -> 4.5 kg through the plant's parameter service at k = 1
            runs = client.run_cycle_per_move(first, MOVES, lambda: None, functools.partial(_learned, client))
            peaks.append([client.measure(r, client.tool_path("cmd", r.start, r.end)[1])[0].peak_mm for r in runs])
            first += len(MOVES)
        # the warning and the learner's relearn, once they came (the last move's rating comes after its END)
        conductor.spin_until(lambda: payload.warnings and payload.relearned, WAIT, "the drift WARN and the relearn")
    finally:
        conductor.close()
        print("peak mm per cycle and move:", json.dumps(peaks), "; drift statuses:",
              "\n".join(f"{d.cycle} level {d.level}: {d.message}" for d in payload.drifts))

    # the 2 kg cycle: the schedule keeps every move within the tolerance, and the watch finds nothing to warn on
    assert all(p <= TOL_MM for p in peaks[0]), peaks
    # 4.5 kg: the schedule for 2 kg no longer does (the physics the case is about), and the watch warns on a move
    # run with 4.5 kg, within the first cycles with it
    assert any(p > TOL_MM for p in peaks[BEFORE]), peaks
    warned = [payload.where(d.cycle) for d in payload.warnings]
    assert all(w is not None and w[0] >= BEFORE for w in warned), warned
    first_warning = warned[0]
    assert first_warning is not None and first_warning[0] <= BEFORE + 1, warned
    # the learner relearned every move it had (its log line), once for the episode
    assert re.search(r"relearning 2 moves from the current schedule", payload.relearned[0]), payload.relearned
    assert len(payload.relearned) == 1, payload.relearned
    # every move is back within the tolerance within 5 cycles of the change: at the changed move's first factor
    # after the relearn (its reference, the schedule alone, comes first). That it stays there is not asserted
    # (LIST's next step measured 0.0029 mm; 0.054 mm when the relearn started from the schedule's mode)
    back = next((k for k in range(BEFORE, BEFORE + AFTER) if all(p <= TOL_MM for p in peaks[k])), None)
    assert back is not None, f"no cycle with every move within {TOL_MM:g} mm after the change: {peaks}"
    assert back - BEFORE + 1 <= AFTER
    assert all(p > TOL_MM for p in (peaks[k][0] for k in range(BEFORE, back))), peaks  # (not within before it)
    # the state the learner saved after the relearn: both moves, learning again
    doc = json.loads(state.read_text())
    assert len(doc["moves"]["moves"]) == 2
    assert learner.running()
