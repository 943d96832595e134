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
from collections.abc import Callable

import numpy as np
import pytest
from conftest import RESTARTED, call_answered
from relearn_peer import LEARNER_PROXY, Peer
from sensor_msgs.msg import Imu, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import CycleEvent
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.learning.list import ListParams
from shaper_nodes.core.learning.list.pole_rule import PoleState
from shaper_nodes.core.learning.list.stack import FactorStack, stack_shaper
from shaper_nodes.core.learning.moves import MoveStore, keep_when_it_pays, move_key
from shaper_nodes.core.shaping.families import convolve
from shaper_nodes.nodes.learner_moves import resumed_line
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


def following(report: dict[str, float]) -> tuple[float, float]:
    """The factor a cycle's report says the move runs with next."""
    return report["a1_next"], report["t2_next"]


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


class Cell:
    """The rig (module docstring): the scheduler, the shaper node and the learner (``learner`` adds to its
    parameters) started, the peer playing the robot program and the controller, its goals sent to ``proxy``."""

    def __init__(self, start_node, ros_context, state, proxy: str, shaper_timeout: float = 60.0, **learner) -> None:
        self.start_node, self.state = start_node, state
        self.scheduler = start_node("shaper_nodes", "scheduler", SCHEDULER)
        start_node("shaper_nodes", "shaper_node", {"joint_names": NAMES, "command_rate": RATE,
                                                   "action.server_timeout": shaper_timeout,
                                                   "action.scheduler": "/scheduler", "action.controller": CONTROLLER})
        self.params = {"mode": "list", "shaper": "/scheduler", "list.structure": "zv2", "list.per_move": True,
                       "state_file": str(state), "topics.imu_reliable": True, "end_wait": 10.0, **learner}
        self.learner = start_node("shaper_nodes", "learner", self.params)
        self.peer = Peer(ros_context, CONTROLLER, imu=True, proxy=proxy)
        self.at = self.peer.node.create_client(ShaperAt, "/scheduler/shaper_at")
        #: added to each accelerometer sample (x, y, z m/s^2) of the move started at t0, sample k (500 Hz); None: none
        self.extra: Callable[[float, int], np.ndarray] | None = None

    def restart(self):
        """The learner started again (the same parameters: the same state file); its NodeProcess."""
        self.learner = self.start_node("shaper_nodes", "learner", self.params, env=RESTARTED)
        return self.learner

    def wait_started(self, moves: int, times: int) -> None:
        """Until learners have logged ``times`` times that they sent the saved factors of ``moves`` moves to the
        scheduler (a START before that is not learned from: its factor may not have been in place)."""
        line = resumed_line(moves)
        self.peer.spin_until(lambda: self.at.service_is_ready()
                             and sum(line in got for got in self.peer.logs) >= times,
                             f"the learner's saved factors sent to the scheduler ({times})")

    def event(self, kind: int, cycle: int, t: float, move: int) -> None:
        self.peer.event(kind, cycle, t, NAMES, *MOVES[move])

    def imu(self, t0: float, upto: float, ring: float = 0.05, since: float = 0.0) -> float:
        """The accelerometer of the move started at ``t0``, from ``since`` to ``upto`` s after its start, at 500 Hz:
        gravity, and after the motion a decaying 8 Hz ring of ``ring`` m/s^2; the last sample's stamp, s."""
        for k in range(int(round(since * 500)), int(round(upto * 500)) + 1):
            t = k / 500
            msg = Imu()
            msg.header.stamp = sec_to_time(t0 + t)
            a = ring * math.exp(-(t - MOTION) / 0.3) * math.sin(2 * math.pi * 8.0 * (t - MOTION)) if t > MOTION else 0.0
            x, y, z = (a, 0.0, 9.81) if self.extra is None else np.array([a, 0.0, 9.81]) + self.extra(t0, k)
            msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = x, y, z
            self.peer.imu.publish(msg)
        return t0 + t

    @staticmethod
    def start(cycle: int) -> float:
        """The cycle's START stamp, s."""
        return 100.0 + 10.0 * cycle

    def finish(self, cycle: int, move: int, ring: float = 0.05, since: float = 0.0) -> dict[str, float]:
        """The rest of the cycle after its goal: the accelerometer (from ``since`` s after the START) to 1.8 s after
        the motion (the residual window: 1 s from the shaped command's end), MOTION_END, END (stamped with the last
        sample's: the END's wait ends with it); the learner's report."""
        t0 = self.start(cycle)
        end = self.imu(t0, MOTION + 1.8, ring, since)
        self.event(CycleEvent.MOTION_END, cycle, t0 + MOTION, move)
        self.event(CycleEvent.END, cycle, end, move)
        return self.peer.report(cycle)

    def run(self, cycle: int, move: int,
            ring: Callable[[JointTrajectory], float] = lambda _: 0.05) -> tuple[dict[str, float], JointTrajectory]:
        """One move as one cycle, its goal through the proxy; its report and what the controller received (the
        ring's amplitude ``ring`` of that, m/s^2)."""
        self.event(CycleEvent.START, cycle, self.start(cycle), move)
        sent = self.peer.run_goal(plan(move), f"the goal of cycle {cycle}")
        return self.finish(cycle, move, ring(sent)), sent

    def kill(self, cycle: int, move: int, gone: bool = False) -> JointTrajectory:
        """The move's cycle interrupted by a kill -9 during its goal, half its window measured, and the learner
        started again (:meth:`relearn_peer.Peer.kill_during_move`); the state file as at the last END. Returns what
        the controller received."""
        t0 = self.start(cycle)
        self.event(CycleEvent.START, cycle, t0, move)
        saved = self.moves()
        sent = self.peer.kill_during_move(self.learner, self.restart, INPUTS, plan(move),
                                          lambda _: self.imu(t0, MOTION + 0.5), self.state,
                                          f"the goal of cycle {cycle}", gone)
        assert self.moves() == saved  # as at the last END
        return sent

    def end_killed(self, cycle: int, move: int) -> None:
        """The interrupted cycle's rest (its accelerometer after the kill, MOTION_END, END) at the restarted learner:
        not learned from (END without its START)."""
        got = self.finish(cycle, move, since=MOTION + 0.5 + 1 / 500)
        assert got == {"skipped": 1.0}, got

    def ask(self, move: int, with_start: bool) -> tuple[np.ndarray, np.ndarray]:
        """The scheduler's shaper at the move's goal: for the move (``with_start``: its factor over the schedule)
        or the schedule alone; (amplitudes, times s)."""
        start, goal = MOVES[move]
        req = ShaperAt.Request(pose=JointState(name=NAMES, position=goal))
        if with_start:
            req.start = JointState(name=NAMES, position=start)
        resp = call_answered(self.peer.ex, self.at, req, "the scheduler's shaper_at", timeout=60.0)
        assert resp.success, resp.message
        return np.asarray(resp.shaper.amplitudes), np.asarray(resp.shaper.times)

    def shaped_by_saved(self, traj: JointTrajectory, move: int) -> None:
        """``traj`` (at the controller) ran with the move's saved correction: the scheduler's shaper for the move
        is the schedule convolved with the state file's correction, and ``traj`` is the move's plan shaped by it: as
        long as the plan plus that shaper (its FIR on the command grid: up to two periods longer; a factor's T2 is
        25 periods or more, so the goal shaped by the schedule alone would be shorter)."""
        saved = self.moves()["moves"]["moves"][KEYS[move]]["correction"]
        want = convolve(self.ask(move, False), (np.asarray(saved["amplitudes"]), np.asarray(saved["times"])))
        amplitudes, times = self.ask(move, True)
        np.testing.assert_allclose(amplitudes, want[0], atol=1e-12)
        np.testing.assert_allclose(times, want[1], atol=1e-12)
        longer = self.longer(traj, move)
        assert -1e-9 <= longer - times[-1] <= 2.0 / RATE + 1e-9, (longer, times[-1])

    @staticmethod
    def longer(traj: JointTrajectory, move: int) -> float:
        """How much longer ``traj`` is than the move's plan, s."""
        return duration_to_sec(traj.points[-1].time_from_start) - duration_to_sec(plan(move).points[-1]
                                                                                  .time_from_start)

    def moves(self) -> dict:
        return json.loads(self.state.read_text())

    def close(self) -> None:
        self.peer.destroy()


