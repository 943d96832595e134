"""MRILC per move over DDS: the sim arm (lockstep, its joint_trajectory_controller emulation), the shaper node's
FollowJointTrajectory proxy shaping each goal for its final pose (``action.scheduler``) and sending it on to the
learner's proxy (``action.controller``), the learner with ``mode: mrilc_moves`` adding each move's learned joint
profile correction and sending the goal on to the controller, and the scheduler on a schedule of the arm's modes:
all real nodes.

Two moves alternate, home -> pick and pick -> home, each marked as a cycle on ``/cycle_events``. Shown: each
move's correction is learned from its own residual window and reaches that move's goals only (a move's first goal
runs uncorrected even after the other move learned); the learner's error (the residual window's vibration) falls
over a few cycles; every joint limit holds; the state file holds a correction per move; after the learner is killed
(SIGKILL) and started again on the same state file, each move resumes from its saved state.
"""

from __future__ import annotations

import json
import math

from conftest import restart_learner, run_move_cycle, start_scheduled_arm

from reproductions.arm_learning import modal_calibration
from shaper_nodes.core.learning.moves import move_key
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME, MAX_ACCELERATION, MAX_VELOCITY, PICK, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.conductor import Conductor

RATE = 500.0
WAIT = 300.0  # s of wall time for a learner's report (the lockstep arm under two busy cores)
MOVES = (trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME))
ROUNDS = 4  # cycles per move before the restart


def run(client: ArmClient, cycle: int, index: int, move) -> dict[str, float]:
    """One move as one cycle; the learner's report of it."""
    return run_move_cycle(client, cycle, index, move, WAIT)[1]


#: the learner's inputs: their subscriptions on the graph again say a restarted learner is up
INPUTS = ("/cycle_events", "/tip_imu")


def test_each_move_learns_its_own_correction_within_the_limits_and_resumes_after_a_kill_9(start_node, ros_context,
                                                                                         tmp_path):
    cal = modal_calibration()
    state = tmp_path / "learner_state.json"
    start_scheduled_arm(start_node, cal["rule_base"], RATE, ["/learner", "/conductor"],
                        **{"action.controller": "/learner/follow_joint_trajectory"})
    learner_params = {"mode": "mrilc_moves", "use_sim_time": True, "state_file": str(state),
                      "topics.imu_reliable": True, "mrilc_moves.operator": "sim_plant_node.arm.lifted:arm_operator",
                      "mrilc_moves.velocity": [MAX_VELOCITY], "mrilc_moves.acceleration": [MAX_ACCELERATION],
                      "mrilc_moves.action_timeout": 60.0, "end_wait": 10.0}
    learner = start_node("shaper_nodes", "learner", learner_params)
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    got: dict[str, list[dict[str, float]]] = {m.name: [] for m in MOVES}
    cycle = 0
    try:
        client.wait_ready(listeners=2, timeout=300.0)  # the sim arm builds its model first (slow on a busy machine)
        AckWatch(conductor, "/learner").wait_subscribed(conductor.spin_until, ["/tip_imu"], 120.0)
        for _ in range(ROUNDS):
            for i, move in enumerate(MOVES):
                got[move.name].append(run(client, cycle, i, move))
                cycle += 1

        for move in MOVES:
            mine = got[move.name]
            assert all("skipped" not in m for m in mine), (move.name, mine)
            assert [m["iteration"] for m in mine] == list(range(1, ROUNDS + 1))
            assert len({m["move"] for m in mine}) == 1
            # the move's first goal ran uncorrected (for the second move: after the first had learned), the later
            # ones with its own learned correction
            assert mine[0]["max_correction_rad"] == 0.0
            assert all(m["max_correction_rad"] > 0.0 for m in mine[1:]), mine
            # every limit held: the corrected profile inside the joint limits (what the learner projected and the
            # goal's check found)
            assert all(m["limit_excess"] == 0.0 for m in mine), mine  # the points sent clipped into them
            # the residual window's vibration (the learner's cost) falls: a relative drop, not tuned digits
            costs = [m["cost"] for m in mine]
            assert min(costs[1:]) < 0.7 * costs[0], (move.name, costs)
        assert got[MOVES[0].name][1]["max_correction_rad"] > 0.0  # the first move had learned before the
        assert got[MOVES[1].name][0]["max_correction_rad"] == 0.0  # second's first goal, which ran uncorrected
        assert got[MOVES[0].name][0]["move"] != got[MOVES[1].name][0]["move"]

        # the state file: one learner per move, with its correction's coefficients
        doc = json.loads(state.read_text())
        assert doc["per_move"] == "mrilc" and len(doc["moves"]) == 2
        saved = {}
        for move in MOVES:
            entry = doc["moves"][move_key(move.positions[0], move.positions[-1])]
            lr = entry["learner"]
            assert lr["cycle"] == ROUNDS + 1
            assert any(abs(c) > 0 for row in lr["coefficients"] for c in row)
            saved[move.name] = lr
        a, b = (saved[m.name]["coefficients"] for m in MOVES)
        assert a != b

        # kill -9, and start again on the same state file: each move resumes from its saved state
        restart_learner(start_node, learner, learner_params, conductor, INPUTS)
        for i, move in enumerate(MOVES):
            m = run(client, cycle, i, move)
            cycle += 1
            assert "skipped" not in m, m
            assert m["iteration"] == ROUNDS + 1  # not from scratch
            assert m["max_correction_rad"] > 0.0 and m["limit_excess"] == 0.0
            assert m["cost"] < got[move.name][0]["cost"]
            assert math.isfinite(m["cost"])
        print("learner cost per move and cycle, m/s^2:",
              json.dumps({k: [m["cost"] for m in v] for k, v in got.items()}))
        print("largest correction per move, rad:",
              json.dumps({k: max(m["max_correction_rad"] for m in v) for k, v in got.items()}))
    finally:
        conductor.close()


