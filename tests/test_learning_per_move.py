"""Learning per move over DDS: the sim arm (lockstep, its joint_trajectory_controller emulation), the shaper
node's FollowJointTrajectory proxy shaping each goal for its final pose (``action.scheduler``), the scheduler
on a schedule of the arm's modes, and the learner with ``list.per_move``, all real nodes.

Two moves alternate, home -> pick and pick -> home; they end at poses whose modes differ. Each is marked as
a cycle on ``/cycle_events`` (its START carries the move's start and goal), so the learner learns each move
from that move's own residual window and the scheduler applies each move's factor to that move's goals only.
Then the learner is killed (SIGKILL) mid-run and started again on the same state file: every move resumes
from its saved state (its next update starts from the factor saved, at the next iteration).

Also: the learner's state file loaded move by move (a broken entry left out, the others kept), and the
scheduler's side alone (in-process, with a peer speaking the learner's and the proxy's sides).
"""

from __future__ import annotations

import json
import time

import pytest
import rclpy
from conftest import restart_learner, start_scheduled_arm

from reproductions.arm_learning import modal_calibration
from shaper_msgs.msg import CycleEvent
from shaper_nodes.core.learning.moves import move_key, store_from_doc
from shaper_nodes.nodes.learner_moves import T2_BAND
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.metrics import measure_move, motion_end
from sim_plant_node.arm.task import HOME, PICK, trapezoid_move
from sim_plant_node.clients.arm_demo import ArmClient
from sim_plant_node.clients.conductor import Conductor

RATE = 500.0
WAIT = 300.0  # s of wall time for a learner's report (the lockstep arm under two busy cores)
MOVES = (trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME))


class Cell:
    """The demo's client (ArmClient: run_move, its streams, the cycle events' publisher), each move a cycle."""

    def __init__(self, client: ArmClient) -> None:
        self.client = client
        self.cycle = 0
        self.residual: dict[str, list[float]] = {m.name: [] for m in MOVES}
        self.cycles: dict[str, list[int]] = {m.name: [] for m in MOVES}

    def event(self, kind: int, t: float, move) -> None:
        msg = CycleEvent(event=kind, cycle=self.cycle, task="per_move", joint_names=list(JOINT_NAMES),
                         start_positions=move.positions[0].tolist(), goal_positions=move.positions[-1].tolist())
        msg.header.stamp = sec_to_time(t)
        self.client.events.publish(msg)

    def run(self, index: int, move) -> None:
        """One move as one cycle; waits for the learner's report of it."""
        c = self.client
        run = c.run_move(index, move, lambda t: self.event(CycleEvent.START, t, move))
        self.event(CycleEvent.MOTION_END, run.start + run.planned, move)
        self.event(CycleEvent.END, run.end, move)
        ct, cq = c.window("cmd", run.start, run.end)
        it, imu = c.window("imu", run.start, run.end)
        lt, tool = c.tool_path("link", run.start, run.end)
        m = measure_move(move.name, run.start, run.planned, motion_end(ct, cq), run.end, it, imu, lt, tool)
        self.residual[move.name].append(m.residual_rms)
        self.cycles[move.name].append(self.cycle)
        cycle = self.cycle
        c.c.spin_until(lambda: report(c, cycle) is not None, WAIT, f"the learner's report of cycle {cycle}")
        self.cycle += 1


def report(client: ArmClient, cycle: int):
    """The learner's latest report of ``cycle`` (None if none yet)."""
    return next((r for r in reversed(client.reports) if r.cycle == cycle), None)


def metrics(r) -> dict[str, float]:
    return dict(zip(r.metric_names, r.metric_values, strict=True))


#: the learner's inputs: their subscriptions on the graph again say a restarted learner is up
INPUTS = ("/cycle_events", "/tip_imu")


