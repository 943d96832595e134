"""Learning to move faster, per move, over DDS: the sim arm (lockstep, its joint_trajectory_controller emulation), the
learner with ``mode: speed_moves`` serving the client's FollowJointTrajectory goals, time-scaling each by its move's
factor and sending it on to the shaper node's proxy, which shapes it for its final pose (the scheduler on a schedule
of the arm's modes) and sends it to the controller: all real nodes.

Two moves alternate, home -> pick and pick -> home, each marked as a cycle on ``/cycle_events``. Shown: each move's
factor rises after its good cycles (settled residual within 0.05 mm at the flange, converted to the accelerometer
level at the goal's lowest mode); every scaled plan holds the joint velocity and acceleration limits; a goal whose
planned points break a limit is rejected with one line naming the joint; a bad cycle (the tolerance tightened at
run time through the parameter service, so that the measured residual is above it) lowers the factor at once to the
largest good one; the joint torques the arm measures (its /joint_states efforts) stay within the UR5e's published
limits on every good cycle, and a move whose measured torque exceeds ``speed.max_effort`` (lowered to 10 N m at run
time; a limit <= 0 is refused) is a bad cycle, its factor lowered at once, the joint named in its saved history; the
measured joint speeds stay within their limit; before a raise the torque is predicted at the next factor from those
measured, and where the prediction passes the limit less the margin (the torque limits scaled at run time so that it
does, the one measured below them) the factor holds, the joint named in the saved history; the state file holds a
speed learner per move, with the peaks measured per factor; after the learner is killed (SIGKILL) and started
again on the same state file, each move resumes at its saved factor. Then the payload changes (2 -> 4.5 kg through the
plant's parameter service) and the drift watch warns (the identifier's status ``identifier: drift`` at WARN on
``/diagnostics``, published by the test's peer): every move's next goal runs at its planned speed again (factor 1).
"""

from __future__ import annotations

import itertools
import json

from conftest import Diagnosed, restart_learner, run_move_cycle, start_scheduled_arm
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from reproductions.arm_learning import modal_calibration
from shaper_nodes.core.learning.moves import move_key
from shaper_nodes.nodes.learner_speed_parameters import SpeedGroup
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.metrics import SETTLE_TOLERANCE
from sim_plant_node.arm.task import HOME, PICK, time_scaled, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.arm_speed import EFFORT, learner_parameters, use_learner_proxy
from sim_plant_node.clients.conductor import Conductor

RATE = 500.0
WAIT = 300.0  # s of wall time for a learner's report (the lockstep arm under two busy cores)
MOVES = (trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME))
ROUNDS = 3  # cycles per move before the bad cycle
STEP = 0.2
#: the learner's inputs: their subscriptions on the graph again say a restarted learner is up
INPUTS = ("/cycle_events", "/tip_imu", "/joint_states")


def run(client: ArmClient, cycle: int, index: int, move) -> dict[str, float]:
    """One move as one cycle; the learner's report of it, with the flange's true peak (mm) beside its estimate."""
    r, out = run_move_cycle(client, cycle, index, move, WAIT)
    measured = client.measure(r, None)[0]
    out["flange_peak_mm"], out["move_settle_s"] = measured.peak_mm, measured.move_and_settle_s
    return out


def set_param(conductor: Conductor, name: str, value, accepted: bool = True) -> None:
    """A parameter of the running learner, through its parameter service (accepted, or refused)."""
    params = AsyncParameterClient(conductor, "/learner")
    conductor.spin_until(lambda: params.services_are_ready(), 60.0, "the learner's parameter services")
    future = params.set_parameters([Parameter(name, value=value)])
    conductor.spin_until(future.done, 60.0, f"the answer to setting {name}")
    assert all(r.successful == accepted for r in future.result().results), future.result()


def set_tolerance(conductor: Conductor, value: float) -> None:
    """speed.tolerance of the running learner, through its parameter service."""
    set_param(conductor, "speed.tolerance", value)