def points(traj: JointTrajectory) -> list[tuple[float, list[float]]]:
    return [(duration_to_sec(p.time_from_start), list(p.positions)) for p in traj.points]


def test_payback_a_kill_9_during_a_move_resumes_every_moves_factor_from_its_saved_state(start_node, ros_context,
                                                                                        tmp_path):
    state = tmp_path / "learner_state.json"
    state.write_text(json.dumps(state_doc()))
    cell = Cell(start_node, ros_context, state, LEARNER_PROXY, **{
        "payback.enabled": True, "payback.controller": "/shaper/follow_joint_trajectory",
        "payback.action_timeout": 60.0})
    try:
        cell.peer.spin_until(lambda: cell.peer.learner_up(INPUTS, set()), "the learner's subscriptions and server")
        cell.wait_started(2, 1)

        # home -> pick runs with its kept factor
        got, sent0 = cell.run(0, 0)
        assert got["phase.kept"] == 1.0 and used(got) == pair(0)
        cell.shaped_by_saved(sent0, 0)
        assert cell.moves()["stacks"][KEYS[1]]["trial"] == list(pair(1))

        # pick -> home's trial: killed while the controller runs its goal, half its window measured; not judged
        sent1 = cell.kill(1, 1, gone=True)
        cell.shaped_by_saved(sent1, 1)
        cell.wait_started(2, 2)
        cell.end_killed(1, 1)

        # every move resumes from its saved state: the same goal at the controller as before the kill
        got, after0 = cell.run(2, 0)
        assert got["phase.kept"] == 1.0 and used(got) == pair(0)
        assert points(after0) == points(sent0)
        got, after1 = cell.run(3, 1)
        assert got["phase.trial"] == 1.0 and used(got) == pair(1)
        assert points(after1) == points(sent1)
        assert got["M"] < BASE and got["factors_kept"] == 1.0, got  # judged now: kept
        doc = cell.moves()
        assert doc["stacks"][KEYS[1]]["kept"] == [list(pair(1))] and doc["stacks"][KEYS[1]]["trial"] is None
        assert [doc["moves"]["moves"][k]["cycles"] for k in KEYS] == [4, 2]
    finally:
        cell.close()


