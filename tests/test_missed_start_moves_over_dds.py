"""The per-move learners that change a goal by its move (MRILC: a correction; speed: a time-scaling factor) learn
from a cycle whose START they missed as from the same cycle seen, over DDS; and a goal's record from the shaper node
(shaper_msgs/ShapedGoal) goes to its cycle strictly: a stood-in START gets its record, a stale one does not
(session 15).

The rig of the per-move learners' tests without the arm (tests/relearn_peer.py: the test's peer serves the
controller's FollowJointTrajectory action, recording each goal it receives, sends the planned goals to the learner's
proxy, publishes the accelerometer and the cycle events); the learner is its own process (the MRILC learner with the
simulated arm's lifted operator, as tests/test_learning_mrilc_relearn.py), or in-process where the test reads its
goal records' book. A START is missed as ``send_goal --cycle`` makes it missed
(tests/test_missed_start_over_dds.py's StartLost: the events' publisher of a participant of its own made for the
cycle, whose START never reaches the learner), then the goal, then, once the goal ran, MOTION_END and END carrying
the START's stamp. The goal comes before the stand-in: the learner matches it at once to its known move by its first
and last points (core/learning/move_cycles.py), so it runs with the move's correction or factor, and the stand-in
claims it.
"""

from __future__ import annotations

import json
import math
import pathlib
from collections.abc import Callable, Sequence

import pytest
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from relearn_peer import Peer
from test_learning_mrilc_relearn import CONTROLLER as MRILC_CONTROLLER
from test_learning_mrilc_relearn import INPUTS as MRILC_INPUTS
from test_learning_mrilc_relearn import MOVES as ARM_MOVES
from test_learning_mrilc_relearn import WINDOW, accelerometer, goal
from test_learning_mrilc_relearn import learner_params as mrilc_params
from test_learning_speed_relearn import CONTROLLER as SPEED_CONTROLLER
from test_learning_speed_relearn import MOVES as SPEED_MOVES
from test_learning_speed_relearn import NAMES, imu_window, motion_end, plan
from test_missed_start_over_dds import StartLost
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import CycleEvent, ShapedGoal
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.cycle_events import set_start_stamp
from shaper_nodes.ros.qos import SHAPED_GOALS_QOS
from sim_plant_node.arm.description import JOINT_NAMES

pytestmark = pytest.mark.integration

SPEED_INPUTS = ("/cycle_events", "/tip_imu")


def speed_params(state) -> dict:
    """The speed learner's parameters (tests/test_learning_speed_relearn.py's kill test: no scheduler, 10 Hz)."""
    return {"mode": "speed_moves", "state_file": str(state), "end_wait": 10.0, "topics.imu_reliable": True,
            "speed.controller": SPEED_CONTROLLER, "speed.scheduler": "", "speed.frequency_hz": 10.0,
            "speed.match_timeout": 30.0, "speed.action_timeout": 60.0, "speed.step": 0.2}


def speed_window(peer: Peer, t0: float, sent: JointTrajectory) -> tuple[float, float]:
    """The speed learner's cycle after its goal ``sent`` started at ``t0`` s: the accelerometer to 1.2 s after the
    motion; MOTION_END's and END's stamps."""
    motion = motion_end(sent)
    return t0 + motion, imu_window(peer, t0, motion, motion + 1.2)


def mark(pub, kind: int, cycle: int, t: float, start: float, names: Sequence[str], poses) -> None:
    """A cycle event stamped ``t`` s carrying its START's stamp ``start`` s, naming the move (start and goal poses)."""
    msg = CycleEvent(event=kind, cycle=cycle, task="per_move", joint_names=list(names),
                     start_positions=[float(x) for x in poses[0]], goal_positions=[float(x) for x in poses[1]])
    msg.header.stamp = sec_to_time(t)
    set_start_stamp(msg, start)
    pub.publish(msg)


def one_cycle(peer: Peer, pub, cycle: int, names, poses, trajectory: JointTrajectory,
              window: Callable[[Peer, float, JointTrajectory], tuple[float, float]]
              ) -> tuple[dict[str, float], JointTrajectory]:
    """One move as one cycle at ``100 + 10 cycle`` s, its START sent by ``pub`` (the peer's, or a StartLost: then
    MOTION_END and END go once it has matched the learner, after the goal ran, as send_goal --cycle does):
    the learner's report and what the controller received. ``window(peer, t0, sent)`` publishes the accelerometer and
    gives MOTION_END's and END's stamps."""
    t0 = 100.0 + 10.0 * cycle
    mark(pub, CycleEvent.START, cycle, t0, t0, names, poses)
    sent = peer.run_goal(trajectory, f"the goal of cycle {cycle}")
    motion, end = window(peer, t0, sent)
    peer.spin_until(lambda: pub.get_subscription_count() >= 1, "the learner matching the events' publisher")
    mark(pub, CycleEvent.MOTION_END, cycle, motion, t0, names, poses)
    mark(pub, CycleEvent.END, cycle, end, t0, names, poses)
    return peer.report(cycle), sent


