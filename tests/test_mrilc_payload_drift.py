"""The MRILC learner works the payload out from the drift warning's mode and relearns on its operator, over DDS.

``mrilc_moves.payload_from_drift`` (default on) with ``mrilc_moves.modes: sim_plant_node.arm.lifted:arm_modes``:
at the drift warning's relearn the learner takes the mode the identifier measured (the warning's KeyValues
``mode_hz`` and ``modes_hz``, as nodes/identifier_watch.py publishes them) at the goal of the move of the warning's
``cycle``, finds the payload whose model modes match (core/learning/mrilc/payload.py) and sets its
``mrilc_moves.payload_mass`` to it (nodes/learner_payload.py). The learner runs as its own process with the peer and
the move cycle of the relearn test (tests/test_learning_mrilc_relearn.py).

Shown: a WARN carrying the modes of the arm with 4.5 kg at the pick pose (the model's own, so the round trip is
exact to the KeyValues' six digits) -> the status ``learner: payload`` OK names 4.5 kg, the state file keeps it
(``payload``: mass, source ``drift``, the mode, the move), and the move's next goal runs as planned on a learner
built for that payload (one line). Killed (SIGKILL) after the rebuild and started again on the same state file, the
learner sets the payload again from the state file (one line) and the move resumes on the operator for it. A later
episode's WARN with the lowest mode alone (which the model gives at 4.5 kg and at 6.4 kg: ambiguous) is refused
with the reason on /diagnostics (WARN), the payload kept; the moves relearn as before.
"""

from __future__ import annotations

import json

import pytest
from conftest import RESTARTED
from relearn_peer import Peer
from test_learning_mrilc_relearn import INPUTS, KEYS, MOVES, learner_params, run_cycle

from shaper_nodes.ros.diagnostics import OK as LEVEL_OK
from shaper_nodes.ros.diagnostics import WARN as LEVEL_WARN
from sim_plant_node.arm.lifted import arm_modes

pytestmark = pytest.mark.integration

HEAVY = 4.5
OK, WARN = 0, 1  # DiagnosticStatus levels as Peer.status takes them


def warn(peer: Peer, cycle: int, values: list[tuple[str, str]]) -> None:
    peer.identifier.publish("drift", LEVEL_WARN, "the mode has drifted out of the active shaper's working band"
                            " (2 cycles in a row)", [("cycle", str(cycle)), *values])


def test_the_payload_from_the_drifts_mode_rebuilds_the_operators_and_a_kill_9_resumes_it(start_node, ros_context,
                                                                                        tmp_path):
    state = tmp_path / "learner_state.json"
    params = {**learner_params(state), "mrilc_moves.modes": "sim_plant_node.arm.lifted:arm_modes"}
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, params["mrilc_moves.controller"], imu=True)
    modes = arm_modes(MOVES[0].positions[-1], HEAVY)[:3]  # home -> pick's goal: the pick pose

    def saved() -> dict:
        return json.loads(state.read_text())

    try:
        peer.spin_until(lambda: peer.learner_up(INPUTS, set()), "the learner's subscriptions and action server")
        m, moved = run_cycle(peer, 0, 0)
        assert (m["iteration"], moved) == (1.0, 0.0)
        m, moved = run_cycle(peer, 1, 0)
        assert m["iteration"] == 2.0 and moved > 0.0

        # the WARN of cycle 1 (home -> pick) carries the 4.5 kg arm's modes there
        warn(peer, 1, [("mode_hz", f"{modes[0]:.6g}"), ("modes_hz", ",".join(f"{f:.6g}" for f in modes))])
        peer.spin_until(lambda: peer.status("learner: payload", OK, "payload from the drift's mode") is not None,
                        "the payload's status on /diagnostics")
        got = peer.status("learner: payload", OK, "payload from the drift's mode")
        values = {kv.key: kv.value for kv in got.values}
        assert abs(float(values["mass_kg"]) - HEAVY) < 1e-3 and values["move"] == KEYS[0], values
        assert f"move {KEYS[0]}" in got.message and "lowest mode" in got.message, got.message
        peer.spin_until(lambda: peer.status("learner: moves", WARN, "relearning the correction of") is not None,
                        "the relearn's status")
        doc = saved()
        entry = doc["payload"]
        assert doc["moves"] == {} and entry["source"] == "drift" and entry["move"] == KEYS[0]
        assert abs(entry["mass"] - HEAVY) < 1e-3 and abs(entry["mode_hz"] - modes[0]) < 1e-4, entry
        told = f"move {KEYS[0]}: operator built for a payload of {entry['mass']:g} kg"

        # the next goal as planned, its learner built for the payload worked out
        m, moved = run_cycle(peer, 2, 0)
        assert (m["iteration"], m["max_correction_rad"], moved) == (1.0, 0.0, 0.0), (m, moved)
        peer.spin_until(lambda: told in peer.logs, "the line of the operator built for the payload worked out")
        assert saved()["payload"] == entry

        # kill -9, and start again on the same state file: the payload from the state file, the move resumes on it
        before = peer.learner_subscriptions(INPUTS)
        assert learner.proc is not None
        learner.proc.kill()
        learner.proc.wait(timeout=30)
        peer.logs.clear()
        start_node("shaper_nodes", "learner", params, env=RESTARTED)
        peer.spin_until(lambda: peer.learner_up(INPUTS, before), "the restarted learner")
        peer.spin_until(lambda: any(f"payload {entry['mass']:.4g} kg from the drift's mode (the state file)" in line
                                    for line in peer.logs), "the restarted learner's line of its payload")
        m, moved = run_cycle(peer, 3, 0)
        assert m["iteration"] == 2.0 and moved > 0.0 and m["limit_excess"] == 0.0, (m, moved)
        peer.spin_until(lambda: told in peer.logs, "the restarted learner's operator built for the payload")
        assert saved()["payload"] == entry

        # a new episode whose WARN carries the lowest mode alone: ambiguous, refused, the payload kept
        peer.identifier.publish("drift", LEVEL_OK, "cycle 4: the mode is inside the working band")
        peer.spin_until(lambda: saved()["drift_warned"] is False, "the OK's save")
        peer.statuses.clear()
        warn(peer, 3, [("mode_hz", f"{modes[0]:.6g}")])
        peer.spin_until(lambda: peer.status("learner: payload", WARN, "refused") is not None,
                        "the refusal's status on /diagnostics")
        refused = peer.status("learner: payload", WARN, "refused").message
        assert "ambiguous" in refused and f"{entry['mass']:g} kg (mrilc_moves.payload_mass)" in refused, refused
        peer.spin_until(lambda: peer.status("learner: moves", WARN, "relearning the correction of") is not None,
                        "the second relearn's status")
        assert saved()["payload"] == entry and saved()["moves"] == {}
    finally:
        peer.destroy()
