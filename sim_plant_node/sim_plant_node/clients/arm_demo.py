"""Arm demo: input shaping on the six-axis arm behind joint_trajectory_controller, over DDS.

Starts the sim plant (``plant.model: arm``, lockstep, with its joint_trajectory_controller
emulation), the shaper node (its FollowJointTrajectory proxy in front of the controller), the
identifier and the recorder as separate processes. The cases that need it first calibrate the
workspace with the ``calibrate`` node (its config/calibrate.yaml: a grid over shoulder_lift and
elbow, three excitations per pose) or reuse a calibration (``--calibration``). A MoveIt-like
client sends the pick-and-place cycle of :mod:`sim_plant_node.arm.task` move by move to the
shaper's action and marks each cycle on ``/cycle_events``. Cases: unshaped; ZV and ZVD designed at
the home pose's lowest mode (modal analysis of the arm); the identifier's recommendation from the
unshaped cycles (applied through its ``~/identify``); LIST learning over the cycles (the learner
node); ``fixed``, the calibration's fallback (``shaper.yaml``: ZV on the home pose's modes);
``scheduled``, the calibrated scheduler (``scheduler.yaml``) with the shaper node's
``action.scheduler``, so each goal is shaped for the modes at its final pose; ``scheduled_list``,
LIST learning on top of the schedule (the learner sends to the scheduler); ``scheduled_list_moves``,
LIST per move on top of the schedule (the learner's ``list.per_move``: every move marked as its own
cycle, each learning its own factor, which the scheduler applies to that move's goals; opt-in, with a
per-move, per-cycle table of its own); ``scheduled_mrilc_moves``, MRILC per move on top of the schedule (the
learner's ``mode: mrilc_moves``: the shaper node's proxy sends each shaped goal to the learner's, which adds the
move's learned joint profile correction and sends it to the controller; opt-in, the same per-move table);
``scheduled_speedup``, the schedule with a time-scaling factor learned per move (the learner's ``mode: speed_moves``
in front of the shaper node's proxy: :mod:`.arm_speed`; opt-in, the same per-move table).
For every move and case it measures (:mod:`sim_plant_node.arm.metrics`) the residual vibration
at the tool, the settling time, the move time plus settling time, the shaper's delay and the
tool-path deviation the shaping causes, and writes them as CSV, Markdown and a PNG plot.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import functools
import itertools
import json
import math
import os
import pathlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import arm_payload

RECORDED = ["/joint_states", "/tip_imu", "/cycle_events", "/shaper/active_shaper", "/diagnostics",
            "/learner/reports"]
RATE = 500.0
SUBSTEPS = 2  # the sim plant's arm.substeps (its default): the flange IMU at RATE x SUBSTEPS
#: the streams the demo's measures read (and the joint states, whose repeated stamp says the arm rests)
IMU, LINK, CMD, JOINTS = "/tip_imu", "/sim_plant/tip_state", "/sim_plant/reference", "/joint_states"
#: the nodes the sim plant waits for in lockstep (lockstep.readers): calibrate, this demo's client, the
#: identifier and the recorder
RECORDER = "/recorder"
READERS = ["/calibrate", "/conductor", "/identifier", RECORDER]
#: s of wall time a wait for the nodes may take before the demo stops with one line (a node starting at load 20
#: took over 60 s to be heard; a node that dies ends the wait at once through its process)
WAIT = 300.0
#: s of wall time the calibration may take (a guard against a hang: on a loaded machine, load average 30 and two
#: CPU hogs, its identification alone took over 6 min of a 15 min run)
CALIBRATION_TIMEOUT = 3600.0
DWELL = 1.5  # s at rest after each move (the gripper's time; the residual window is in it)
CASES = ("none", "zv", "zvd", "identified", "list", "fixed", "scheduled", "scheduled_list", "scheduled_list_moves",
         "scheduled_mrilc_moves", "payload", "scheduled_speedup")
#: the story ``./run demo`` tells: calibrate, then unshaped, the calibrated fixed shaper, the calibrated schedule
DEFAULT_CASES = ("none", "fixed", "scheduled")
#: cases that need a calibration
CALIBRATED = ("fixed", "scheduled", "scheduled_list", "scheduled_list_moves", "scheduled_mrilc_moves", "payload",
              "scheduled_speedup")
#: cases whose shaper node asks the scheduler for each goal (the shaper node is restarted for them)
SCHEDULED = ("scheduled", "scheduled_list", "scheduled_list_moves", "scheduled_mrilc_moves", "payload",
             "scheduled_speedup")
#: cases that mark every move as its own cycle on /cycle_events (the learner per move)
PER_MOVE = ("scheduled_list_moves", "scheduled_mrilc_moves", "payload", "scheduled_speedup")
#: cases that learn (their cycles: --list-cycles)
LEARNING = ("list", "scheduled_list", *PER_MOVE)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="demo [arm]", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=pathlib.Path, default=None,
                   help="output folder (default: out/demo-arm-<date-time> in the current folder)")
    p.add_argument("--cycles", type=int, default=1, help="pick-and-place cycles per fixed-shaper case (default 1;"
                   " the measures are the last cycle's)")
    p.add_argument("--list-cycles", type=int, default=8, help="cycles of LIST learning (default 8)")
    p.add_argument("--cases", default=",".join(DEFAULT_CASES),
                   help=f"cases to run, among {','.join(CASES)} (default {','.join(DEFAULT_CASES)}); those with a"
                   " schedule run last")
    p.add_argument("--calibration", type=pathlib.Path, default=None,
                   help="a calibration folder to use (scheduler.yaml, shaper.yaml) instead of calibrating first")
    p.add_argument("--noise", type=float, default=0.01, help="accelerometer noise, m/s^2 (default 0.01)")
    arm_payload.add_arguments(p)
    return p.parse_args(argv)


@dataclass
class Streams:
    """Stamped samples received by the client (times in simulated s)."""

    imu_t: list[float] = field(default_factory=list)
    imu: list[tuple[float, float, float]] = field(default_factory=list)
    link_t: list[float] = field(default_factory=list)
    link: list[list[float]] = field(default_factory=list)
    cmd_t: list[float] = field(default_factory=list)
    cmd: list[list[float]] = field(default_factory=list)
    clock: float = 0.0
    #: the simulated time the arm last rested at: a /joint_states stamp received twice (the plant republishes
    #: its last state at rest, and does not step until a goal comes); -inf before any
    rest: float = -math.inf
    js_last: float = -math.inf

    def window(self, which: str, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Samples of one move that started at ``t0`` and ended at ``t1``. Commands are stamped at the start of
        their period, so [t0, t1) (the next move's first command is stamped t1); states and the IMU at its end,
        so (t0, t1]."""
        t = np.asarray(getattr(self, which + "_t"))
        v = np.asarray(getattr(self, which))
        sel = (t >= t0) & (t < t1) if which == "cmd" else (t > t0) & (t <= t1)
        order = np.argsort(t[sel], kind="stable")
        return t[sel][order], v[sel][order]


