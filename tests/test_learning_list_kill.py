"""A kill -9 of the LIST per-move learner (``payback.enabled``) during a move resumes every move from its saved state.

Real nodes over DDS, without the arm: the scheduler (a schedule of two modes over ``j1``, ZV, modes interpolated), the
shaper node's FollowJointTrajectory proxy asking it for each goal's shaper (``action.scheduler``; the move's learned
factor over the schedule at its goal), the learner with ``list.per_move`` and ``payback.enabled`` as its own process
(its proxy in front of the shaper node's: the goals' waypoints predict a factor's time cost), and the test's peer
(tests/relearn_peer.py) playing the robot program (cycle events, the goals, the tool accelerometer: a decaying 8 Hz
ring after the motion) and the controller (recording each goal it receives). The learner starts from a state file of
two moves: home -> pick kept its factor (it paid), pick -> home has a factor on trial.

Shown: the learner sends both saved factors to the scheduler at its start; home -> pick's cycle runs with its kept
factor. pick -> home's trial cycle is interrupted: the learner is killed (SIGKILL) after its goal went through the
learner's and the shaper node's proxies and reached the controller, which runs it, with half the move's residual
window measured (:meth:`relearn_peer.Peer.kill_during_move`: the controller finishes the goal, the state file was not
written since the last END and parses, the client never hangs on the killed server: it sees the server gone from its
graph once DDS's lease of the killed process ran out, and the restarted learner answers the goal's result
``STATUS_UNKNOWN``). Started again on the same state file, the learner sends the saved factors again; the interrupted
cycle's END is not learned from (END without its START: the trial is not judged on half a window); each move's next
goal reaches the controller exactly as before the kill (the same points: the schedule convolved with the state file's
correction, which the scheduler answers for the move); pick -> home's next cycle is its trial, judged then (kept: its
M is below the saved reference's), home -> pick stays kept.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from relearn_peer import Peer
from sensor_msgs.msg import Imu, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import CycleEvent
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.learning.list import ListParams
from shaper_nodes.core.learning.list.stack import FactorStack, stack_shaper
from shaper_nodes.core.learning.moves import MoveStore, keep_when_it_pays, move_key
from shaper_nodes.core.shaping.families import convolve
from shaper_nodes.ros.conversions import duration_to_sec, sec_to_duration, sec_to_time

pytestmark = pytest.mark.integration

NAMES = ["j1", "j2"]
MOVES = (([0.0, 0.0], [1.0, 0.5]), ([1.0, 0.5], [0.0, 0.0]))  # home -> pick, pick -> home
KEYS = [move_key(s, g) for s, g in MOVES]
CONTROLLER = "/list_kill_controller/follow_joint_trajectory"
MOTION = 1.0  # s, the planned motion (a cosine ramp), then a hold point 0.5 s later
RATE = 500.0  # Hz, the shaper node's command rate
FACTORS = (ListParams(0.6, 0.05), ListParams(0.55, 0.07))  # home -> pick's kept, pick -> home's on trial
BASE = 1.0  # m/s^2, the saved references' M (the ring below measures far less: a trial pays)
INPUTS = ("/cycle_events", "/tip_imu")
#: the scheduler: a schedule of two modes over j1 (the scheduler test's of test_learning_per_move.py)
SCHEDULER = {"premises": ["j1"], "rule_names": ["lo", "hi"], "interpolation": "modes", "family": "zv",
             "rules.lo.membership": ["triangular"], "rules.lo.membership_params": [0.0, 0.0, 2.0],
             "rules.lo.frequency_hz": [4.0, 11.0], "rules.lo.damping_ratio": [0.02, 0.02],
             "rules.hi.membership": ["triangular"], "rules.hi.membership_params": [0.0, 2.0, 2.0],
             "rules.hi.frequency_hz": [8.0, 15.0], "rules.hi.damping_ratio": [0.02, 0.02]}


def plan(move: int) -> JointTrajectory:
    """The move's planned goal: a cosine ramp over MOTION s, then a hold point 0.5 s later."""
    start, goal = (np.asarray(p) for p in MOVES[move])
    t = np.linspace(0.0, MOTION, 51)[1:]
    q = start + np.outer(0.5 * (1.0 - np.cos(math.pi * t / MOTION)), goal - start)
    points = [JointTrajectoryPoint(positions=row.tolist(), time_from_start=sec_to_duration(float(ti)))
              for ti, row in zip(t, q, strict=True)]
    points.append(JointTrajectoryPoint(positions=goal.tolist(), time_from_start=sec_to_duration(MOTION + 0.5)))
    return JointTrajectory(joint_names=NAMES, points=points)


