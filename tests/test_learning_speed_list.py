"""Scheduled + LIST per move + speed-up on the arm, over DDS: two learner nodes on the same moves.

Issue 31's case "scheduled + learning + speed-up" as docs/guide/learning.md says to run it: the speed learner
(``mode: speed_moves``, node ``learner``) serves the client's FollowJointTrajectory goals, time-scales each by its
move's factor and sends it on to the shaper node's proxy; a second learner node (``list_learner``, renamed with
``-r __node:=list_learner``) learns LIST per move (``list.per_move``) over the schedule and gives each move's factor
to the scheduler, whose shaper for the goal's final pose the shaper node applies. All real nodes: the sim arm in
lockstep (both learners are its readers), the scheduler on a schedule of the arm's modes, the shaper node.

The two learn in turn, not at once: LIST compares each cycle with its move's reference cycle and refuses one whose
motion ends elsewhere ("motion_end 1.018 s differs from the reference's 1.11 s: the task changed"), which every
speed-up does (measured: with both learning from the start, LIST skipped every cycle of a move after its first
faster one). So: the speed learner held (``/learner/hold``: every goal as planned) while LIST learns each move's
reference and steps; LIST killed (SIGKILL) and started again on its state file: every move resumes from its saved
state; then LIST held (``/list_learner/hold``: its best factors stay at the scheduler) and the speed learner
released: the moves learn to run faster over the learned shapers. Two moves alternate, home -> pick and
pick -> home, each marked as a cycle on ``/cycle_events``.
"""

from __future__ import annotations

import itertools
import json

import pytest
from conftest import restart_learner, start_scheduled_arm
from std_srvs.srv import SetBool

from reproductions.arm_learning import modal_calibration
from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME, PICK, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.arm_speed import learner_parameters, use_learner_proxy
from sim_plant_node.clients.conductor import Conductor

pytestmark = pytest.mark.integration

RATE = 500.0
WAIT = 300.0  # s of wall time for a learner's report (the lockstep arm under two busy cores)
MOVES = (trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME))
LIST_ROUNDS = 2  # cycles per move before the kill (LIST: its reference, then a step)
SPEED_ROUNDS = 2  # cycles per move of the speed-up, LIST held
LIST_NODE = "list_learner"
INPUTS = ("/cycle_events", "/tip_imu")


def metrics(r: CycleReport) -> dict[str, float]:
    """A report's metrics, with its residual RMS (m/s^2) as ``residual``."""
    return {**dict(zip(r.metric_names, r.metric_values, strict=True)), "residual": r.residual_rms}


def speed_rightly(mine: list[dict[str, float]]) -> None:
    """Each speed verdict moved the factor the right way, every scaled plan held the limits, and the next goal of
    the move ran with the factor learned."""
    for m in mine:
        assert "skipped" not in m, m
        assert 1.0 <= m["speed_factor"] <= m["ceiling"] + 1e-9
        assert m["velocity_ratio"] <= 1.0 + 1e-9 and m["acceleration_ratio"] <= 1.0 + 1e-9, m
        if m["ok"]:
            assert m["factor_next"] > m["speed_factor"] or m["speed_factor"] >= m["ceiling"] - 1e-9 or m["holding"], m
        else:
            assert m["factor_next"] < m["speed_factor"] or m["speed_factor"] == 1.0, m
    for a, b in itertools.pairwise(mine):
        assert b["speed_factor"] == a["factor_next"]