def learner_run(start_node, ros_context, program, params: dict, inputs, controller: str, names, poses, trajectory,
                window, missed: bool) -> tuple[list[dict[str, float]], list[JointTrajectory], dict, list[str]]:
    """A fresh learner (its own process) and two cycles of one move, the second's START seen or missed: the reports,
    the goals at the controller, the state file's moves and the learner's log lines."""
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, controller, imu=True)
    try:
        peer.spin_until(lambda: peer.learner_up(inputs, set()), "the learner's subscriptions and action server")
        got = [one_cycle(peer, StartLost(program) if missed and cycle == 1 else peer.events, cycle, names,
                         poses, trajectory, window) for cycle in (0, 1)]
        logs = list(peer.logs)
        assert learner.stop(timeout=60.0) == 0, learner.log_path.read_text()
    finally:
        peer.destroy()
    doc = json.loads(pathlib.Path(params["state_file"]).read_text())
    return [r for r, _ in got], [s for _, s in got], doc["moves"], logs


def same(missed: dict[str, float], seen: dict[str, float]) -> None:
    assert sorted(missed) == sorted(seen), (missed, seen)
    for name, value in seen.items():
        assert missed[name] == pytest.approx(value, rel=1e-9, abs=1e-12, nan_ok=True), name


def stood_in(logs: list[str]) -> bool:
    return any("cycle 1: its START was missed; stood in for by the MOTION_END's start stamp, 110.000 s" in m
               for m in logs)


def test_the_speed_learner_learns_from_a_cycle_whose_start_it_missed_as_from_the_same_cycle_seen(
        start_node, ros_context, program, tmp_path):
    runs = {}
    for missed in (False, True):
        runs[missed] = learner_run(start_node, ros_context, program, speed_params(tmp_path / f"{missed}.json"),
                                   SPEED_INPUTS, SPEED_CONTROLLER, NAMES, SPEED_MOVES[0], plan(0), speed_window, missed)
    (seen, seen_goals, seen_moves, seen_logs), (missed_, missed_goals, missed_moves, logs) = runs[False], runs[True]
    assert stood_in(logs) and not stood_in(seen_logs), logs
    for report in (*seen, *missed_):
        assert "skipped" not in report, report
    # the missed cycle's goal ran at the factor learned in cycle 0 (1.2), and it raised it as the seen one did
    assert seen[1]["speed_factor"] == pytest.approx(1.2) and seen[1]["factor_next"] == pytest.approx(1.4)
    same(missed_[1], seen[1])
    assert motion_end(missed_goals[1]) == pytest.approx(motion_end(seen_goals[1]), abs=1e-9)
    assert missed_moves == seen_moves


def test_the_mrilc_learner_learns_from_a_cycle_whose_start_it_missed_as_from_the_same_cycle_seen(
        start_node, ros_context, program, tmp_path):
    move = ARM_MOVES[0]

    def window(peer: Peer, t0: float, _sent: JointTrajectory) -> tuple[float, float]:
        accelerometer(peer, t0, 0, WINDOW)
        return t0 + float(move.duration), t0 + WINDOW

    runs = {}
    for missed in (False, True):
        runs[missed] = learner_run(start_node, ros_context, program, mrilc_params(tmp_path / f"{missed}.json"),
                                   MRILC_INPUTS, MRILC_CONTROLLER, JOINT_NAMES, (move.positions[0], move.positions[-1]),
                                   goal(0), window, missed)
    (seen, seen_goals, seen_moves, seen_logs), (missed_, missed_goals, missed_moves, logs) = runs[False], runs[True]
    assert stood_in(logs) and not stood_in(seen_logs), logs
    for report in (*seen, *missed_):
        assert "skipped" not in report, report
    # the missed cycle's goal ran with the correction learned in cycle 0, and learned the same next one
    assert seen[1]["iteration"] == 2.0 and seen[1]["max_correction_rad"] > 0.0, seen[1]
    same(missed_[1], seen[1])
    for a, b in zip(missed_goals[1].points, seen_goals[1].points, strict=True):
        assert list(a.positions) == pytest.approx(list(b.positions), rel=0, abs=1e-12)
    assert missed_moves == seen_moves  # the learned coefficients, digit for digit


