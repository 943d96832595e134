"""A drift warning relearns every move, over DDS: the learner per move (``list.per_move``), the scheduler and a
peer named ``identifier`` that publishes the drift watch's status on ``/diagnostics`` through the identifier's own
reporter (``identifier: drift``, WARN then OK, as nodes/identifier.py does), all real nodes in one process.

The learner starts from a state file of two learned moves and gives the scheduler their factors; at the first
WARN it resets both moves (state file, scheduler) once, not again at the WARNs that repeat it, and again after
an OK and a new WARN. A cycle under way at the warning is not learned from; the moves' next cycles start from
the current schedule. Statuses of other names, and the watched one with a level that is not a diagnostic level,
change nothing.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Log
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams, make_reference
from shaper_nodes.core.learning.moves import MoveStore, move_key, store_from_doc
from shaper_nodes.core.shaping import Mode
from shaper_nodes.ros.conversions import mode_from_msg, sec_to_time
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN, Diagnostics

WAIT = 120.0  # s of wall time for a state to come (two busy cores)
NAMES = ["j1", "j2"]
MOVES = (([0.0, 0.0], [1.5, 0.3]), ([1.5, 0.3], [0.0, 0.0]))
#: a two-premise schedule: 4 and 11 Hz at j1 = 0, 8 and 15 Hz at j1 = 2
SCHEDULE = {"premises": ["j1"], "rule_names": ["lo", "hi"], "interpolation": "modes", "family": "zv",
            "rules.lo.membership": ["triangular"], "rules.lo.membership_params": [0.0, 0.0, 2.0],
            "rules.lo.frequency_hz": [4.0, 11.0], "rules.lo.damping_ratio": [0.02, 0.02],
            "rules.hi.membership": ["triangular"], "rules.hi.membership_params": [0.0, 2.0, 2.0],
            "rules.hi.frequency_hz": [8.0, 15.0], "rules.hi.damping_ratio": [0.02, 0.02]}


def learned_learner(hz: float) -> ListLearner:
    """A move's LIST learner with a reference (a free decay at ``hz``, damping 0.02, after MOTION_END at 1 s)."""
    t = np.arange(0.0, 3.0, 0.002)
    w, z = 2 * math.pi * hz, 0.02
    a = np.where(t > 1.0, np.exp(-z * w * (t - 1.0)) * np.sin(w * math.sqrt(1 - z * z) * (t - 1.0)), 0.0)
    return ListLearner(ListConfig(), reference=make_reference(t, a, 1.0, 3.0, config=ListConfig()))


def state_doc() -> dict:
    """The learner's state file with both moves learned (a reference, a factor, a base) and one held."""
    store = MoveStore()
    for (start, goal), hz in zip(MOVES, (6.0, 9.0), strict=True):
        entry, _ = store.entry(start, goal)
        learner = learned_learner(hz)
        entry.list_state = learner.to_dict()
        sh = learner.params.shaper("zv2")
        entry.correction = (sh.amplitudes.tolist(), sh.times.tolist())
        entry.base = entry.best = {"residual_rms": 0.05}
        entry.cycles = 4
    keys = [move_key(s, g) for s, g in MOVES]
    return {"version": 1, "structure": "zv2", "per_move": True, "moves": store.to_doc(),
            "joint_names": {k: NAMES for k in keys}, "at_schedule": []}