@dataclass
class MoveRun:
    """One executed move: name, simulated start and end, the planned duration."""

    index: int
    name: str
    start: float
    planned: float
    end: float


class ArmClient:
    """The MoveIt-like client and the demo's measurements, on a :class:`Conductor` node."""

    def __init__(self, conductor: Any) -> None:
        from control_msgs.action import FollowJointTrajectory
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Imu, JointState

        from shaper_msgs.msg import CycleEvent, CycleReport
        from shaper_nodes.recordings.cdr_sensors import CdrError, JointStateReader, decode_imu
        from shaper_nodes.ros.action_client import ResilientActionClient
        from shaper_nodes.ros.lockstep_reader import (
            STREAM_QOS,
            AckWatch,
            LockstepReader,
            header_stamp,
            subscribe_draining,
        )

        from ..arm.dynamics import ArmModel

        self.c = conductor
        self.model = ArmModel()
        self.s = Streams()
        self.reports: list[Any] = []
        # the plant waits for this node (its lockstep.readers): acknowledged, and each stream checked for gaps
        self.lockstep = LockstepReader(conductor, {IMU: 1.0 / (RATE * SUBSTEPS), LINK: 1.0 / RATE, CMD: 1.0 / RATE,
                                                   JOINTS: 1.0 / RATE})
        took = self.lockstep.took

        # the per-step streams taken raw (serialized bytes, no message objects: a fraction of the CPU per message,
        # docs/results/benchmarks.md); the stamp and the fields used read by checked decoders, and a message that
        # does not decode logged and dropped (its gap then counts as lost)
        joints_read, link_read, cmd_read = JointStateReader(), JointStateReader(), JointStateReader()

        def refused(topic: str, err: CdrError) -> None:
            conductor.get_logger().error(f"{topic}: a message dropped: {err}", throttle_duration_sec=1.0)

        def on_imu(raw: bytes) -> None:
            try:
                t, a = decode_imu(raw)
            except CdrError as err:
                return refused(IMU, err)
            self.s.imu_t.append(t)
            self.s.imu.append(a)
            took(IMU, t)

        def on_link(raw: bytes) -> None:
            try:
                t, _, position = link_read(raw)
            except CdrError as err:
                return refused(LINK, err)
            self.s.link_t.append(t)
            self.s.link.append(list(position))
            took(LINK, t)

        def on_cmd(raw: bytes) -> None:
            try:
                t, _, position = cmd_read(raw)
            except CdrError as err:
                return refused(CMD, err)
            self.s.cmd_t.append(t)
            self.s.cmd.append(list(position))
            took(CMD, t)

        def on_joints(raw: bytes) -> None:
            try:
                t, _, _ = joints_read(raw)
            except CdrError as err:
                return refused(JOINTS, err)
            if t == self.s.js_last:
                self.s.rest = t
            self.s.js_last = t
            took(JOINTS, t)

        def on_clock(raw: bytes) -> None:  # rosgraph_msgs/Clock: the stamp right after the encapsulation
            if len(raw) < 12:
                return refused("/clock", CdrError(f"truncated /clock: {len(raw)} bytes, 12 expected"))
            self.s.clock = max(self.s.clock, header_stamp(raw))

        # every stream a measure depends on: reliable, deeper than the plant's lead over this reader; every queued
        # sample taken per wake-up (one executor turn per batch while the plant runs ahead)
        subscribe_draining(conductor, Imu, IMU, on_imu, STREAM_QOS)
        subscribe_draining(conductor, JointState, LINK, on_link, STREAM_QOS)
        subscribe_draining(conductor, JointState, CMD, on_cmd, STREAM_QOS)
        subscribe_draining(conductor, JointState, JOINTS, on_joints, STREAM_QOS)
        subscribe_draining(conductor, Clock, "/clock", on_clock, 100)
        conductor.create_subscription(CycleReport, "/learner/reports", self.reports.append, 100)
        #: what the recorder has taken (its lockstep acknowledgements)
        self.recorder = AckWatch(conductor, RECORDER)
        self.events = conductor.create_publisher(CycleEvent, "/cycle_events", 10)
        self.action = ResilientActionClient(conductor, FollowJointTrajectory, "/shaper/follow_joint_trajectory")
        self._Goal = FollowJointTrajectory.Goal
        self._CycleEvent = CycleEvent
        self._last_start: float | None = None  # the last move's start, simulated s
        #: a move ends where the arm rests after it (its goal may run shorter than planned: time-scaled)
        self.ends_at_rest = False

    # ------------------------------------------------------------------ driving
    def wait_listeners(self, n: int, timeout: float = WAIT) -> None:
        """Wait until the cycle events reach ``n`` matched subscriptions (this node's own among them)."""
        self.c.spin_until(lambda: self.events.get_subscription_count() >= n, timeout,
                          f"{n} matched subscriptions of /cycle_events")

    def wait_ready(self, listeners: int, timeout: float = WAIT) -> None:
        """Wait for the shaper's action server, ``listeners`` matched subscriptions of the cycle events (this
        node's own among them) and the sim plant's reference and tip state publishers."""
        self.c.spin_until(self.action.server_is_ready, timeout, "the shaper's FollowJointTrajectory server")
        self.wait_listeners(listeners, timeout)
        for topic in ("/sim_plant/reference", "/sim_plant/tip_state"):  # published only to subscribers
            self.c.spin_until(lambda t=topic: self.c.count_publishers(t) > 0, timeout, f"the sim plant's {topic}")

    def wait_recorder(self, topics: list[str], timeout: float = WAIT) -> None:
        """Wait until the recorder subscribes to ``topics`` (it subscribes to a topic once it sees it on the graph;
        the plant, which steps only once a goal comes, would otherwise run the first samples past it)."""
        self.recorder.wait_subscribed(self.c.spin_until, topics, timeout)

    def _goal(self, move: Any) -> Any:
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        from ..arm.description import JOINT_NAMES

        def dur(t: float) -> Duration:
            return Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000)

        pts = [JointTrajectoryPoint(positions=p.tolist(), velocities=v.tolist(), accelerations=a.tolist(),
                                    time_from_start=dur(t))
               for t, p, v, a in zip(move.times[1:], move.positions[1:], move.velocities[1:], move.accelerations[1:],
                                     strict=True)]
        last = move.positions[-1].tolist()
        pts.append(JointTrajectoryPoint(positions=last, velocities=[0.0] * 6, accelerations=[0.0] * 6,
                                        time_from_start=dur(move.duration + DWELL)))
        return self._Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES), points=pts))

    def _event(self, kind: int, cycle: int, t: float, start: np.ndarray, goal: np.ndarray) -> None:
        from shaper_nodes.ros.conversions import sec_to_time

        from ..arm.description import JOINT_NAMES

        msg = self._CycleEvent(event=kind, cycle=cycle, task="pick_and_place", joint_names=list(JOINT_NAMES),
                               start_positions=start.tolist(), goal_positions=goal.tolist())
        msg.header.stamp = sec_to_time(t)
        self.events.publish(msg)

    def rest_after(self, t: float, what: str) -> float:
        """The simulated time the arm rests at, once past ``t`` s (a /joint_states stamp received twice: at rest
        the plant republishes its last state and does not step)."""
        self.c.spin_until(lambda: self.s.rest > t, WAIT, f"the arm at rest (a repeated /joint_states stamp) {what}")
        return self.s.rest

    def wait_samples(self, end: float, what: str) -> None:
        """Wait until every stream a measure reads reached simulated time ``end`` s; on a timeout, one line names
        the streams that did not."""
        def reached() -> dict[str, float]:
            return {name: (times[-1] if times else -math.inf) for name, times in
                    (("/clock", [self.s.clock]), (IMU, self.s.imu_t), (LINK, self.s.link_t), (CMD, self.s.cmd_t))}
        try:
            self.c.spin_until(lambda: min(reached().values()) >= end - 0.0025, WAIT, "")
        except TimeoutError:
            late = ", ".join(f"{name} (up to t = {t:.3f} s)" for name, t in reached().items() if t < end - 0.0025)
            raise TimeoutError(f"no samples up to the end of {what} (t = {end:.3f} s) within {WAIT:g} s on"
                               f" {late}") from None

    def wait_recorded(self, end: float) -> None:
        """Wait until the recorder has taken every sample up to simulated time ``end`` s (its acknowledgement,
        which it sends on a wall-clock timer once the plant rests): closed before, the recording would lack the
        last samples still on their way to it."""
        self.recorder.wait_processed(self.c.spin_until, end, WAIT)

    def run_move(self, index: int, move: Any, on_start: Callable[[float], None] | None = None) -> MoveRun:
        """Send one move and wait for its end. It starts where the arm rests (the controller's clock: the plant
        does not step between goals, and the first controller update of the goal is at that time); ends
        ``move.duration + DWELL`` later, the goal's last point. ``on_start`` gets its start."""
        after = self._last_start if self._last_start is not None else -math.inf
        start = self.rest_after(after, f"before {move.name}")
        self._last_start = start
        if on_start is not None:
            on_start(start)
        future = self.action.send_goal_async(self._goal(move))
        self.c.spin_until(future.done, WAIT, f"the answer to the goal of {move.name}")
        handle = future.result()
        if not handle.accepted:
            raise RuntimeError(f"the goal of {move.name} was rejected (see the shaper's and the sim's logs)")
        result = handle.get_result_async()
        self.c.spin_until(result.done, 300.0, f"the result of {move.name}")
        res = result.result()
        if res.result.error_code != 0:
            raise RuntimeError(f"{move.name}: {res.result.error_code} {res.result.error_string}")
        end = self.rest_after(start, f"after {move.name}") if self.ends_at_rest else start + move.duration + DWELL
        self.wait_samples(end, move.name)
        return MoveRun(index, move.name, start, end - start - DWELL if self.ends_at_rest else move.duration, end)

    def run_cycle(self, cycle: int, moves: list[Any], progress: Callable[[], None]) -> list[MoveRun]:
        """One pick-and-place cycle. Its last move (the reach back home) is what ``/cycle_events`` marks as the
        learners' and the identifier's cycle: its timing from START is the same whatever the shaper, where the
        whole cycle's grows by the shaper's delay at every move."""
        from ..arm.task import CYCLE

        start, goal = CYCLE[-2][1], CYCLE[-1][1]
        runs = []
        for i, move in enumerate(moves):
            mark = None
            if i == len(moves) - 1:
                def mark(t: float) -> None:
                    self._event(self._CycleEvent.START, cycle, t, start, goal)
            runs.append(self.run_move(i, move, mark))
            progress()
        for run, nxt in itertools.pairwise(runs):
            run.end = nxt.start  # the sim is idle between goals: a move ends where the next one starts
        self._event(self._CycleEvent.MOTION_END, cycle, runs[-1].start + runs[-1].planned, start, goal)
        self._event(self._CycleEvent.END, cycle, runs[-1].end, start, goal)
        return runs

    def run_cycle_per_move(self, first: int, moves: list[Any], progress: Callable[[], None],
                           learned: Callable[[int], Any]) -> list[MoveRun]:
        """One pick-and-place cycle with every move marked as its own cycle on ``/cycle_events`` (cycles ``first``
        to ``first + len(moves) - 1``, each START naming the joints and the move's start and goal), for the learner
        per move; ``learned(cycle)`` waits for what the learner does with a move's cycle before the next move."""
        runs = []
        for i, move in enumerate(moves):
            cycle, q0, q1 = first + i, move.positions[0], move.positions[-1]

            def mark(t: float, cycle: int = cycle, q0: np.ndarray = q0, q1: np.ndarray = q1) -> None:
                self._event(self._CycleEvent.START, cycle, t, q0, q1)
            run = self.run_move(i, move, mark)
            self._event(self._CycleEvent.MOTION_END, cycle, run.start + run.planned, q0, q1)
            self._event(self._CycleEvent.END, cycle, run.end, q0, q1)
            report = learned(cycle)
            if self.ends_at_rest:  # the move's planned (time-scaled) duration, as the learner that scaled it says
                m = dict(zip(report.metric_names, report.metric_values, strict=True))
                run.planned = m.get("motion_s", run.planned)
            runs.append(run)
            progress()
        for run, nxt in itertools.pairwise(runs):
            run.end = nxt.start  # the sim is idle between goals: a move ends where the next one starts
        return runs

    # ------------------------------------------------------------------ measuring
    def tool_path(self, which: str, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        t, q = self.window(which, t0, t1)
        return t, self.model.tool_positions(q) if q.size else np.zeros((0, 3))

    def window(self, which: str, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        return self.s.window(which, t0, t1)

    def measure(self, run: MoveRun, reference_path: np.ndarray) -> tuple[Any, np.ndarray]:
        from ..arm.metrics import measure_move, motion_end

        ct, cq = self.window("cmd", run.start, run.end)
        commanded_end = motion_end(ct, cq)
        _, path = self.tool_path("cmd", run.start, run.end)
        it, imu = self.window("imu", run.start, run.end)
        lt, tool = self.tool_path("link", run.start, run.end)
        m = measure_move(run.name, run.start, run.planned, commanded_end, run.end, it, imu, lt, tool, path,
                         reference_path)
        return m, path


def _table(rows: list[dict[str, Any]]) -> list[str]:
    head = ["case", "move", "residual RMS m/s^2", "% of unshaped", "peak mm", "settling s", "move+settle s",
            "shaper delay s", "path deviation mm"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        move = f"{r['move']} ({r['lost']})" if r.get("lost") else r["move"]
        out.append(f"| {r['case']} | {move} | {r['residual_rms']:.4f} | {r['percent']:.1f} | {r['peak_mm']:.4f} |"
                   f" {r['settling_s']:.3f} | {r['move_and_settle_s']:.3f} | {r['delay_s']:.3f} |"
                   f" {r['path_deviation_mm']:.3f} |")
    return out


def _learned(client: ArmClient, cycle: int) -> Any:
    """The learner's report of ``cycle``, once it came (what the learner did with a move's cycle)."""
    client.c.spin_until(lambda: any(r.cycle == cycle for r in client.reports), 120.0, f"the learner's report of"
                        f" cycle {cycle}")
    return next(r for r in reversed(client.reports) if r.cycle == cycle)


def _per_move_table(per_move: list[list[tuple[MoveRun, Any, Any]]], rows: list[dict[str, Any]],
                    noise: float) -> list[str]:
    """The per-move case, per move and cycle: the residual RMS (m/s^2) and the move + settle time (s), the last
    cycle's against the schedule's (its row of the case ``scheduled``, if run), and what the learner's last
    report of the move says."""
    def status(report: Any) -> str:
        m = dict(zip(report.metric_names, report.metric_values, strict=True))
        if m.get("skipped"):
            return "skipped"
        if "speed_factor" in m:  # speed-up per move
            from .arm_speed import status as speed_status

            return speed_status(m)
        if "cost" in m:  # MRILC per move
            action = next((k.split(".", 1)[1] for k in m if k.startswith("action.")), "?")
            return (f"cost {m['cost']:.4g} m/s^2, {action}; correction used {m['max_correction_rad']:.2e} rad,"
                    f" limit excess {m['limit_excess']:.1g}")
        if m.get("held") and "a1_next" not in m:
            return "held at the schedule alone"
        if "a1_next" not in m or m["a1_next"] != m["a1_next"]:
            return "the schedule alone next"
        return (f"factor A1 {m['a1_next']:.3f}, T2 {1e3 * m['t2_next']:.1f} ms"
                + (" (held)" if m.get("held") else ""))

    cycles = len(per_move)
    head = ["move", *[f"c{k + 1}" for k in range(cycles)], "last % of scheduled", "learner's last report"]
    out = [f"Per move and cycle (the per-move learner's cycles; accelerometer noise {noise:g} m/s^2, its floor"
           f" {math.sqrt(3) * noise:.4f} m/s^2 in this RMS): residual RMS m/s^2, then move + settle s", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for what, key in (("residual", "residual_rms"), ("move+settle", "move_and_settle_s")):
        for i, (run, _, _) in enumerate(per_move[0]):
            name = f"{run.index + 1}. {run.name}"
            values = [float(getattr(c[i][1], key)) for c in per_move]
            sched = next((r[key] for r in rows if r["case"] == "scheduled" and r["move"] == run.name), None)
            ratio = f"{100 * values[-1] / sched:.1f}" if sched else "-"
            fmt = "{:.4f}" if key == "residual_rms" else "{:.3f}"
            out.append(f"| {name} {what} | " + " | ".join(fmt.format(v) for v in values)
                       + f" | {ratio} | {status(per_move[-1][i][2]) if what == 'residual' else ''} |")
    return out


def _losses(client: ArmClient) -> str:
    """One line: the samples the client checked and those lost (gaps in the stamps), per stream."""
    gaps = client.lockstep.gaps
    lost = client.lockstep.describe_lost()
    checked = ", ".join(f"{name} {g.samples}" for name, g in gaps.items())
    return (f"Samples lost: {lost.removeprefix('lost ')} (the moves they touch are marked above); received:"
            f" {checked}" if lost else
            f"Samples lost: none (no gap in the stamps; received: {checked})")


def _sums(rows: list[dict[str, Any]], cases: list[str], noise: float) -> list[str]:
    """Per case: the residual summed over the cycle's moves, as measured and above the accelerometer's noise
    (sqrt(RMS^2 - 3 noise^2) per move: the noise adds 3 noise^2 to the mean square over three axes), and their
    ratios to the unshaped and the fixed shaper's."""
    def above(rms: float) -> float:
        return math.sqrt(max(rms * rms - 3.0 * noise * noise, 0.0))

    total = {c: sum(r["residual_rms"] for r in rows if r["case"] == c) for c in cases}
    clean = {c: sum(above(r["residual_rms"]) for r in rows if r["case"] == c) for c in cases}
    out = ["| case | summed residual RMS m/s^2 | % of unshaped | % of fixed | above the noise m/s^2 | % of fixed |",
           "|---|---|---|---|---|---|"]
    for c in cases:
        lost = sum(1 for r in rows if r["case"] == c and r.get("lost"))
        name = f"{c} ({lost} move{'s' if lost != 1 else ''} with lost samples)" if lost else c
        has = "fixed" in total and total["fixed"] > 0 and clean["fixed"] > 0
        fixed = f"{100 * total[c] / total['fixed']:.1f}" if has else "-"
        fixed_clean = f"{100 * clean[c] / clean['fixed']:.1f}" if has else "-"
        out.append(f"| {name} | {total[c]:.4f} | {100 * total[c] / total['none']:.1f} | {fixed} | {clean[c]:.4f} |"
                   f" {fixed_clean} |")
    return out


def plot(path: pathlib.Path, traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]], cases: list[str],
         moves: list[str]) -> Any:
    """tool_deviation.png: per move, each case's distance of the flange from where it comes to rest (mm)
    against the time from the planned end of the move (s), with the settling band
    (:data:`~sim_plant_node.arm.metrics.SETTLE_TOLERANCE`, 0.05 mm) shaded; the figure is returned
    (closed) for inspection.

    Every case keeps its own colour and line style, the first drawn widest, so a case whose trace is
    another's (the schedule and the fixed shaper apply the same shaper where a move ends at the home
    reach) shows as a coloured dash over it; the panel's title names such pairs (within 0.001 mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..arm.metrics import SETTLE_TOLERANCE

    band_mm = SETTLE_TOLERANCE * 1e3
    same_mm = 1e-3  # traces within a micrometre of each other are one on the figure
    styles = ["-", "--", "-.", ":"]
    fig, axes = plt.subplots(len(moves), 1, figsize=(10, 2.3 * len(moves)), sharex=True, squeeze=False)
    for ax, move in zip(axes[:, 0], moves, strict=True):
        drawn: list[tuple[str, np.ndarray]] = []
        same: list[str] = []
        ax.axhspan(0.0, band_mm, color="0.85", zorder=0, label=f"settling band ({band_mm:g} mm)")
        for i, case in enumerate(cases):
            if (case, move) not in traces:
                continue
            t, d = traces[(case, move)]
            ax.plot(t, d, lw=max(0.7, 2.2 - 0.4 * i), ls=styles[i % len(styles)], color=f"C{i % 10}",
                    label=case, zorder=2 + i)
            twin = next((c for c, e in drawn if e.shape == d.shape and np.allclose(e, d, rtol=0, atol=same_mm)), None)
            if twin is not None:
                same.append(f"{case} = {twin}")
            drawn.append((case, d))
        ax.set_title(move + (f"  (same trace within {same_mm:g} mm: {', '.join(same)})" if same else ""), fontsize=9)
        ax.set_ylabel("tool dev. (mm)")
        ax.grid(alpha=0.3)
        ax.set_yscale("symlog", linthresh=0.01)
    axes[0, 0].legend(loc="upper right", fontsize=8, ncol=len(cases) + 1)
    axes[-1, 0].set_xlabel("time from the planned end of the move (s): distance of the flange from where it comes"
                           " to rest")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig


def identify(conductor: Any, identifier_cli: Any, cycles: int) -> tuple[Any, str]:
    """The identifier's recommendation from the last ``cycles`` cycles (not applied), and its summary."""
    from shaper_msgs.srv import Identify

    deadline = time.monotonic() + 60.0
    while True:  # the identifier closes a cycle once samples after its END came, or after its max wait
        resp = conductor.call(identifier_cli, Identify.Request(cycles=int(cycles), max_modes=3, apply=False),
                              timeout=120.0)
        if resp.success or "buffered" not in resp.message or time.monotonic() > deadline:
            break
        pause = time.monotonic() + 0.5
        conductor.spin_until(lambda: time.monotonic() > pause, 5.0, "the identifier's buffer")  # noqa: B023
    if not resp.success:
        raise RuntimeError(f"identification failed: {resp.message}")
    from shaper_nodes.ros.conversions import estimate_modes

    modes = ", ".join(f"{hz:.3f} Hz zeta {zeta:.3f}" for hz, zeta in estimate_modes(resp.estimate))
    return resp.recommended, f"{resp.recommended.family} for {modes}"


def calibrate(out: pathlib.Path, noise_log: pathlib.Path) -> pathlib.Path:
    """Run the ``calibrate`` node on the simulated arm (its installed config/calibrate.yaml) into
    ``out``; returns ``out``. Raises RuntimeError with the log's end if it fails."""
    from ament_index_python.packages import get_package_share_directory

    from shaper_nodes.ros.launching import NodeProcess

    config = pathlib.Path(get_package_share_directory("shaper_nodes")) / "config" / "calibrate.yaml"
    proc = NodeProcess("shaper_nodes", "calibrate", {}, log_path=noise_log, params_file=config,
                       args=["--execute", "--out", str(out)]).start()
    assert proc.proc is not None
    import subprocess

    try:
        code = proc.proc.wait(timeout=CALIBRATION_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.stop()
        raise RuntimeError(f"the calibration did not finish within {CALIBRATION_TIMEOUT:g} s (its log:"
                           f" {noise_log})") from None
    except BaseException:
        proc.stop()
        raise
    proc.stop()
    if code != 0:
        tail = "\n".join(noise_log.read_text().splitlines()[-5:])
        raise RuntimeError(f"calibration failed (exit {code}):\n{tail}")
    return out


def fallback_request(calibration: pathlib.Path) -> Any:
    """The SetShaper request for the calibration's fallback shaper (shaper.yaml)."""
    import yaml

    from shaper_msgs.msg import Shaper as ShaperMsg
    from shaper_msgs.srv import SetShaper
    from shaper_nodes.ros.conversions import mode_msg

    (body,) = yaml.safe_load((calibration / "shaper.yaml").read_text()).values()
    sh = body["ros__parameters"]["shaper"]
    modes = [mode_msg(float(f), float(z)) for f, z in zip(sh["frequencies_hz"], sh["damping_ratios"], strict=True)]
    return SetShaper.Request(shaper=ShaperMsg(family=str(sh["family"]), design_modes=modes, source="user"))


@dataclass
class Session:
    """What the cases share: the node starter, the shaper node's process, the calibration."""

    start: Callable[..., Any]
    shaper: Any
    shaper_params: dict[str, Any]
    calibration: pathlib.Path | None = None
    scheduled: bool = False


def _schedule(session: Session, client: ArmClient) -> None:
    """Start the calibrated scheduler, and the shaper node again with action.scheduler (once)."""
    if session.scheduled:
        return
    assert session.calibration is not None
    session.shaper.stop()
    session.start("shaper_nodes", "scheduler", {"use_sim_time": True},
                  params_file=session.calibration / "scheduler.yaml")
    session.shaper = session.start("shaper_nodes", "shaper_node", {**session.shaper_params,
                                                                    "action.scheduler": "/scheduler"})
    session.scheduled = True
    client.c.wait_ready(60.0, {})
    client.wait_ready(3)


def _apply_case(case: str, client: ArmClient, recommended: tuple[Any, str] | None, home_mode: Any,
                session: Session) -> str:
    """Install the case's shaper (or start its learner); returns what was installed, for the log."""
    from shaper_msgs.srv import SetShaper

    conductor = client.c
    if case in ("none", "zv", "zvd"):
        conductor.set_shaper(case, home_mode.omega, home_mode.zeta)
        return case if case == "none" else f"{case} at {home_mode.hz:.3f} Hz, zeta {home_mode.zeta:.3f}"
    if case == "identified":
        if recommended is None:
            raise RuntimeError("the identified case needs the unshaped case's cycles first")
        shaper = recommended[0]
        shaper.source, shaper.family = "identification", "custom"  # its impulses as identified, as the identifier sends
        resp = conductor.call(conductor.set_shaper_cli, SetShaper.Request(shaper=shaper))
        if not resp.success:
            raise RuntimeError(f"the shaper refused the recommendation: {resp.message}")
        return recommended[1]
    if case == "fixed":
        assert session.calibration is not None
        req = fallback_request(session.calibration)
        resp = conductor.call(conductor.set_shaper_cli, req)
        if not resp.success:
            raise RuntimeError(f"the shaper refused the calibrated fallback: {resp.message}")
        from shaper_nodes.ros.conversions import msg_hz

        return (f"calibrated fallback: {req.shaper.family} on the home pose's modes "
                + ", ".join(f"{msg_hz(m):.3f} Hz" for m in req.shaper.design_modes))
    if case in SCHEDULED:
        _schedule(session, client)
        if case == "scheduled":
            return "calibrated schedule: each goal shaped for the modes at its final pose"
        if case == "scheduled_mrilc_moves":
            return _mrilc_moves(session, client)
        if case == "scheduled_speedup":
            from . import arm_speed

            return arm_speed.start(session, client, IMU, WAIT)
        if case in PER_MOVE:
            from shaper_nodes.ros.lockstep_reader import AckWatch

            # every sample of a move, reliable (the plant rests between goals, and the next goal waits for the
            # learner's report of the move: its queue of 10 s holds a move)
            payback = case == "scheduled_list_moves"  # each factor chosen to pay: the goals through the learner
            session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2",
                                                       "shaper": "/scheduler", "list.per_move": True,
                                                       "topics.imu_reliable": True, "payback.enabled": payback})
            if payback:
                from . import arm_speed

                arm_speed.use_learner_proxy(client, ends_at_rest=False)
                client.wait_ready(4)  # the learner's action server, and its subscription of the cycle events
            else:
                client.wait_listeners(4)  # and the learner
            AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [IMU], WAIT)
            return "calibrated schedule with LIST (zv2) per move on top" + (", chosen to pay" if payback else "")
        session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2",
                                                   "shaper": "/scheduler"})
        client.wait_listeners(4)  # and the learner
        return "calibrated schedule with LIST (zv2) on top"
    conductor.set_shaper("none")
    session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2"})
    client.wait_listeners(4)  # and the learner
    return "LIST (zv2), from unshaped"