def pair(move: int) -> tuple[float, float]:
    """The move's saved factor, (A1, T2 s)."""
    return FACTORS[move].a1, FACTORS[move].t2


def used(report: dict[str, float]) -> tuple[float, float]:
    """The factor a cycle ran with, from its report."""
    return report["a1_used"], report["t2_used"]


def state_doc() -> dict:
    """The learner's state file: both moves measured their reference (M = BASE); home -> pick kept its factor,
    pick -> home's is on trial."""
    store, stacks = MoveStore(), {}
    for (start, goal), factor, kept in zip(MOVES, FACTORS, (True, False), strict=True):
        entry, _ = store.entry(start, goal)
        keep_when_it_pays(entry, BASE, False)
        if kept:
            keep_when_it_pays(entry, 0.5 * BASE, True)
        stack = FactorStack([factor], None, True) if kept else FactorStack([], factor)
        sh = stack_shaper(stack.factors())
        assert sh is not None
        entry.correction, entry.cycles = (sh.amplitudes.tolist(), sh.times.tolist()), 2 if kept else 1
        stacks[entry.key] = stack.to_dict()
    return {"version": 1, "structure": "zv2", "per_move": True, "moves": store.to_doc(),
            "joint_names": {k: NAMES for k in KEYS}, "at_schedule": [], "stacks": stacks, "drift_warned": False}