def first_cycle_missed(start_node, ros_context, program, params: dict, inputs, controller: str, names,
                       moves: Sequence[tuple], plans: Sequence[JointTrajectory], window, how: str
                       ) -> tuple[dict[str, float], dict[str, float]]:
    """A move's first cycle whose START a per-move learner (its own process) missed, and the move's next cycle: cycle 0
    of move 1, seen (the learner listens from the start: its samples reach back to the stand-in's stamp, the window
    rule's other reason not to learn); cycle 1, move 0's first, its START lost; cycle 2 of move 0, seen. Shown: cycle
    1's goal, of a move not known yet, waits the learner's match timeout for a START that never comes and reaches the
    controller as planned; the stand-in at MOTION_END finds the goal matched to no cycle, and the cycle is reported
    not learned from with that reason (the learner's UNMATCHED, ending with ``how``: what the goal went without).
    Returns the reports of cycles 0 and 2."""
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, controller, imu=True)
    try:
        peer.spin_until(lambda: peer.learner_up(inputs, set()), "the learner's subscriptions and action server")
        other, _ = one_cycle(peer, peer.events, 0, names, moves[1], plans[1], window)
        got, sent = one_cycle(peer, StartLost(program), 1, names, moves[0], plans[0], window)
        assert got == {"skipped": 1.0}, got
        assert sent.points == plans[0].points  # as planned
        line = ("cycle 1 not learned from: its START was missed and its goal, which came before the stand-in, matched"
                f" no move known then (the move's first cycle): {how}")
        peer.spin_until(lambda: any(line in m for m in peer.logs), "the learner's line on cycle 1")
        assert any(m.startswith("a goal matched no move's START") for m in peer.logs), peer.logs  # its WARN
        first, _ = one_cycle(peer, peer.events, 2, names, moves[0], plans[0], window)
        assert learner.stop(timeout=60.0) == 0, learner.log_path.read_text()
    finally:
        peer.destroy()
    return other, first


def test_a_new_moves_first_cycle_whose_start_the_speed_learner_missed_runs_as_planned_and_is_reported(
        start_node, ros_context, program, tmp_path):
    """:func:`first_cycle_missed` for the speed learner (its match timeout 2 s): cycle 2 is move 0's first learned
    from, at factor 1 (the next 1.2), as cycle 0 was move 1's."""
    params = {**speed_params(tmp_path / "state.json"), "speed.match_timeout": 2.0}
    other, first = first_cycle_missed(start_node, ros_context, program, params, SPEED_INPUTS, SPEED_CONTROLLER,
                                      NAMES, SPEED_MOVES, (plan(0), plan(1)), speed_window,
                                      "it went as planned, its factor not recorded")
    for got in (other, first):
        assert "skipped" not in got, got
        assert got["speed_factor"] == pytest.approx(1.0) and got["factor_next"] == pytest.approx(1.2), got


def test_a_known_moves_cycle_whose_start_was_missed_and_whose_goal_leaves_out_its_start_is_reported_so(
        start_node, ros_context, program, tmp_path):
    """A goal that leaves out its start point (a FollowJointTrajectory goal need not begin where the robot stands) is
    matched to its cycle by its START (its last point the START's goal pose), not before it: with the START missed
    the goal waits the match timeout and goes as planned, and the cycle's reason says the goal did not match its move
    (not "the move's first cycle", which it is not). The speed learner, its own process; cycle 0 of the move seen."""
    trimmed = plan(0)
    trimmed.points = trimmed.points[1:]  # from the first point after the start (t > 0)
    learner = start_node("shaper_nodes", "learner", {**speed_params(tmp_path / "state.json"),
                                                     "speed.match_timeout": 2.0})
    peer = Peer(ros_context, SPEED_CONTROLLER, imu=True)
    try:
        peer.spin_until(lambda: peer.learner_up(SPEED_INPUTS, set()), "the learner's subscriptions and action server")
        got, _ = one_cycle(peer, peer.events, 0, NAMES, SPEED_MOVES[0], trimmed, speed_window)
        assert "skipped" not in got and got["factor_next"] == pytest.approx(1.2), got  # matched by its START
        got, sent = one_cycle(peer, StartLost(program), 1, NAMES, SPEED_MOVES[0], trimmed, speed_window)
        assert got == {"skipped": 1.0}, got
        assert sent.points == trimmed.points  # as planned
        line = ("cycle 1 not learned from: its START was missed and its goal, which came before the stand-in, did not"
                " match its move: an early goal is matched by its first and last points, within 0.001 rad of the"
                " move's start and goal poses: it went as planned, its factor not recorded")
        peer.spin_until(lambda: any(line in m for m in peer.logs), "the learner's line on cycle 1")
        assert learner.stop(timeout=60.0) == 0, learner.log_path.read_text()
    finally:
        peer.destroy()