class Peer:
    """The test's side: the identifier's /diagnostics (its own reporter), the cycle events, the learner's reports
    and log lines, and the scheduler's ``shaper_at``."""

    def __init__(self, ctx, ex: SingleThreadedExecutor) -> None:
        self.ex = ex
        self.node = Node("identifier", context=ctx)  # statuses named "identifier: ..." as the identifier's
        self.identifier = Diagnostics(self.node)  # one publisher: its statuses arrive in order
        self.events = self.node.create_publisher(CycleEvent, "/cycle_events", 10)
        self.reports: list[CycleReport] = []
        self.logs: list[str] = []
        self.statuses: list[DiagnosticStatus] = []
        self.node.create_subscription(CycleReport, "/learner/reports", self.reports.append, 100)
        self.node.create_subscription(Log, "/rosout", lambda m: self.logs.append(m.msg) if m.name == "learner"
                                      else None, 100)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.statuses.extend(m.status), 100)
        self.shaper_at = self.node.create_client(ShaperAt, "/scheduler/shaper_at")
        ex.add_node(self.node)

    def spin_until(self, done, what: str, timeout: float = WAIT) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out after {timeout:g} s waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def drift(self, level, text: str, name: str = "drift") -> None:
        """The identifier's drift status, as nodes/identifier.py publishes it (or another of its statuses)."""
        self.identifier.publish(name, level, text, [("cycle", "7"), ("mode_hz", "5.1")])

    def event(self, kind: int, cycle: int, t: float, move: int) -> None:
        start, goal = MOVES[move]
        msg = CycleEvent(event=kind, cycle=cycle, task="drift", joint_names=NAMES, start_positions=start,
                         goal_positions=goal)
        msg.header.stamp = sec_to_time(t)
        self.events.publish(msg)

    def destroy(self) -> None:
        self.node.destroy_node()