def test_iterative_a_kill_9_during_a_move_resumes_every_moves_learner_from_its_saved_state(start_node, ros_context,
                                                                                           tmp_path):
    """The iterative LIST per move (no payback rule: the goals go to the shaper node's proxy, the learner is not in
    their path), learning from scratch: each move's reference (the schedule alone; the ring 0.05 m/s^2), then its
    learner's factors (a factor over the schedule at the controller: the ring 0.03 m/s^2, so each trial pays). The
    learner is killed during pick -> home's first trial (its goal at the controller, half its window measured): the
    goal ends as usual (the shaper node's proxy is not the learner), the state file as at the last END. Started
    again, the interrupted cycle is not learned from; each move's next goal reaches the controller shaped with its
    saved factor (the same points as before the kill for pick -> home) and its learner resumes at the next iteration
    from the factor saved (its ``a1_used``, ``t2_used`` the last report's ``a1_next``, ``t2_next``)."""
    state = tmp_path / "learner_state.json"
    cell = Cell(start_node, ros_context, state, "/shaper/follow_joint_trajectory")
    schedule: dict[int, float] = {}

    def ring(move: int) -> Callable[[JointTrajectory], float]:
        """The ring after a goal of the move: smaller with a factor over the schedule (the goal longer than the plan
        by more than the schedule's shaper and two command periods)."""
        def amplitude(traj: JointTrajectory) -> float:
            return 0.03 if cell.longer(traj, move) > schedule[move] + 2.0 / RATE + 1e-9 else 0.05
        return amplitude

    try:
        cell.peer.spin_until(lambda: cell.peer.learner_up(INPUTS, set()), "the learner's subscriptions")
        cell.wait_started(0, 1)
        schedule.update({m: float(cell.ask(m, False)[1][-1]) for m in (0, 1)})
        reports = [cell.run(cycle, move, ring(move))[0] for cycle, move in ((0, 0), (1, 1), (2, 0))]
        assert [r["iteration"] for r in reports] == [1.0, 1.0, 2.0], reports
        assert all(r["applied"] == 1.0 and r["held"] == 0.0 for r in reports), reports
        assert math.isnan(reports[1]["a1_used"]) and not math.isnan(reports[1]["a1_next"]), reports[1]
        saved = cell.moves()

        # pick -> home's first trial: killed during its goal, half its window measured
        sent = cell.kill(3, 1)
        assert ring(1)(sent) == 0.03  # it ran with the factor
        cell.shaped_by_saved(sent, 1)
        cell.wait_started(2, 1)
        cell.end_killed(3, 1)
        assert cell.moves() == saved

        # every move resumes: its saved factor at the controller, the next iteration from it
        got, after1 = cell.run(4, 1, ring(1))
        assert got["iteration"] == 2.0 and used(got) == pytest.approx(following(reports[1]), rel=1e-12), got
        assert points(after1) == points(sent)
        got, after0 = cell.run(5, 0, ring(0))
        assert got["iteration"] == 3.0 and used(got) == pytest.approx(following(reports[2]), rel=1e-12), got
        assert ring(0)(after0) == 0.03
    finally:
        cell.close()