def _mrilc_moves(session: Session, client: ArmClient) -> str:
    """MRILC per move: the shaper node again, its proxy sending the shaped goals to the learner's proxy, and the
    learner (``mode: mrilc_moves``) in front of the controller, the sim arm's operator and the moves' planning
    limits."""
    from shaper_nodes.ros.lockstep_reader import AckWatch

    from ..arm.task import MAX_ACCELERATION, MAX_VELOCITY

    session.shaper.stop()
    session.start("shaper_nodes", "learner", {"mode": "mrilc_moves", "use_sim_time": True,
                                               "topics.imu_reliable": True,
                                               "mrilc_moves.operator": "sim_plant_node.arm.lifted:arm_operator",
                                               "mrilc_moves.velocity": [MAX_VELOCITY],
                                               "mrilc_moves.acceleration": [MAX_ACCELERATION]})
    session.shaper = session.start("shaper_nodes", "shaper_node", {
        **session.shaper_params, "action.scheduler": "/scheduler",
        "action.controller": "/learner/follow_joint_trajectory"})
    client.c.wait_ready(60.0, {})
    client.wait_ready(4)  # and the learner
    AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [IMU], WAIT)
    return ("calibrated schedule with MRILC per move on top (each move's joint profile correction added by the"
            " learner's proxy)")