def test_each_move_learns_its_own_factor_and_resumes_after_a_kill_9(start_node, ros_context, tmp_path):
    cal = modal_calibration()
    state = tmp_path / "learner_state.json"
    # the plant waits for its readers (the learner and this test's client take every sample, reliable), so a
    # starved learner loses no sample of a move
    start_scheduled_arm(start_node, cal["rule_base"], RATE, ["/learner", "/conductor"])
    learner_params = {"mode": "list", "use_sim_time": True, "shaper": "/scheduler", "list.structure": "zv2",
                      "list.per_move": True, "state_file": str(state), "topics.imu_reliable": True}
    learner = start_node("shaper_nodes", "learner", learner_params)
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    cell = Cell(client)
    try:
        client.wait_ready(listeners=2)  # this client's and the learner's subscriptions of /cycle_events
        # and the learner's accelerometer, from the first step on (its subscription, and its announcement as a
        # lockstep reader: from then on the plant waits for it)
        AckWatch(conductor, "/learner").wait_subscribed(conductor.spin_until, ["/tip_imu"], 120.0)
        rounds = 4  # per move: the reference (the schedule alone), the schedule's lowest mode, learned steps
        for _ in range(rounds):
            for i, move in enumerate(MOVES):
                cell.run(i, move)

        # each move was learned from its own cycles: its first is its reference, then its own factors
        last, nxt = {}, {}
        for move in MOVES:
            mine = [report(client, k) for k in cell.cycles[move.name]]
            got = [metrics(r) for r in mine]
            assert all("skipped" not in m for m in got), (move.name, got)
            assert got[0]["action.reference"] == 1.0 and got[0]["iteration"] == 1.0, got[0]
            assert len({m["move"] for m in got}) == 1
            learned_ = [m for m in got if "iteration" in m]
            assert [m["iteration"] for m in learned_] == list(range(1, len(learned_) + 1))
            last[move.name], nxt[move.name] = got[-1], mine[-1].shaper_next
            # the factor stays in its band: T2 within T2_BAND of the start's (the schedule's lowest mode at the goal)
            t2 = [m[k] for m in learned_[1:] for k in ("t2_used", "t2_next") if m[k] == m[k]]
            if t2:
                lo, hi = t2[0] / (1.0 + T2_BAND), t2[0] / (1.0 - T2_BAND)
                assert all(lo * (1 - 1e-12) <= x <= hi * (1 + 1e-12) for x in t2), (move.name, t2[0], t2)
            # a factor is kept only when it pays: after the first cycle (the schedule alone) at most one trial is
            # worse than it, and none after that one (1 %: the schedule alone again measured 0.14 % above its
            # first run, which started from rest at the task's start rather than where the previous move ended)
            first, later = cell.residual[move.name][0], cell.residual[move.name][1:]
            worse = [k for k, r in enumerate(later) if r > first * 1.01]
            assert len(worse) <= 1, (move.name, cell.residual[move.name], got)
        a, b = (last[m.name] for m in MOVES)
        assert a["move"] != b["move"]
        # the two moves' corrections differ (their goals' modes differ)
        assert list(nxt[MOVES[0].name].times) != list(nxt[MOVES[1].name].times), nxt

        # the state file holds one entry per move, each loadable
        doc = json.loads(state.read_text())
        store, problems = store_from_doc(doc["moves"])
        assert problems == {} and len(store) == 2
        held = set(doc["at_schedule"])  # the moves whose factor did not pay: the schedule alone, held
        for move in MOVES:
            entry = store.get(move_key(move.positions[0], move.positions[-1]))
            assert entry is not None and entry.learner() is not None and entry.base is not None
            assert (entry.correction is None) == (entry.key in held), (entry.key, held, entry.correction)

        # kill -9 mid-run, and start again on the same state file
        restart_learner(start_node, learner, learner_params, conductor, INPUTS, resumed=len(MOVES))
        mark = cell.cycle
        for _ in range(2):
            for i, move in enumerate(MOVES):
                cell.run(i, move)
        for move in MOVES:
            saved = last[move.name]
            after = [metrics(report(client, k)) for k in cell.cycles[move.name] if k >= mark]
            if "iteration" not in saved or saved["a1_next"] != saved["a1_next"]:
                # held at the schedule alone before the kill: still held (no new reference, no factor)
                assert all("iteration" not in m for m in after), (move.name, after)
                assert any(m.get("held") == 1.0 for m in after), (move.name, after)
                continue
            resumed = next((m for m in after if "iteration" in m), None)
            assert resumed is not None, f"{move.name}: no cycle learned from after the restart: {after}"
            assert resumed["iteration"] == saved["iteration"] + 1  # not from scratch (iteration 1: a reference)
            assert resumed["a1_used"] == pytest.approx(saved["a1_next"], rel=1e-12)
            assert resumed["t2_used"] == pytest.approx(saved["t2_next"], rel=1e-12)
            assert resumed["move"] == saved["move"]
        print("residual RMS per move and cycle, m/s^2:", json.dumps(cell.residual))
    finally:
        conductor.close()