def test_a_cycle_whose_end_never_came_is_reported_not_dropped(start_node, ros_context, tmp_path):
    """A cycle whose END never reaches the learner (lost while it was paused past the DDS lease, session 13's walk:
    its START came before the pause, its END while it was out of the graph) was replaced by the next START without a
    word: no log line, no report. It is reported as not learned from when the next cycle's event comes, and the
    next cycle is learned from as usual."""
    cell = Cell(start_node, ros_context, tmp_path / "learner_state.json", "/shaper/follow_joint_trajectory")
    try:
        cell.peer.spin_until(lambda: cell.peer.learner_up(INPUTS, set()), "the learner's subscriptions")
        cell.wait_started(0, 1)
        assert cell.run(0, 0)[0]["iteration"] == 1.0
        t0 = cell.start(1)  # pick -> home: START, its goal, its accelerometer; MOTION_END and END lost
        cell.event(CycleEvent.START, 1, t0, 1)
        cell.peer.run_goal(plan(1), "the goal of cycle 1")
        cell.imu(t0, MOTION + 1.8)
        got, _ = cell.run(2, 0)
        assert got["iteration"] == 2.0 and "skipped" not in got, got
        assert cell.peer.report(1) == {"skipped": 1.0}
        line = "cycle 1 not learned from: its END never came"
        cell.peer.spin_until(lambda: any(line in got for got in cell.peer.logs), "the learner's line on cycle 1")
    finally:
        cell.close()


#: the pooled-pole test's accelerometer noise per axis, m/s^2, and the loop's transient (50 Hz, damping 0.6)
NOISE, LOOP_HZ, LOOP_ZETA = 0.005, 50.0, 0.6