def test_the_operator_is_required_and_named_when_it_cannot_be_loaded(ros_context):
    """A learner without a usable operator refuses to start, with one line naming the parameter (in-process)."""
    import pytest
    from rclpy.parameter import Parameter

    from shaper_nodes.nodes.learner import LearnerNode

    for value, words in (("", "must be 'module:function'"), ("sim_plant_node.arm.nowhere:f", "cannot be loaded"),
                         ("sim_plant_node.arm.lifted:DELAY", "is not callable")):
        with pytest.raises(ValueError, match=words) as err:
            LearnerNode(context=ros_context, parameter_overrides=[Parameter("mode", value="mrilc_moves"),
                                                                  Parameter("mrilc_moves.operator", value=value)])
        assert "mrilc_moves.operator" in str(err.value) and "\n" not in str(err.value)


def test_a_saved_state_is_loaded_per_move_and_a_broken_one_set_aside(ros_context, tmp_path):
    """The state file's moves come back with their saved learners (rebuilt at each move's first goal); a file whose
    move entry does not match its poses is reported and set aside, and the learner starts afresh (in-process)."""
    from rclpy.parameter import Parameter

    from shaper_nodes.nodes.learner import LearnerNode

    start, goal = MOVES[0].positions[0].tolist(), MOVES[0].positions[-1].tolist()
    learner_doc = {"version": 1, "basis": 7, "joints": 6, "outputs": 3, "gain": 0.5, "cycle": 1,
                   "coefficients": [[0.0] * 6] * 7, "best_cost": None, "best_coefficients": None, "grew": 0,
                   "fallbacks": 0, "holding": False, "history": []}
    doc = {"version": 1, "per_move": "mrilc", "moves": {move_key(start, goal): {
        "start": start, "goal": goal, "joint_names": list(JOINT_NAMES), "learner": learner_doc}}}
    path = tmp_path / "state.json"
    params = [Parameter("mode", value="mrilc_moves"), Parameter("state_file", value=str(path)),
              Parameter("mrilc_moves.operator", value="sim_plant_node.arm.lifted:arm_operator")]
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=params)
    try:
        assert list(node.mode.moves) == [move_key(start, goal)] and node.state_problem == ""
        assert node.mode.state()["moves"][move_key(start, goal)]["learner"] == learner_doc  # kept until rebuilt
    finally:
        node.destroy_node()
    doc["moves"]["pose-0000000000000000"] = doc["moves"].pop(move_key(start, goal))
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=params)
    try:
        assert node.mode.moves == {} and "does not match its start and goal" in node.state_problem
        assert not path.exists() and path.with_name(path.name + ".corrupt").exists()
    finally:
        node.destroy_node()