def learned_rightly(mine: list[dict[str, float]]) -> None:
    """Each cycle's verdict moved the factor the right way, and every scaled plan held the limits."""
    for m in mine:
        assert "skipped" not in m, m
        assert m["speed_factor"] <= m["ceiling"] + 1e-9 and m["speed_factor"] >= 1.0
        assert m["velocity_ratio"] <= 1.0 + 1e-9 and m["acceleration_ratio"] <= 1.0 + 1e-9, m
        assert m["effort_ratio"] > 0.0 and m["effort_ok"] == float(m["effort_ratio"] <= 1.0), m  # torques measured
        assert 0.0 < m["speed_ratio"] < 1.0 and m["speed_ok"] == 1.0, m  # the measured joint speeds: within
        if m["ok"]:  # raised, unless at the ceiling or holding (the good and the bad factor within the resolution)
            assert m["factor_next"] > m["speed_factor"] or m["speed_factor"] >= m["ceiling"] - 1e-9 or m["holding"], m
        else:  # lowered at once (at the planned speed it cannot go lower)
            assert m["factor_next"] < m["speed_factor"] or m["speed_factor"] == 1.0, m
    for a, b in itertools.pairwise(mine):
        assert b["speed_factor"] == a["factor_next"]  # the next goal of the move ran with the factor learned