def test_payback_the_pooled_references_and_the_trial_at_the_pole_survive_kill_9_between_and_during_cycles(
        start_node, ros_context, tmp_path):
    """The pooled-pole rule (``payback.pool_cycles`` 3, nodes/learner_payback_pole.py): pick -> home has a
    reference measured and its references pooled (its factor from one window did not pay: state file). Its
    reference cycles with noise (``NOISE``, seeded per cycle) and the 8 Hz ring pool their windows (the state file's
    ``poles``: the count and a running sum of one window's samples); the learner is killed -9 during the second
    (its goal at the controller: not learned from, the pool as saved) and between the next two (restarted on the
    state file: the pool resumes at its count). The third window pooled holds the loop's transient (50 Hz, damping
    0.6, at the shaped command's end): the pole found in the mean, a factor on it chosen by the time rule and tried;
    its trial (no transient) is judged at the pole and kept."""
    state = tmp_path / "learner_state.json"
    doc = state_doc()
    stacks = doc["stacks"]
    stacks[KEYS[1]] = FactorStack().to_dict()  # pick -> home: its reference measured, no factor
    doc["moves"]["moves"][KEYS[1]]["correction"] = None
    doc["poles"] = {KEYS[1]: PoleState(pooled_only=True).to_dict()}
    state.write_text(json.dumps(doc))
    cell = Cell(start_node, ros_context, state, LEARNER_PROXY, **{
        "payback.enabled": True, "payback.controller": "/shaper/follow_joint_trajectory",
        "payback.action_timeout": 60.0, "payback.pool_cycles": 3})
    loop: dict[int, float] = {}  # cycle -> the transient's amplitude at the shaped command's end, m/s^2

    def extra(t0: float, k: int) -> np.ndarray:
        cycle = int(round((t0 - 100.0) / 10.0))
        noise = np.random.default_rng(cycle).normal(0.0, NOISE, (int(round((MOTION + 1.8) * 500)) + 1, 3))[k]
        t = k / 500 - MOTION - sched_end
        w = 2 * math.pi * LOOP_HZ
        a = loop.get(cycle, 0.0) * math.exp(-LOOP_ZETA * w * t) * math.cos(w * math.sqrt(1 - LOOP_ZETA**2) * t) \
            if t >= 0 else 0.0
        return noise + np.array([a, 0.0, 0.0])

    def pool() -> dict | None:
        return cell.moves().get("poles", {}).get(KEYS[1])

    try:
        cell.peer.spin_until(lambda: cell.peer.learner_up(INPUTS, set()), "the learner's subscriptions and server")
        cell.wait_started(2, 1)
        sched_end = float(cell.ask(1, False)[1][-1])
        cell.extra = extra
        got, _ = cell.run(0, 1)
        assert got["phase.reference"] == 1.0 and got["pooled"] == 1.0 and got["held"] == 0.0, got
        assert math.isnan(got["a1_next"]) and pool()["pool"]["count"] == 1  # no pole in one window: again

        # killed during its next reference (its goal at the controller, half the window measured): not learned from
        cell.kill(1, 1)
        cell.wait_started(2, 2)
        cell.end_killed(1, 1)
        assert pool()["pool"]["count"] == 1
        got, _ = cell.run(2, 1)
        assert got["pooled"] == 2.0 and math.isnan(got["a1_next"]) and got["held"] == 0.0, got
        saved = pool()
        assert saved["pool"]["count"] == 2 and len(saved["pool"]["times"]) <= 501  # one window's samples, 1 s
        assert np.asarray(saved["pool"]["sum"]).shape == (len(saved["pool"]["times"]), 3)

        # killed between two cycles: restarted on the state file, the pool resumes at its count
        before = cell.peer.learner_subscriptions(INPUTS)
        cell.learner.proc.kill()
        assert cell.learner.proc.wait(timeout=30) == -9
        cell.restart()
        cell.peer.spin_until(lambda: cell.peer.learner_up(INPUTS, before), "the restarted learner")
        cell.wait_started(2, 3)
        assert pool() == saved
        loop[3] = 0.3
        got, _ = cell.run(3, 1)
        assert got["pooled"] == 3.0 and got["held"] == 0.0 and got["at_pole"] > 3.0 * got["at_pole_error"], got
        a1, t2 = following(got)
        assert 0.5 <= a1 < 1.0 and 1.0 / (2.2 * LOOP_HZ) < t2 < 1.0 / (1.2 * LOOP_HZ), got  # on the loop's pole
        assert got["cost_s"] <= 0.002 + 1e-9, got
        judged = pool()
        assert judged["poles"] is not None and judged["pool"]["count"] == 0

        # the trial (no transient): judged at the pole, kept
        got, _ = cell.run(4, 1)
        assert got["phase.trial"] == 1.0 and used(got) == (a1, t2) and got["pooled"] == 1.0, got
        assert got["at_pole"] + 2.0 * math.hypot(got["at_pole_error"], judged["reference"][1]) \
            < judged["reference"][0], got
        assert got["factors_kept"] == 1.0 and got["held"] == 0.0, got
        doc = cell.moves()
        assert doc["stacks"][KEYS[1]]["kept"] == [[a1, t2]] and KEYS[1] not in doc.get("poles", {})
    finally:
        cell.close()
