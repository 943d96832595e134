"""The arm demo's MoveIt-like client: it sends the pick-and-place cycle move by move to the shaper's
FollowJointTrajectory action, marks the cycles on ``/cycle_events``, takes the streams the measures read (the sim
plant waits for it in lockstep) and measures each move (:mod:`sim_plant_node.arm.metrics`)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .arm_split import Splits

RATE = 500.0
SUBSTEPS = 2  # the sim plant's arm.substeps (its default): the flange IMU at RATE x SUBSTEPS
#: the streams the demo's measures read (and the joint states, whose repeated stamp says the arm rests)
IMU, LINK, CMD, JOINTS = "/tip_imu", "/sim_plant/tip_state", "/sim_plant/reference", "/joint_states"
#: the recorder, whose lockstep acknowledgements say what it has taken
RECORDER = "/recorder"
#: s of wall time a wait for the nodes may take before the demo stops with one line (a node starting at load 20
#: took over 60 s to be heard; a node that dies ends the wait at once through its process)
WAIT = 300.0
DWELL = 1.5  # s at rest after each move (the gripper's time; the residual window is in it)


def goal_trajectory(move: Any) -> Any:
    """The JointTrajectory of ``move``'s goal (:func:`sim_plant_node.arm.task.goal_points`: from its start at time
    0, so that the shaper node shapes the whole motion, to its end held :data:`DWELL` s)."""
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from ..arm.description import JOINT_NAMES
    from ..arm.task import goal_points

    def dur(t: float) -> Duration:
        return Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000)

    pts = [JointTrajectoryPoint(positions=p.tolist(), velocities=v.tolist(), accelerations=a.tolist(),
                                time_from_start=dur(t))
           for t, p, v, a in zip(*goal_points(move, DWELL), strict=True)]
    return JointTrajectory(joint_names=list(JOINT_NAMES), points=pts)


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

        def on_positions(topic: str, read: JointStateReader, which: str) -> Callable[[bytes], None]:
            """The callback of a JointState stream whose positions a measure reads (Streams.<which>)."""
            def on(raw: bytes) -> None:
                try:
                    t, _, position = read(raw)
                except CdrError as err:
                    return refused(topic, err)
                getattr(self.s, which + "_t").append(t)
                getattr(self.s, which).append(list(position))
                took(topic, t)
            return on

        on_link, on_cmd = on_positions(LINK, link_read, "link"), on_positions(CMD, cmd_read, "cmd")

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
        #: the sim plant's servo/vibration split of each move (.arm_split)
        self.splits = Splits(conductor)
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
        return self._Goal(trajectory=goal_trajectory(move))

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
        from action_msgs.msg import GoalStatus

        # only SUCCEEDED is success: an empty result (error_code 0) comes with UNKNOWN when the server is gone or
        # restarted without the goal (ResilientActionClient), with ABORTED when the shaper's proxy lost its controller
        if res.status != GoalStatus.STATUS_SUCCEEDED or res.result.error_code != 0:
            state = {GoalStatus.STATUS_ABORTED: "aborted", GoalStatus.STATUS_CANCELED: "canceled",
                     GoalStatus.STATUS_UNKNOWN: "unknown to the server"}.get(res.status, f"status {res.status}")
            raise RuntimeError(f"{move.name}: {state}: error_code {res.result.error_code} {res.result.error_string}")
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


def learned_report(client: ArmClient, cycle: int) -> Any:
    """The learner's report of ``cycle``, once it came (what the learner did with a move's cycle)."""
    client.c.spin_until(lambda: any(r.cycle == cycle for r in client.reports), 120.0, f"the learner's report of"
                        f" cycle {cycle}")
    return next(r for r in reversed(client.reports) if r.cycle == cycle)