def test_a_kill_9_during_a_move_resumes_every_moves_factor_from_its_saved_state(start_node, ros_context, tmp_path):
    state = tmp_path / "learner_state.json"
    state.write_text(json.dumps(state_doc()))
    start_node("shaper_nodes", "scheduler", SCHEDULER)
    start_node("shaper_nodes", "shaper_node", {"joint_names": NAMES, "command_rate": RATE,
                                               "action.server_timeout": 60.0, "action.scheduler": "/scheduler",
                                               "action.controller": CONTROLLER})
    params = {"mode": "list", "shaper": "/scheduler", "list.structure": "zv2", "list.per_move": True,
              "state_file": str(state), "topics.imu_reliable": True, "end_wait": 10.0, "payback.enabled": True,
              "payback.controller": "/shaper/follow_joint_trajectory", "payback.action_timeout": 60.0}
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, CONTROLLER, imu=True)
    at = peer.node.create_client(ShaperAt, "/scheduler/shaper_at")

    def event(kind: int, cycle: int, t: float, move: int) -> None:
        peer.event(kind, cycle, t, NAMES, *MOVES[move])

    def imu(t0: float, upto: float) -> None:
        """The accelerometer from the move's start ``t0`` to ``upto`` s after it, at 500 Hz: gravity, and after the
        motion a decaying 8 Hz ring of 0.05 m/s^2."""
        for k in range(int(round(upto * 500)) + 1):
            t = k / 500
            msg = Imu()
            msg.header.stamp = sec_to_time(t0 + t)
            ring = 0.05 * math.exp(-(t - MOTION) / 0.3) * math.sin(2 * math.pi * 8.0 * (t - MOTION)) \
                if t > MOTION else 0.0
            msg.linear_acceleration.x, msg.linear_acceleration.z = ring, 9.81
            peer.imu.publish(msg)

    def window(cycle: int) -> tuple[float, float]:
        """The cycle's START stamp and its END's (the residual window: 1 s from the shaped command's end)."""
        t0 = 100.0 + 10.0 * cycle
        return t0, t0 + MOTION + 1.8

    def finish(cycle: int, move: int) -> dict[str, float]:
        """The rest of the cycle after its goal: the accelerometer, MOTION_END, END; the learner's report."""
        t0, end = window(cycle)
        imu(t0, end - t0)
        event(CycleEvent.MOTION_END, cycle, t0 + MOTION, move)
        event(CycleEvent.END, cycle, end, move)
        return peer.report(cycle)

    def run(cycle: int, move: int) -> tuple[dict[str, float], JointTrajectory]:
        """One move as one cycle through the learner's proxy; its report and what the controller received."""
        event(CycleEvent.START, cycle, window(cycle)[0], move)
        sent = peer.run_goal(plan(move), f"the goal of cycle {cycle}")
        return finish(cycle, move), sent

    def move_shaper(move: int) -> tuple[np.ndarray, np.ndarray]:
        """The scheduler's shaper for the move (its goal, from its start), and the state file's correction over
        the schedule alone at its goal; checked equal."""
        start, goal = MOVES[move]

        def ask(req: ShaperAt.Request) -> ShaperAt.Response:
            future = at.call_async(req)
            peer.spin_until(future.done, "the scheduler's answer")
            resp = future.result()
            assert resp.success, resp.message
            return resp

        pose = JointState(name=NAMES, position=goal)
        mine = ask(ShaperAt.Request(pose=pose, start=JointState(name=NAMES, position=start))).shaper
        schedule = ask(ShaperAt.Request(pose=pose)).shaper
        saved = json.loads(state.read_text())["moves"]["moves"][KEYS[move]]["correction"]
        want = convolve((np.asarray(schedule.amplitudes), np.asarray(schedule.times)),
                        (np.asarray(saved["amplitudes"]), np.asarray(saved["times"])))
        np.testing.assert_allclose(mine.amplitudes, want[0], atol=1e-12)
        np.testing.assert_allclose(mine.times, want[1], atol=1e-12)
        return np.asarray(mine.amplitudes), np.asarray(mine.times)

    def points(traj: JointTrajectory) -> list[tuple[float, list[float]]]:
        return [(duration_to_sec(p.time_from_start), list(p.positions)) for p in traj.points]

    def shaped_by(traj: JointTrajectory, move: int) -> None:
        """``traj`` (at the controller) is the move's plan shaped by the scheduler's shaper for it: as long as the
        plan plus that shaper (its FIR on the command grid: up to two periods longer; the factor's T2 is 25 periods
        or more, so the goal shaped by the schedule alone would be shorter)."""
        amplitudes, times = move_shaper(move)
        assert math.isclose(amplitudes.sum(), 1.0, abs_tol=1e-9) and len(times) > 2
        longer = duration_to_sec(traj.points[-1].time_from_start) - duration_to_sec(plan(move).points[-1]
                                                                                    .time_from_start)
        assert -1e-9 <= longer - times[-1] <= 2.0 / RATE + 1e-9, (longer, times[-1])  # its FIR: on the grid

    def moves() -> dict:
        return json.loads(state.read_text())

    def resumed() -> int:
        """How many times a learner logged that it sent the 2 saved moves' factors to the scheduler."""
        return sum("learning per move: 2 moves resumed from the state file" in line for line in peer.logs)

    try:
        peer.spin_until(lambda: peer.learner_up(INPUTS, set()) and at.service_is_ready(),
                        "the learner's subscriptions and action server, and the scheduler")
        peer.spin_until(lambda: resumed() == 1, "the learner's saved factors sent to the scheduler")

        # home -> pick runs with its kept factor
        got, sent0 = run(0, 0)
        assert got["phase.kept"] == 1.0 and used(got) == pair(0)
        shaped_by(sent0, 0)
        saved = moves()
        assert saved["stacks"][KEYS[1]]["trial"] == list(pair(1))

        # pick -> home's trial: killed while the controller runs its goal, half its window measured
        t0, end = window(1)
        event(CycleEvent.START, 1, t0, 1)
        sent1 = peer.kill_during_move(learner, lambda: start_node("shaper_nodes", "learner", params), INPUTS,
                                      plan(1), lambda _: imu(t0, MOTION + 0.5), state, "the goal of cycle 1",
                                      gone=True)
        shaped_by(sent1, 1)
        assert moves() == saved  # as at the last END: the trial not judged
        peer.spin_until(lambda: resumed() == 2, "the restarted learner's saved factors sent to the scheduler")
        event(CycleEvent.MOTION_END, 1, t0 + MOTION, 1)
        event(CycleEvent.END, 1, end, 1)  # the interrupted cycle's END: not learned from
        got = peer.report(1)
        assert got == {"skipped": 1.0}, got

        # every move resumes from its saved state: the same goal at the controller as before the kill
        got, after0 = run(2, 0)
        assert got["phase.kept"] == 1.0 and used(got) == pair(0)
        assert points(after0) == points(sent0)
        got, after1 = run(3, 1)
        assert got["phase.trial"] == 1.0 and used(got) == pair(1)
        assert points(after1) == points(sent1)
        assert got["M"] < BASE and got["factors_kept"] == 1.0, got  # judged now: kept
        doc = moves()
        assert doc["stacks"][KEYS[1]]["kept"] == [list(pair(1))] and doc["stacks"][KEYS[1]]["trial"] is None
        assert [doc["moves"]["moves"][k]["cycles"] for k in KEYS] == [4, 2]
    finally:
        peer.destroy()