def test_a_new_moves_first_cycle_whose_start_the_mrilc_learner_missed_runs_uncorrected_and_is_reported(
        start_node, ros_context, program, tmp_path):
    """:func:`first_cycle_missed` for the MRILC learner per move (its match timeout 2 s; the simulated arm's lifted
    operator): cycle 2 is move 0's first iteration, as cycle 0 was move 1's."""
    def window(peer: Peer, t0: float, sent: JointTrajectory) -> tuple[float, float]:
        index = next(i for i, m in enumerate(ARM_MOVES)  # the move whose goal pose the goal ends at
                     if list(sent.points[-1].positions) == pytest.approx(m.positions[-1].tolist(), abs=1e-9))
        accelerometer(peer, t0, index, WINDOW)
        return t0 + float(ARM_MOVES[index].duration), t0 + WINDOW

    params = {**mrilc_params(tmp_path / "state.json"), "mrilc_moves.match_timeout": 2.0}
    poses = [(m.positions[0], m.positions[-1]) for m in ARM_MOVES]
    other, first = first_cycle_missed(start_node, ros_context, program, params, MRILC_INPUTS, MRILC_CONTROLLER,
                                      JOINT_NAMES, poses, (goal(0), goal(1)), window,
                                      "it went uncorrected, without the move's plan")
    for got in (other, first):
        assert "skipped" not in got, got
        assert got["iteration"] == 1.0, got


def test_a_stale_record_is_ignored_and_a_stood_in_start_gets_its_goals_record(ros_context, program, tmp_path):
    """The shaper node's ``~/shaped_goals`` is latched (depth 16): a learner that starts receives the records of goals
    sent before it. A stale FALLBACK of a move, stamped long before the move's next START, took that cycle (the START
    claimed the latest record of its move) and refused it. Now a record goes to a cycle only if stamped from the
    cycle's START on (less 0.5 s): the cycle is learned from. And a cycle whose START the learner missed gets its
    goal's record as one seen would (the stood-in START goes to the records' book): its FALLBACK refuses it, where
    the record was dropped at END and the cycle learned from. The learner in-process (the test reads its book); the
    peer plays the shaper node's record publisher (as the speed learner sends its goals on to the shaper node's
    proxy, the peer's controller stands for both)."""
    from shaper_nodes.nodes.learner import LearnerNode

    peer_ex = SingleThreadedExecutor(context=ros_context)
    shaper = Node("shaper", context=ros_context)
    records = shaper.create_publisher(ShapedGoal, "/shaper/shaped_goals", SHAPED_GOALS_QOS)

    def record(how: int, stamp: float, detail: str = "") -> None:
        msg = ShapedGoal(shaped_with=how, detail=detail, joint_names=NAMES,
                         start_positions=list(SPEED_MOVES[0][0]), goal_positions=list(SPEED_MOVES[0][1]))
        msg.header.stamp = sec_to_time(stamp)
        msg.shaper.source, msg.shaper.revision = "parameters", 1
        records.publish(msg)

    record(ShapedGoal.FALLBACK, 80.0, "no answer from the scheduler: stale")  # a goal sent before the learner began
    learner = LearnerNode(context=ros_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in speed_params(tmp_path / "state.json").items()])
    peer_ex.add_node(learner)
    peer_ex.add_node(shaper)
    peer = Peer(ros_context, SPEED_CONTROLLER, peer_ex, imu=True)

    def goal_recorded(how: int, stamp: float, detail: str = "") -> Callable[[Peer, float, JointTrajectory],
                                                                            tuple[float, float]]:
        def then(peer: Peer, t0: float, sent: JointTrajectory) -> tuple[float, float]:
            record(how, stamp, detail)  # the goal's record, as the shaper node sends it on
            peer.spin_until(lambda: records.wait_for_all_acked(Duration(seconds=0.05)), "the record acknowledged")
            return speed_window(peer, t0, sent)
        return then

    try:
        peer.spin_until(lambda: learner.goals.unclaimed == 1 and peer.client.server_is_ready()
                        and learner.mode.proxy._client.server_is_ready() and peer.events.get_subscription_count(),
                        "the stale record in the learner's book, the learner's action server and the controller")
        got, _ = one_cycle(peer, peer.events, 0, NAMES, SPEED_MOVES[0], plan(0),
                           goal_recorded(ShapedGoal.ACTIVE, 100.0))
        assert "skipped" not in got and got["factor_next"] == pytest.approx(1.2), got  # the stale FALLBACK ignored
        # the START of cycle 1 missed; its goal fell back (its record stamped in the cycle): refused as if seen
        got, _ = one_cycle(peer, StartLost(program), 1, NAMES, SPEED_MOVES[0], plan(0),
                           goal_recorded(ShapedGoal.FALLBACK, 110.0, "no answer from the scheduler: paused"))
        assert learner.events.rule.stood_in == 1
        assert got == {"skipped": 1.0}
        peer.spin_until(lambda: any(m.startswith("cycle 1 not learned from: its goal was shaped with the active shaper"
                                                 " (parameters, revision 1), not for its final pose: no answer from the"
                                                 " scheduler: paused") for m in peer.logs), "the learner's line")
        # the next cycle, its START seen and its goal scheduled, learns on at the factor cycle 0 left
        got, _ = one_cycle(peer, peer.events, 2, NAMES, SPEED_MOVES[0], plan(0),
                           goal_recorded(ShapedGoal.ACTIVE, 120.0))
        assert "skipped" not in got and got["speed_factor"] == pytest.approx(1.2), got
    finally:
        peer_ex.shutdown()
        peer.destroy()
        shaper.destroy_node()
        learner.destroy_node()