def test_a_broken_move_entry_is_left_out_and_the_others_resume(ros_context, tmp_path):
    """The state file is loaded move by move: a broken entry is reported (its move starts afresh), the others
    are kept (an in-process learner: no peer is needed to load its state)."""
    from rclpy.parameter import Parameter

    from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
    from shaper_nodes.core.learning.moves import MoveStore
    from shaper_nodes.core.shaping import Mode
    from shaper_nodes.nodes.learner import LearnerNode

    store = MoveStore()
    for move in MOVES:
        entry, _ = store.entry(move.positions[0], move.positions[-1])
        entry.list_state = ListLearner(ListConfig(), ListParams.from_mode(Mode.from_hz(10.0, 0.02))).to_dict()
    doc = {"version": 1, "structure": "zv2", "per_move": True, "moves": store.to_doc(), "joint_names": {},
           "at_schedule": []}
    good, bad = (move_key(m.positions[0], m.positions[-1]) for m in MOVES)
    doc["moves"]["moves"][bad]["cycles"] = -1
    path = tmp_path / "state.json"
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=[
        Parameter("list.per_move", value=True), Parameter("shaper", value="/scheduler"),
        Parameter("state_file", value=str(path))])
    try:
        assert [e.key for e in node.mode.store] == [good]
        assert bad in node.state_problem and "cycles must be an integer >= 0" in node.state_problem
        assert path.exists()  # the file is kept: only the broken entry is left out
    finally:
        node.destroy_node()