def test_each_move_learns_to_move_faster_within_the_limits_lowers_at_once_and_resumes_after_a_kill_9(
        start_node, ros_context, tmp_path):
    cal = modal_calibration()
    state = tmp_path / "learner_state.json"
    start_scheduled_arm(start_node, cal["rule_base"], RATE, ["/learner", "/conductor"])
    learner_params = {**learner_parameters(), "state_file": str(state), "speed.step": STEP,
                      "speed.action_timeout": 60.0, "end_wait": 10.0}
    learner = start_node("shaper_nodes", "learner", learner_params)
    conductor = Conductor(context=ros_context)
    diagnosed = Diagnosed(conductor)
    client = ArmClient(conductor)
    use_learner_proxy(client)
    got: dict[str, list[dict[str, float]]] = {m.name: [] for m in MOVES}
    cycle = 0
    try:
        client.wait_ready(listeners=2, timeout=300.0)  # the sim arm builds its model first (slow on a busy machine)
        AckWatch(conductor, "/learner").wait_subscribed(conductor.spin_until, ["/tip_imu", "/joint_states"], 120.0)
        for _ in range(ROUNDS):
            for i, move in enumerate(MOVES):
                got[move.name].append(run(client, cycle, i, move))
                cycle += 1

        for move in MOVES:
            mine = got[move.name]
            assert mine[0]["speed_factor"] == 1.0  # a new move starts at its planned speed
            learned_rightly(mine)
            assert max(m["speed_factor"] for m in mine) > 1.0, mine  # it did learn to move faster
            assert len({m["move"] for m in mine}) == 1
            # the tolerance: 0.05 mm at the goal's lowest mode, as the accelerometer level
            assert all(abs(m["tolerance"] - SETTLE_TOLERANCE * (6.283185307 * m["frequency_hz"]) ** 2) < 1e-6
                       for m in mine)
            assert all(m["effort_ok"] == 1.0 and m["effort_ratio"] <= 1.0 for m in mine)  # within the UR5e's limits
        assert got[MOVES[0].name][0]["move"] != got[MOVES[1].name][0]["move"]

        # a goal whose planned points break a joint limit is rejected, one line naming the joint and the limit
        fast = time_scaled(MOVES[0], 3.0)  # 4.5 rad/s against the learner's pi
        future = client.action.send_goal_async(client._goal(fast))
        conductor.spin_until(future.done, 60.0, "the answer to the goal past the limits")
        assert not future.result().accepted
        conductor.spin_until(lambda: diagnosed.find("learner", "goal refused") is not None, 60.0,
                             "the learner's refusal on /diagnostics")
        refusal = diagnosed.find("learner", "goal refused").message
        assert "velocity" in refusal and "above its limit 3.142 rad/s" in refusal and "\n" not in refusal

        # a bad cycle: the tolerance tightened far below what the arm leaves; the factor comes down at once
        before = got[MOVES[0].name][-1]
        set_tolerance(conductor, 1e-6)
        bad = run(client, cycle, 0, MOVES[0])
        cycle += 1
        assert bad["speed_factor"] == before["factor_next"] and not bad["ok"]
        good = [m["speed_factor"] for m in got[MOVES[0].name] + [bad] if m["ok"]]
        assert bad["factor_next"] < bad["speed_factor"] and bad["factor_next"] == max(good)
        got[MOVES[0].name].append(bad)
        set_tolerance(conductor, SETTLE_TOLERANCE)

        # a measured torque past its limit: speed.max_effort lowered to 10 N m (the shoulder holds more against
        # gravity alone); pick -> home is a bad cycle for its torque, its factor lowered at once, the joint named
        set_param(conductor, "speed.max_effort", [0.0], accepted=False)  # a limit must be > 0
        set_param(conductor, "speed.max_effort", [10.0])
        before = got[MOVES[1].name][-1]
        heavy = run(client, cycle, 1, MOVES[1])
        cycle += 1
        assert heavy["speed_factor"] == before["factor_next"] and not heavy["ok"], heavy
        assert heavy["effort_ok"] == 0.0 and heavy["effort_ratio"] > 1.0, heavy
        good = [m["speed_factor"] for m in got[MOVES[1].name] if m["ok"]]
        assert heavy["factor_next"] < heavy["speed_factor"] and heavy["factor_next"] == max(good)
        got[MOVES[1].name].append(heavy)
        set_param(conductor, "speed.max_effort", list(EFFORT))
        key = move_key(MOVES[1].positions[0], MOVES[1].positions[-1])
        why = json.loads(state.read_text())["moves"]["moves"][key]["speed"]["history"][-1]["reason"]
        assert why.startswith("joint ") and "measured |effort|" in why and "above its limit 10 N m" in why, why

        # the hold before a raise: the torque limits scaled so that at home -> pick's good factor the measured torque
        # is below them but the one predicted a quarter of the resolution above it passes them less the margin (its
        # next raise, half way to the bad factor, would go further): the factor holds, the joint named
        defaults = SpeedGroup()
        f_good = got[MOVES[0].name][-1]["factor_next"]
        ratio = max(m["effort_ratio"] for m in got[MOVES[0].name] if m["speed_factor"] == f_good and m["ok"])
        scale = ratio * (1.0 + 0.25 * defaults.resolution / f_good) ** 2 / (1.0 - defaults.limit_margin)
        set_param(conductor, "speed.max_effort", [scale * e for e in EFFORT])
        held = run(client, cycle, 0, MOVES[0])
        cycle += 1
        set_param(conductor, "speed.max_effort", list(EFFORT))
        assert held["speed_factor"] == f_good and held["ok"] and held["effort_ratio"] < 1.0, held  # below its limit
        assert held["held"] == 1.0 and held["factor_next"] == f_good and held["holding"] == 1.0, held
        assert f_good <= held["allowed_factor"] < f_good + defaults.resolution, held
        key = move_key(MOVES[0].positions[0], MOVES[0].positions[-1])
        why = json.loads(state.read_text())["moves"]["moves"][key]["speed"]["history"][-1]["held"]
        assert why.startswith("joint ") and "predicted |effort|" in why and f"held at x{f_good:.3f}" in why, why
        got[MOVES[0].name].append(held)
        got[MOVES[1].name].append(run(client, cycle, 1, MOVES[1]))  # (back home)
        cycle += 1

        # the state file: a speed learner per move, at the factor learned, with the peaks measured per factor
        doc = json.loads(state.read_text())
        assert doc["per_move"] == "speed" and len(doc["moves"]["moves"]) == 2
        for move in MOVES:
            entry = doc["moves"]["moves"][move_key(move.positions[0], move.positions[-1])]
            assert entry["speed"]["factor"] == got[move.name][-1]["factor_next"]
            assert entry["cycles"] == len(got[move.name])
            factors = {m["speed_factor"] for m in got[move.name]}
            assert {f for f, _ in entry["speed"]["peaks"]["effort"]} == factors, entry["speed"]["peaks"]
            assert all(len(p) == len(JOINT_NAMES) for _, p in entry["speed"]["peaks"]["velocity"])

        # kill -9, and start again on the same state file: each move resumes at its saved factor (the arm is at
        # home: home -> pick first)
        restart_learner(start_node, learner, learner_params, conductor, INPUTS)
        for i in (0, 1):
            move = MOVES[i]
            m = run(client, cycle, i, move)
            cycle += 1
            assert m["speed_factor"] == got[move.name][-1]["factor_next"], (move.name, m)
            got[move.name].append(m)
            learned_rightly(got[move.name])
        # a payload change and the drift watch's WARN: every move starts again at its planned speed
        conductor.set_plant(arm__payload_mass=4.5)
        warn = conductor.create_publisher(DiagnosticArray, "/diagnostics", 10)
        status = DiagnosticStatus(level=DiagnosticStatus.WARN, name="identifier: drift",
                                  message="the mode has drifted out of the active shaper's working band")

        def relearned() -> bool:
            warn.publish(DiagnosticArray(status=[status]))  # (again until read: one episode, acted on once)
            doc = json.loads(state.read_text())
            return doc.get("drift_warned") is True and all(
                e["speed"]["factor"] == 1.0 and e["speed"]["good"] is None for e in doc["moves"]["moves"].values())

        conductor.spin_until(relearned, 120.0, "the relearn of every move's factor on the drift WARN")
        after: dict[str, list[dict[str, float]]] = {m.name: [] for m in MOVES}
        for i in (0, 1):
            move = MOVES[i]
            m = run(client, cycle, i, move)
            cycle += 1
            assert m["speed_factor"] == 1.0, (move.name, m)
            after[move.name].append(m)
            learned_rightly(after[move.name])
        print("after the payload change (4.5 kg) and the relearn, factor / learner's peak mm / flange peak mm / ok:",
              json.dumps({k: [(m["speed_factor"], round(m["peak_mm"], 4), round(m["flange_peak_mm"], 4), m["ok"])
                              for m in v] for k, v in after.items()}))
        print("factor, settled peak (learner's estimate mm / flange mm), move + settle s, largest torque / limit per"
              " move and cycle, largest speed / limit:",
              json.dumps({k: [(round(m["speed_factor"], 3), round(m["peak_mm"], 4), round(m["flange_peak_mm"], 4),
                               round(m["move_settle_s"], 3), round(m["effort_ratio"], 3), round(m["speed_ratio"], 3))
                              for m in v]
                          for k, v in got.items()}))
    finally:
        conductor.close()