def test_speed_up_and_list_per_move_learn_together_and_a_killed_list_learner_resumes(start_node, ros_context,
                                                                                     tmp_path):
    cal = modal_calibration()
    start_scheduled_arm(start_node, cal["rule_base"], RATE, ["/learner", f"/{LIST_NODE}", "/conductor"])
    speed_params = {**learner_parameters(), "state_file": str(tmp_path / "speed.json"), "speed.step": 0.2,
                    "speed.action_timeout": 60.0, "end_wait": 10.0}
    list_params = {"mode": "list", "use_sim_time": True, "shaper": "/scheduler", "list.structure": "zv2",
                   "list.per_move": True, "state_file": str(tmp_path / "list.json"), "topics.imu_reliable": True}
    start_node("shaper_nodes", "learner", speed_params)
    lister = start_node("shaper_nodes", "learner", list_params, remaps={"__node": LIST_NODE})
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    use_learner_proxy(client)
    list_reports: list[CycleReport] = []
    conductor.create_subscription(CycleReport, f"/{LIST_NODE}/reports", list_reports.append, 100)

    def list_report(cycle: int) -> dict[str, float]:
        conductor.spin_until(lambda: any(r.cycle == cycle for r in list_reports), WAIT,
                             f"the LIST learner's report of cycle {cycle}")
        return metrics(next(r for r in reversed(list_reports) if r.cycle == cycle))

    speed: dict[str, list[dict[str, float]]] = {m.name: [] for m in MOVES}
    lists: dict[str, list[dict[str, float]]] = {m.name: [] for m in MOVES}
    cycle = 0

    def run(i: int) -> None:
        """One move as one cycle: START, MOTION_END at the commanded motion's end (the planned duration over the
        move's factor: what LIST compares with its reference), END where the arm rests; both learners' reports."""
        nonlocal cycle
        move, k = MOVES[i], cycle
        mine = speed[move.name]
        factor = mine[-1]["factor_next"] if mine else 1.0  # what the speed learner scales this goal by

        def event(kind: int, t: float) -> None:
            msg = CycleEvent(event=kind, cycle=k, task="per_move", joint_names=list(JOINT_NAMES),
                             start_positions=move.positions[0].tolist(), goal_positions=move.positions[-1].tolist())
            msg.header.stamp = sec_to_time(t)
            client.events.publish(msg)

        r = client.run_move(i, move, lambda t: event(CycleEvent.START, t))
        event(CycleEvent.MOTION_END, r.start + move.duration / factor)
        event(CycleEvent.END, r.end)
        conductor.spin_until(lambda: any(x.cycle == k for x in client.reports), WAIT, f"the speed report of cycle {k}")
        s = metrics(next(x for x in reversed(client.reports) if x.cycle == k))
        assert s["speed_factor"] == factor and s["motion_s"] == pytest.approx(move.duration / factor, abs=0.011), s
        mine.append({**s, "flange_peak_mm": client.measure(r, None)[0].peak_mm})
        lists[move.name].append(list_report(k))
        cycle += 1

    def hold(node: str, on: bool) -> None:
        answer = conductor.call(conductor.create_client(SetBool, f"/{node}/hold"), SetBool.Request(data=on), 60.0)
        assert answer.success, (node, answer.message)

    try:
        client.wait_ready(listeners=3, timeout=300.0)  # this client's and both learners' /cycle_events
        for reader, inputs in (("/learner", ["/tip_imu", "/joint_states"]), (f"/{LIST_NODE}", ["/tip_imu"])):
            AckWatch(conductor, reader).wait_subscribed(conductor.spin_until, inputs, 120.0)

        # LIST learns, the speed learner held at the planned speed
        hold("learner", True)
        for _ in range(LIST_ROUNDS):
            for i in range(len(MOVES)):
                run(i)
        for move in MOVES:
            ls = lists[move.name]
            assert all(m["speed_factor"] == 1.0 and m["holding"] == 1.0 for m in speed[move.name])
            assert all("skipped" not in m for m in ls), (move.name, ls)
            assert ls[0]["action.reference"] == 1.0 and ls[0]["iteration"] == 1.0, ls[0]  # its reference

        # kill -9 the LIST learner, and start it again on its state file: every move resumes from its saved state
        # (its cycles from the scheduler's acknowledgement of the saved factors on: a START before that is not
        # learned from, the factor its goal ran with unknown to the learner)
        saved = {move.name: lists[move.name][-1] for move in MOVES}
        restart_learner(start_node, lister, list_params, conductor, INPUTS, resumed=len(MOVES),
                        remaps={"__node": LIST_NODE})
        AckWatch(conductor, f"/{LIST_NODE}").wait_subscribed(conductor.spin_until, ["/tip_imu"], 120.0)
        mark = {move.name: len(lists[move.name]) for move in MOVES}
        for i in range(len(MOVES)):
            run(i)
        resumed_moves = 0
        for move in MOVES:
            after, last = lists[move.name][mark[move.name]:], saved[move.name]
            assert all("skipped" not in m for m in after), (move.name, after)
            if "iteration" not in last or last["a1_next"] != last["a1_next"]:  # held at the schedule: still held
                assert all("iteration" not in m for m in after), (move.name, after)
                continue
            resumed = after[0]
            assert resumed["iteration"] == last["iteration"] + 1  # from its saved state, not from scratch
            assert resumed["a1_used"] == pytest.approx(last["a1_next"], rel=1e-12)
            assert resumed["t2_used"] == pytest.approx(last["t2_next"], rel=1e-12)
            resumed_moves += 1
        assert resumed_moves >= 1, lists  # (pick -> home learns on: its LIST residual falls, noise-free)

        # LIST held at its best factors, the speed learner released: the moves learn to run faster
        hold(LIST_NODE, True)
        hold("learner", False)
        mark = {move.name: len(speed[move.name]) for move in MOVES}
        for _ in range(SPEED_ROUNDS):
            for i in range(len(MOVES)):
                run(i)
        for move in MOVES:
            speed_rightly(speed[move.name])
        assert any(max(m["speed_factor"] for m in speed[move.name][mark[move.name]:]) > 1.0 for move in MOVES), speed
        print("speed factor / flange peak mm / residual RMS m/s^2 (LIST's window) per move and cycle:",
              json.dumps({k: [(round(s["speed_factor"], 3), round(s["flange_peak_mm"], 4), round(lm["residual"], 5))
                              for s, lm in zip(v, lists[k], strict=True)] for k, v in speed.items()}))
    finally:
        conductor.close()