def test_the_scheduler_applies_a_moves_factor_to_that_move_only(ros_context):
    """The scheduler's side, in-process over DDS with a peer speaking the learner's (``~/set_move_shaper``) and
    the shaper node's proxy's (``~/shaper_at`` with ``start``) sides: the factor over the schedule for the move's
    goals only, the schedule alone elsewhere, refusals named, ``none`` forgetting the move."""
    import numpy as np
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from shaper_msgs.msg import Shaper as ShaperMsg
    from shaper_msgs.srv import SetMoveShaper, ShaperAt
    from shaper_nodes.core.learning.list import ListParams
    from shaper_nodes.core.shaping import Mode
    from shaper_nodes.core.shaping.families import convolve, design
    from shaper_nodes.nodes.scheduler import SchedulerNode
    from shaper_nodes.ros.conversions import shaper_to_msg

    params = {"premises": ["j1"], "rule_names": ["lo", "hi"], "interpolation": "modes", "family": "zv",
              "rules.lo.membership": ["triangular"], "rules.lo.membership_params": [0.0, 0.0, 2.0],
              "rules.lo.frequency_hz": [4.0, 11.0], "rules.lo.damping_ratio": [0.02, 0.02],
              "rules.hi.membership": ["triangular"], "rules.hi.membership_params": [0.0, 2.0, 2.0],
              "rules.hi.frequency_hz": [8.0, 15.0], "rules.hi.damping_ratio": [0.02, 0.02]}
    scheduler = SchedulerNode(context=ros_context, parameter_overrides=[Parameter(k, value=v)
                                                                        for k, v in params.items()])
    peer = rclpy.create_node("peer", context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(scheduler)
    ex.add_node(peer)
    set_move = peer.create_client(SetMoveShaper, "/scheduler/set_move_shaper")
    at = peer.create_client(ShaperAt, "/scheduler/shaper_at")
    names = ["j1", "j2"]

    def call(client, request):
        deadline = time.monotonic() + 60.0
        while not client.service_is_ready():
            assert time.monotonic() < deadline, f"{client.srv_name} not discovered"
            ex.spin_once(timeout_sec=0.05)
        future = client.call_async(request)
        while not future.done():
            assert time.monotonic() < deadline, f"no answer from {client.srv_name}"
            ex.spin_once(timeout_sec=0.05)
        return future.result()

    def pose(q):
        return JointState(name=names, position=[float(x) for x in q])

    factor = ListParams(0.55, 0.06).shaper("zv2")
    try:
        start, goal = [0.0, 0.0], [1.5, 0.3]
        ok = call(set_move, SetMoveShaper.Request(start=pose(start), goal=pose(goal),
                                                  shaper=shaper_to_msg(factor, "learner", 0)))
        assert ok.success, ok.message
        schedule = call(at, ShaperAt.Request(pose=pose(goal))).shaper  # no start: the schedule, as before
        assert schedule.family == "zv" and "move" not in call(at, ShaperAt.Request(pose=pose(goal))).message
        interp = [Mode.from_hz(m.frequency_hz, m.damping_ratio) for m in schedule.design_modes]
        base = design("zv", interp)
        want = convolve((base.amplitudes, base.times), (factor.amplitudes, factor.times))
        # the move (its first point a fraction of a milliradian off the start): the factor over the schedule
        mine = call(at, ShaperAt.Request(pose=pose(goal), start=pose([3e-4, 0.0])))
        assert mine.success and mine.shaper.family == "custom" and "learned factor" in mine.message
        np.testing.assert_allclose(mine.shaper.amplitudes, want[0], atol=1e-12)
        np.testing.assert_allclose(mine.shaper.times, want[1], atol=1e-12)
        # another move to the same goal, and the same start to another goal: the schedule alone
        for other in (ShaperAt.Request(pose=pose(goal), start=pose([0.5, 0.0])),
                      ShaperAt.Request(pose=pose([1.0, 0.3]), start=pose(start))):
            resp = call(at, other)
            assert resp.shaper.family == "zv" and "no learned correction" in resp.message
        # refusals name the problem; nothing is kept
        for req, words in (
                (SetMoveShaper.Request(start=pose(start), goal=pose(goal),
                                       shaper=shaper_to_msg(factor, "user", 0)), "from the learner only"),
                (SetMoveShaper.Request(start=pose([0.0]), goal=pose(goal), shaper=shaper_to_msg(factor, "learner", 0)),
                 "1 positions for 2 names"),
                (SetMoveShaper.Request(start=JointState(name=["j2", "j1"], position=[0.0, 0.0]), goal=pose(goal),
                                       shaper=shaper_to_msg(factor, "learner", 0)), "different joints"),
                (SetMoveShaper.Request(start=pose(start), goal=pose([1.5, float("nan")]),
                                       shaper=shaper_to_msg(factor, "learner", 0)), "non-empty and finite"),
                (SetMoveShaper.Request(start=pose(start), goal=pose([0.2, 0.2]),
                                       shaper=ShaperMsg(family="custom", amplitudes=[1.0 / 17] * 17,
                                                        times=[0.01 * k for k in range(17)], source="learner")),
                 "2 to 16 impulses, got 17"),
                (SetMoveShaper.Request(start=pose(start), goal=pose([0.2, 0.2]),
                                       shaper=ShaperMsg(family="custom", amplitudes=[0.5, 0.5], times=[0.0, 1.5],
                                                        source="learner")),
                 "at most 1 s long, got 1.5 s")):
            resp = call(set_move, req)
            assert not resp.success and words in resp.message, (words, resp.message)
        assert len(scheduler.moves.moves) == 1
        # "none" forgets the move's factor: the schedule alone again
        forget = call(set_move, SetMoveShaper.Request(start=pose(start), goal=pose(goal),
                                                      shaper=ShaperMsg(family="none", source="learner")))
        assert forget.success and "forgotten" in forget.message
        again = call(at, ShaperAt.Request(pose=pose(goal), start=pose(start)))
        assert again.shaper.family == "zv" and list(again.shaper.times) == list(schedule.times)
    finally:
        ex.shutdown()
        peer.destroy_node()
        scheduler.destroy_node()


def test_payback_chooses_each_moves_factor_from_its_reference_and_resumes_after_a_kill_9(start_node, ros_context,
                                                                                         tmp_path):
    """``payback.enabled``: the goals go through the learner's proxy (recorded, sent on unchanged to the shaper
    node's), each move's reference cycle (the schedule alone) picks the factor predicted to pay (its components,
    the time cost predicted from the move's recorded goal and the schedule at its goal), the next cycle tries it
    and it is kept only if its residual is below the reference's; after a kill -9 every move resumes in its phase
    (a kept factor still applied, a move held at the schedule still held)."""
    from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S
    from sim_plant_node.clients import arm_speed

    cal = modal_calibration()
    state = tmp_path / "learner_state.json"
    start_scheduled_arm(start_node, cal["rule_base"], RATE, ["/learner", "/conductor"])
    learner_params = {"mode": "list", "use_sim_time": True, "shaper": "/scheduler", "list.structure": "zv2",
                      "list.per_move": True, "state_file": str(state), "topics.imu_reliable": True,
                      "payback.enabled": True, "payback.controller": "/shaper/follow_joint_trajectory",
                      # a settling band wide enough (0.05 rad) that the predicted time does not bind: a factor is
                      # chosen and tried (at 0.05 mm / 1 m no factor fits in 2 ms on these two moves, as the
                      # reproduction found for pick->home), so the trial and the keep rule run over DDS
                      "payback.joint_tolerance": 0.05}
    learner = start_node("shaper_nodes", "learner", learner_params)
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    arm_speed.use_learner_proxy(client, ends_at_rest=False)  # the goals through the learner's proxy
    cell = Cell(client)
    try:
        client.wait_ready(listeners=2)  # the learner's action server; its and this client's /cycle_events
        AckWatch(conductor, "/learner").wait_subscribed(conductor.spin_until, ["/tip_imu"], 120.0)
        for _ in range(3):  # per move: the reference, the trial of the chosen factor, then kept or held
            for i, move in enumerate(MOVES):
                cell.run(i, move)

        last, tried = {}, 0
        for move in MOVES:
            got = [metrics(report(client, k)) for k in cell.cycles[move.name]]
            assert all("skipped" not in m for m in got), (move.name, got)
            first = got[0]
            assert first["phase.reference"] == 1.0 and first["a1_used"] != first["a1_used"], first  # the schedule
            if first["a1_next"] == first["a1_next"]:  # a factor predicted to pay: lower residual, no slower
                tried += 1
                assert first["held"] == 0.0 and first["predicted"] < first["without"], first
                assert first["cost_s"] <= TIME_TOLERANCE_S, first
                trial = got[1]
                assert trial["phase.trial"] == 1.0
                assert (trial["a1_used"], trial["t2_used"]) == pytest.approx((first["a1_next"], first["t2_next"]),
                                                                             rel=1e-12)
                kept = trial["M"] < first["M"]  # the keep rule: only a factor that measured below the schedule
                assert (trial["held"] == 0.0) == kept and (trial["a1_next"] == trial["a1_next"]) == kept, trial
                assert got[2][f"phase.{'kept' if kept else 'held'}"] == 1.0, got[2]
            else:  # nothing predicted to pay: held at the schedule alone from the reference on
                assert first["held"] == 1.0 and all(m["phase.held"] == 1.0 for m in got[1:]), got
            # never worse than the schedule after the trial (1 %: the schedule alone measures slightly differently
            # from rest at the task's start), as the demo's own measure says
            worse = [r for r in cell.residual[move.name][2:] if r > cell.residual[move.name][0] * 1.01]
            assert not worse, (move.name, cell.residual[move.name], got)
            last[move.name] = got[-1]
        assert tried >= 1, f"no move had a factor predicted to pay: {last}"

        doc = json.loads(state.read_text())
        store, problems = store_from_doc(doc["moves"])
        assert problems == {} and len(store) == 2
        for move in MOVES:
            entry = store.get(move_key(move.positions[0], move.positions[-1]))
            assert entry is not None and entry.base is not None and entry.list_state is None
            assert (entry.correction is None) == (entry.key in doc["at_schedule"]), (entry, doc["at_schedule"])

        restart_learner(start_node, learner, learner_params, conductor, INPUTS, resumed=len(MOVES))
        conductor.spin_until(client.action.server_is_ready, 120.0, "the restarted learner's action server")
        mark = cell.cycle
        for _ in range(2):  # (a START the restarted learner missed: its cycle not learned from, the next one is)
            for i, move in enumerate(MOVES):
                cell.run(i, move)
        for move in MOVES:
            saved = last[move.name]
            after = [metrics(report(client, k)) for k in cell.cycles[move.name] if k >= mark]
            assert "skipped" not in after[-1], after
            m = after[-1]
            if saved["held"] == 1.0:
                assert m["phase.held"] == 1.0 and m["a1_used"] != m["a1_used"], m
            else:  # the kept factor, sent again at the restart
                assert m["phase.kept"] == 1.0, m
                assert (m["a1_used"], m["t2_used"]) == pytest.approx((saved["a1_next"], saved["t2_next"]), rel=1e-12)
        print("payback: residual RMS per move and cycle, m/s^2:", json.dumps(cell.residual))
    finally:
        conductor.close()