def test_the_payback_learner_chooses_the_same_factor_from_a_reference_whose_start_it_missed(start_node, ros_context,
                                                                                             program, tmp_path):
    """The LIST per move with the payback rule (the rig of tests/test_learning_list_kill.py: the scheduler, the shaper
    node asking it, the learner's proxy in front of the shaper node's recording each goal's waypoints, all their own
    processes): a new move's reference cycle whose START it missed gives the same M and the same factor chosen to pay
    (predicted from the goal recorded for the move, its time cost from the schedule at the goal) as the cycle seen."""
    from conftest import Starter
    from relearn_peer import LEARNER_PROXY
    from test_learning_list_kill import INPUTS as LIST_INPUTS
    from test_learning_list_kill import MOTION, Cell
    from test_learning_list_kill import MOVES as LIST_MOVES
    from test_learning_list_kill import NAMES as LIST_NAMES
    from test_learning_list_kill import plan as list_plan

    def reference(missed: bool) -> tuple[dict[str, float], list[str], dict]:
        starter = Starter(start_node)
        state = tmp_path / f"{missed}.json"
        cell = Cell(starter, ros_context, state, LEARNER_PROXY, **{
            "payback.enabled": True, "payback.controller": "/shaper/follow_joint_trajectory",
            "payback.action_timeout": 60.0})
        try:
            cell.peer.spin_until(lambda: cell.peer.learner_up(LIST_INPUTS, set()), "the learner's subscriptions")
            cell.wait_started(0, 1)
            pub = StartLost(program) if missed else cell.peer.events
            t0 = cell.start(0)
            mark(pub, CycleEvent.START, 0, t0, t0, LIST_NAMES, LIST_MOVES[0])
            cell.imu(t0 - 1.0, 1.0 - 1 / 500)  # the accelerometer from 1 s before START: the samples reach back to it
            cell.peer.run_goal(list_plan(0), "the goal of cycle 0")
            end = cell.imu(t0, MOTION + 1.8)
            cell.peer.spin_until(lambda: pub.get_subscription_count() >= 1, "the learner matching the publisher")
            mark(pub, CycleEvent.MOTION_END, 0, t0 + MOTION, t0, LIST_NAMES, LIST_MOVES[0])
            mark(pub, CycleEvent.END, 0, end, t0, LIST_NAMES, LIST_MOVES[0])
            got, logs = cell.peer.report(0), list(cell.peer.logs)
        finally:
            cell.close()
            starter.stop_all()
        return got, logs, json.loads(state.read_text())["stacks"]

    seen, seen_logs, seen_stacks = reference(False)
    missed, logs, stacks = reference(True)
    line = "cycle 0: its START was missed; stood in for by the MOTION_END's start stamp, 100.000 s"
    assert any(line in m for m in logs) and not any(line in m for m in seen_logs), logs
    assert "skipped" not in seen and seen["phase.reference"] == 1.0, seen
    assert not math.isnan(seen["a1_next"]) and not math.isnan(seen["predicted"]), seen  # a factor chosen to pay
    same(missed, seen)
    assert stacks == seen_stacks