def test_a_saved_state_is_loaded_per_move_and_a_broken_entry_left_out(ros_context, tmp_path):
    """The state file's moves come back with their speed learners; an entry whose factor is outside its settings is
    left out with the reason (its move starts afresh), the others resume (in-process)."""
    from shaper_nodes.core.learning.moves import MoveStore
    from shaper_nodes.core.learning.speed import SpeedLearner, SpeedSettings
    from shaper_nodes.nodes.learner import LearnerNode

    store = MoveStore()
    for move, factor in zip(MOVES, (1.4, 1.2), strict=True):
        entry, _ = store.entry(move.positions[0], move.positions[-1])
        sp = SpeedLearner(SpeedSettings(step=0.2, ceiling=2.0))
        sp.factor = factor
        entry.speed_state, entry.cycles = sp.to_dict(), 3
    doc = {"version": 1, "per_move": "speed", "moves": store.to_doc(),
           "joint_names": {e.key: list(JOINT_NAMES) for e in store}}
    path = tmp_path / "state.json"
    params = [Parameter("mode", value="speed_moves"), Parameter("state_file", value=str(path))]
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=params)
    try:
        assert node.state_problem == ""
        assert [e.speed().factor for e in node.mode.store] == [1.4, 1.2]
    finally:
        node.destroy_node()
    broken = move_key(MOVES[1].positions[0], MOVES[1].positions[-1])
    doc["moves"]["moves"][broken]["speed"]["factor"] = 7.0  # above its ceiling
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=params)
    try:
        assert [e.speed().factor for e in node.mode.store] == [1.4]
        assert broken in node.state_problem and "factor 7 outside [1, 2]" in node.state_problem
    finally:
        node.destroy_node()


def test_a_bad_limit_is_refused_at_start_with_one_line(ros_context):
    """speed.velocity must be finite and positive: the node refuses to start, naming the parameter (in-process)."""
    import pytest

    from shaper_nodes.nodes.learner import LearnerNode

    with pytest.raises(ValueError, match=r"speed\.velocity must be one or more finite numbers > 0") as err:
        LearnerNode(context=ros_context, parameter_overrides=[Parameter("mode", value="speed_moves"),
                                                              Parameter("speed.velocity", value=[0.0])])
    assert "\n" not in str(err.value)