def main(argv: list[str] | None = None) -> int:
    from .conductor import interrupted

    try:
        return _main(argv)
    except (TimeoutError, RuntimeError, KeyboardInterrupt) as err:
        if interrupted() or isinstance(err, KeyboardInterrupt):  # Ctrl-C or SIGTERM: the nodes were stopped
            print(f"\ndemo arm: interrupted ({interrupted() or 'SIGINT'}); the nodes were stopped", file=sys.stderr)
            return 130
        print(f"demo arm: {err}", file=sys.stderr)  # a wait that failed, a refused goal: one line, no traceback
        return 1


def _main(argv: list[str] | None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from shaper_msgs.srv import Identify

    from ..arm.description import JOINT_NAMES
    from ..arm.dynamics import ArmModel
    from ..arm.modal import lowest
    from ..arm.task import HOME, cycle_moves
    from .conductor import Conductor, node_session

    cases = [c.strip() for c in args.cases.split(",")]
    cases = [c for c in cases if c not in SCHEDULED] + [c for c in cases if c in SCHEDULED]  # one shaper restart
    unknown = sorted(set(cases) - set(CASES))
    if unknown or "none" not in cases:
        print(f"demo arm: --cases must include none and be among {', '.join(CASES)}; got {args.cases}", file=sys.stderr)
        return 2
    if len(set(cases) & {"list", "scheduled_list", *PER_MOVE}) > 1:
        print(f"demo arm: --cases may name one learning case (list, scheduled_list, {', '.join(PER_MOVE)}: each"
              f" runs its own learner); got {args.cases}", file=sys.stderr)
        return 2
    if bad := arm_payload.check_args(args, cases):
        print(f"demo arm: {bad}", file=sys.stderr)
        return 2
    out = args.out or pathlib.Path("out") / datetime.datetime.now().strftime("demo-arm-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    moves = cycle_moves()
    home_mode = lowest(ArmModel(), HOME)
    print(f"demo arm: UR5e-based elastic arm, home lowest mode {home_mode.hz:.3f} Hz (zeta {home_mode.zeta:.3f});"
          f" {len(moves)} moves a cycle; cases {', '.join(cases)}; output in {out}", flush=True)
    t_wall = time.monotonic()
    rows: list[dict[str, Any]] = []
    traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    reference_paths: dict[int, np.ndarray] = {}
    per_move: list[list[tuple[MoveRun, Any, Any]]] = []  # per cycle of the per-move case: (run, measure, report)
    with node_session(out, "arm") as (start, ctx):
        start("sim_plant_node", "sim_plant", {"plant.model": "arm", "mode": "lockstep", "rate": RATE,
                                              "task.start": HOME.tolist(), "imu.noise_stddev": args.noise,
                                              "lockstep_timeout": 60.0, "arm.substeps": SUBSTEPS,
                                              "lockstep.readers": READERS})
        shaper_params = {"joint_names": list(JOINT_NAMES), "command_rate": RATE, "use_sim_time": True,
                         "action.server_timeout": 30.0}
        session = Session(start, start("shaper_nodes", "shaper_node", shaper_params), shaper_params,
                          args.calibration)
        if session.calibration is None and any(c in CALIBRATED for c in cases):
            # first, alone with the sim (the other nodes' subscriptions would slow the lockstep down)
            print("calibrate: the workspace (config/calibrate.yaml) ... ", end="", flush=True)
            session.calibration = calibrate(out / "calibration", out / "arm-calibrate.log")
            report = json.loads((session.calibration / "report.json").read_text())
            print(f"{len(report['poses'])} poses, {len(report['flagged_poses'])} flagged; scheduler over"
                  f" {', '.join(report['scheduler']['premises'])} ({time.monotonic() - t_wall:.0f} s)", flush=True)
        start("shaper_nodes", "identifier", {"use_sim_time": True, "buffer_cycles": 20, "settle_tolerance": 1e-4,
                                             "max_modes": 3, "topics.imu_reliable": True,
                                             **arm_payload.identifier_params(cases)})
        start("shaper_nodes", "recorder", {"output": str(out / "recording"), "topics": RECORDED,
                                           "use_sim_time": True})
        conductor = Conductor(context=ctx)
        client = ArmClient(conductor)
        identifier_cli = conductor.create_client(Identify, "/identifier/identify")
        payload = arm_payload.PayloadWatch(conductor, args, cases)
        try:
            conductor.wait_ready(60.0, {"/cycle_events": 2})
            client.wait_ready(3)  # this node, the identifier and the recorder
            client.wait_recorder([IMU, JOINTS])  # the per-step streams, from the first step on
            cycle_index = 0
            recommended = None
            for case in cases:
                installed = _apply_case(case, client, recommended, home_mode, session)
                learning = case in LEARNING
                n = args.list_cycles if learning else args.cycles
                print(f"{case:>10}: {installed}; {n} cycles ", end="", flush=True)
                for k in range(n):
                    payload.before_cycle(case, k, cycle_index)
                    if case in PER_MOVE:  # every move a cycle of the learner's: cycle_index up to its last move's
                        runs = client.run_cycle_per_move(cycle_index, moves, lambda: print(".", end="", flush=True),
                                                         functools.partial(_learned, client))
                        per_move.append([(run, client.measure(run, reference_paths[run.index])[0],
                                          _learned(client, cycle_index + run.index)) for run in runs])
                        cycle_index += len(moves) - 1
                    else:
                        runs = client.run_cycle(cycle_index, moves, lambda: print(".", end="", flush=True))
                    if learning and case not in PER_MOVE:
                        client.c.spin_until(lambda c=cycle_index: any(r.cycle == c for r in client.reports), 120.0,
                                            "the learner's report")
                    cycle_index += 1
                    last_end = runs[-1].end
                print(f" ({time.monotonic() - t_wall:.0f} s)", flush=True)
                if case == "none" and "identified" in cases:
                    recommended = identify(conductor, identifier_cli, n)
                for run in runs:  # the case's last cycle
                    if case == "none":
                        reference_paths[run.index] = client.tool_path("cmd", run.start, run.end)[1]
                    m, _ = client.measure(run, reference_paths[run.index])
                    lt, tool = client.tool_path("link", run.start, run.end)
                    planned_end = run.start + run.planned
                    traces[(case, f"{run.index + 1}. {run.name}")] = (
                        lt - planned_end, 1e3 * np.linalg.norm(tool - tool[-1], axis=1))
                    rows.append({"case": case, "move": f"{run.index + 1}. {run.name}", **m.__dict__,
                                 "move_and_settle_s": m.move_and_settle_s, "installed": installed,
                                 "lost": client.lockstep.describe_lost(run.start, run.end)})
            client.wait_recorded(last_end)
        finally:
            arrays: dict[str, Any] = {k: np.asarray(v) for k, v in client.s.__dict__.items()}
            np.savez_compressed(out / "streams.npz", **arrays)
            conductor.close()
    for r in rows:
        base = next(x for x in rows if x["case"] == "none" and x["move"] == r["move"])
        r["percent"] = 100.0 * r["residual_rms"] / base["residual_rms"] if base["residual_rms"] > 0 else math.nan
    keys = ["case", "move", "residual_rms", "percent", "residual_peak", "peak_mm", "settling_s", "move_s",
            "move_and_settle_s", "delay_s", "path_deviation_mm", "installed", "lost"]
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    table = [*_table(rows), "", *_sums(rows, cases, args.noise)]
    if per_move:
        table += ["", *_per_move_table(per_move, rows, args.noise)]
        if "scheduled_speedup" in cases:
            from .arm_speed import summary

            table += summary(per_move, rows)
    table += payload.table(per_move, args.noise)
    from ..arm.metrics import RESIDUAL_WINDOW, SETTLE_TOLERANCE

    note = (f"Residual vibration: the flange IMU's specific force minus its mean, over {RESIDUAL_WINDOW:g} s after"
            f" the commanded motion ends (accelerometer noise {args.noise:g} m/s^2); peak: the flange's largest"
            f" distance from where it comes to rest in that window; settling: from the planned end of the move until"
            f" the flange stays within {SETTLE_TOLERANCE * 1e3:g} mm; delay: commanded motion end minus planned end;"
            " path deviation: commanded tool path against the unshaped one. Last cycle of each case.")
    (out / "results.md").write_text("# Arm demo\n\n" + note + "\n\n" + "\n".join(table) + "\n")
    plot(out / "tool_deviation.png", traces, cases, [f"{i + 1}. {m.name}" for i, m in enumerate(moves)])
    print()
    print(note)
    print("\n".join(table))
    print(_losses(client))
    print()
    print(f"results:   {out / 'results.csv'}, {out / 'results.md'}")
    print(f"plot:      {out / 'tool_deviation.png'}")
    print(f"recording: {out / 'recording'}  (rosbag2, MCAP storage)")
    print(f"node logs: {out}/*.log   ({time.monotonic() - t_wall:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