def test_a_drift_warning_relearns_every_move_once_per_episode(ros_context, tmp_path):
    from shaper_nodes.nodes.learner import LearnerNode
    from shaper_nodes.nodes.scheduler import SchedulerNode

    path = tmp_path / "learner_state.json"
    path.write_text(json.dumps(state_doc()))
    keys = [move_key(s, g) for s, g in MOVES]
    scheduler = SchedulerNode(context=ros_context, parameter_overrides=[Parameter(k, value=v)
                                                                        for k, v in SCHEDULE.items()])
    learner = LearnerNode(context=ros_context, parameter_overrides=[
        Parameter("list.per_move", value=True), Parameter("shaper", value="/scheduler"),
        Parameter("state_file", value=str(path)), Parameter("end_wait", value=0.0)])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(scheduler)
    ex.add_node(learner)
    peer = Peer(ros_context, ex)
    mode = learner.mode
    try:
        # the learner resumes both moves: their factors reach the scheduler
        peer.spin_until(lambda: len(scheduler.moves.moves) == 2, "the saved factors at the scheduler")
        peer.spin_until(lambda: peer.node.count_subscribers("/diagnostics") >= 2
                        and peer.events.get_subscription_count() >= 1,
                        "the learner's /diagnostics and /cycle_events subscriptions")

        # unrelated and bad statuses change nothing (the bad level is reported: once it is, all before it were read)
        peer.drift(WARN, "cycle 7: saturated samples", "sensor")
        peer.drift(WARN, "a status whose name only begins as the watched one's", "drifting")
        peer.drift(ERROR, "cycle 7: cannot rate the mode: saturated")
        peer.drift(b"\x07", "a level that is none")
        peer.spin_until(lambda: any(s.name == "learner: drift_status" for s in peer.statuses),
                        "the learner's report of the bad status")
        bad = next(s for s in peer.statuses if s.name == "learner: drift_status")
        assert "not a DiagnosticStatus level" in bad.message and "identifier: drift" in bad.message
        assert len(scheduler.moves.moves) == 2 and not mode.drift.warned
        assert all(e.list_state is not None for e in mode.store)

        # a cycle under way when the warning comes
        peer.event(CycleEvent.START, 1, 10.0, 0)
        peer.spin_until(lambda: 1 in mode._cycle_move, "the learner's START of cycle 1")

        # the identifier's WARN: both moves reset, once
        peer.drift(WARN, "the mode has drifted out of the active shaper's working band (3 cycles in a row)")
        peer.spin_until(lambda: len(scheduler.moves.moves) == 0, "the factors withdrawn from the scheduler")
        peer.spin_until(lambda: any("relearning 2 moves" in m for m in peer.logs), "the learner's log line")
        line = next(m for m in peer.logs if "relearning 2 moves" in m)
        assert all(k in line for k in keys) and "identifier: drift" in line, line
        doc = json.loads(path.read_text())
        assert doc["drift_warned"] is True and doc["at_schedule"] == []
        store, problems = store_from_doc(doc["moves"])
        assert problems == {} and len(store) == 2
        for e in store:
            assert (e.list_state, e.correction, e.base, e.best, e.cycles, e.origin) == \
                (None, None, None, None, 0, "schedule"), e

        # the cycle under way is not learned from
        peer.event(CycleEvent.MOTION_END, 1, 11.0, 0)
        peer.event(CycleEvent.END, 1, 12.0, 0)
        peer.spin_until(lambda: any(r.cycle == 1 for r in peer.reports), "the report of cycle 1")
        got = next(r for r in peer.reports if r.cycle == 1)
        assert dict(zip(got.metric_names, got.metric_values, strict=True)) == {"skipped": 1.0}

        # WARNs that repeat it: nothing more; an OK ends the episode
        peer.drift(WARN, "the mode has drifted out of the active shaper's working band (4 cycles in a row)")
        peer.drift(WARN, "the mode has drifted out of the active shaper's working band (5 cycles in a row)")
        peer.drift(OK, "cycle 10: the mode is inside the working band")
        peer.spin_until(lambda: not mode.drift.warned, "the OK read")
        assert mode.drift.resets == 1
        assert sum("relearning" in m for m in peer.logs) == 1

        # the move's next cycle starts from the current schedule: its learner from the schedule's lowest mode
        peer.event(CycleEvent.START, 2, 20.0, 0)
        peer.spin_until(lambda: keys[0] in mode.learners, "the move's new learner")
        req = ShaperAt.Request()
        req.pose.name, req.pose.position = NAMES, MOVES[0][1]
        future = peer.shaper_at.call_async(req)
        peer.spin_until(future.done, "the schedule at the goal")
        lowest = min((mode_from_msg(m) for m in future.result().estimate.modes), key=lambda m: m.omega)
        want = ListParams.from_mode(Mode(lowest.omega, lowest.zeta))
        made = mode.learners[keys[0]].params
        assert made is not None and (made.a1, made.t2) == pytest.approx((want.a1, want.t2), rel=1e-9)
        assert mode.learners[keys[0]].reference is None  # this cycle is its new reference

        # a new episode: reset again
        peer.drift(WARN, "the mode has drifted out of the active shaper's working band (3 cycles in a row)")
        peer.spin_until(lambda: mode.drift.resets == 2, "the second episode's reset")
        assert keys[0] not in mode.learners
        assert json.loads(path.read_text())["drift_warned"] is True
    finally:
        ex.shutdown()
        peer.destroy()
        learner.destroy_node()
        scheduler.destroy_node()


def test_the_state_files_episode_flag_is_checked(ros_context, tmp_path):
    """``drift_warned`` in the state file: a restarted learner inside an episode does not act on it twice; a
    value that is not true or false refuses the file (reported, the learner starts afresh)."""
    from shaper_nodes.nodes.learner import LearnerNode

    for value, resumed in ((True, True), ("yes", False)):
        doc = state_doc()
        doc["drift_warned"] = value
        path = tmp_path / f"state_{resumed}.json"
        path.write_text(json.dumps(doc))
        node = LearnerNode(context=ros_context, parameter_overrides=[
            Parameter("list.per_move", value=True), Parameter("shaper", value="/scheduler"),
            Parameter("state_file", value=str(path))])
        try:
            assert node.mode.drift.warned is resumed
            assert (len(node.mode.store) == 2) is resumed
            if not resumed:
                assert "drift_warned must be true or false" in node.state_problem
        finally:
            node.destroy_node()
