"""The learner node's MRILC per move (``mode: mrilc_moves``): a feedforward correction of each move's joint profile.

Issue 31's item 3 over DDS, on the ROS-free law of :mod:`shaper_nodes.core.learning.mrilc.moves` (the one the
reproduction ``reproductions.arm_mrilc`` runs) and the move's set-up of :mod:`~shaper_nodes.core.learning.mrilc.plan`.

**Where the correction is added.** The learner serves ``~/follow_joint_trajectory``
(control_msgs/FollowJointTrajectory, :class:`~.trajectory_action.TrajectoryActionProxy`) between the shaper
node's proxy and the controller: the shaper node's ``action.controller`` names ``/learner/follow_joint_trajectory``
and ``mrilc_moves.controller`` the controller's action. Each goal (the shaped trajectory) is matched to the move
whose cycle START came last (``/cycle_events``: its ``goal_positions`` equal to the goal's last point within
:data:`MATCH` rad), or at once to a known move whose start and goal are its first and last points (its START not
come yet, or missed: the START, or its stand-in at MOTION_END, claims it; core/learning/move_cycles.py); a goal of a
move not known yet waits up to ``mrilc_moves.match_timeout`` s for its START. The move's correction
dq(t), dq'(t), dq''(t) is added to the goal's points (positions, velocities, accelerations; missing velocities or
accelerations are differentiated from the positions), and the goal goes on to the controller. A goal matched to no
move goes on uncorrected (one line on the log). So each move's correction reaches that move's goals only.

**What is learned.** Per move (the identity :func:`~shaper_nodes.core.learning.moves.move_key` of the START's
start and goal), one :class:`~shaper_nodes.core.learning.mrilc.moves.MoveLearner`: B-spline coefficients per joint
in the last ``mrilc_moves.tail`` s of the shaped motion and, ``mrilc_moves.fine_spacing`` s apart, in its last
``mrilc_moves.fine_tail`` s (the goal and the timing do not change), learned at the move's END from the tool
accelerometer's residual window (``topics.imu``; 1 s after the commanded motion ends, its mean taken out:
:func:`~shaper_nodes.core.learning.mrilc.plan.residual_error`) with the lifted operator G that
``mrilc_moves.operator`` gives (``"module:function"``, called once per family of B-splines as ``f(goal_pose, count,
samples, first, spacing, period)``; the simulated arm's: ``sim_plant_node.arm.lifted:arm_operator``), computed once
per move at its first goal; with ``mrilc_moves.payload_mass`` set (> 0, kg: the payload the robot is told, settable
at run time) it is called with ``payload=`` that mass too (the simulated arm's provider takes it).
The learner's divergence guard falls back to its best coefficients (and holds after ``max_fallbacks``).

**Limits.** The learner projects every update inside the joint limits (``mrilc_moves.position_min``, ``position_max``,
``velocity``, ``acceleration``: one value per joint or one for all), and the goal's corrected profile is checked
again before it is sent: a correction that would break a limit is refused, the goal is sent uncorrected, and one
line names the joint and the limit; the points sent are clipped into the limits (where the correction meets a limit
with equality, rounding would leave it 1e-18 past: the report's ``limit_excess`` is exactly 0).
Where the goal itself is already past a limit (a shaped profile's points can
be: 7.05 rad/s^2 measured on the elbow of pick -> home against the moves' planned 6), the correction may not take
it further there (as the learner's projection holds it).

**State.** Every move's learner (coefficients, best coefficients, gain, guard counters, history) with its start,
goal and joint names in ``state_file``, saved atomically after each update; after a restart each move resumes
from its saved state at its first goal (its operator and profile are rebuilt from that goal, the saved state checked
against them entry by entry; a state that does not fit is reported and the move starts afresh). A file whose
document is broken (an entry missing, a key that does not match its poses) is reported and set aside, and the
learner starts afresh (:meth:`~.learner_base.LearnerBase.restore`).

**A drift warning relearns every move** (a payload change: the corrections learned no longer fit the arm). At the
first WARN of the status ``mrilc_moves.drift_status`` (default the identifier's ``identifier: drift``) on
``/diagnostics`` (:mod:`.learner_drift`: once per warning episode, an OK ends it), every move's learner is dropped
with its correction, so each move's next goal runs as the current schedule shaped it (no correction) and its
learner starts again from zero at that goal (its plan and operator rebuilt from it, for the payload
``mrilc_moves.payload_mass`` says then: on the operator of the old payload it does not converge,
docs/results/arm_mrilc_payload.md; with ``mrilc_moves.payload_from_drift`` and ``mrilc_moves.modes`` the payload
is first worked out from the mode the warning carries and set as ``payload_mass``, :mod:`.learner_payload`; a hold
ends with it); one line
on the log and ``/diagnostics`` (``learner: moves``, WARN) names the moves, and the state is saved (atomically,
with the episode flag ``drift_warned``: a move with no learner is not in it). A cycle whose goal ran with the old
correction is not learned from.

Reports (``~/reports``): per move's END, the metrics ``move`` (index in the state's order), ``iteration`` (the
learner's cycle), ``cost`` (weighted RMS of the error, m/s^2), ``action.<learn|fallback|hold>``,
``max_correction_rad``, ``max_correction_rad_s``, ``max_correction_rad_s2`` (the correction the cycle ran with) and
``limit_excess`` (0: every limit held); the residual_rms is the cost.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.cycles import END, START, unseen_window
from shaper_nodes.core.learning.move_cycles import MoveCycles, unmatched
from shaper_nodes.core.learning.moves import MoveError, move_key
from shaper_nodes.core.learning.mrilc.model import MrilcError
from shaper_nodes.core.learning.mrilc.moves import MoveLearner
from shaper_nodes.core.learning.mrilc.plan import (
    MovePlan,
    PlanSettings,
    limit_breach,
    plan_move,
    plan_operator,
    residual_error,
)
from shaper_nodes.core.learning.mrilc.profile import JointLimits, clip_into, profile_excess
from shaper_nodes.ros.conversions import trajectory_arrays, trajectory_msg
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN
from shaper_nodes.ros.parameters import declare

from .learner_base import LearnerBase
from .learner_drift import FLAG, DriftWarnings, saved_flag
from .learner_list import subscribe_imu
from .learner_moves_mrilc_parameters import PARAMETERS as PARAMETERS  # (re-exported: the mode's table)
from .learner_moves_mrilc_parameters import MrilcMovesParams
from .learner_payload import KEY, PayloadGlue, saved_payload
from .learner_payload import load_provider as load_operator  # (kept: the provider's loader)
from .move_goals import MATCH as MATCH  # (re-exported: the tolerance of the match, rad)
from .move_goals import await_match
from .trajectory_action import TrajectoryActionProxy

#: most accelerometer samples kept (a bound whatever the cycle events do)
MAX_SAMPLES = 400_000
_ENTRY = {"start", "goal", "joint_names", "learner"}
#: why a cycle whose goal ran with a correction dropped meanwhile is not learned from
RESET = "every move's correction was dropped (drift warning) after this cycle's goal ran with it"
#: how a goal matched to no cycle went (the reason a cycle whose START was missed is not learned from: unmatched())
UNMATCHED = "it went uncorrected, without the move's plan"


@dataclass
class _Move:
    """One move: its identity, its poses, and (from its first goal on) its plan and learner."""

    key: str
    start: list[float]
    goal: list[float]
    names: list[str]
    saved: dict[str, Any] | None = None  # a saved learner not yet rebuilt (no goal since the restart)
    plan: MovePlan | None = None
    times: np.ndarray | None = None
    learner: MoveLearner | None = None


@dataclass
class _Cycle:
    key: str
    start: float  # the move's start (the START's stamp), s
    goal: np.ndarray
    applied: tuple[float, float, float] | None = None  # the correction the goal ran with (largest dq, dq', dq'')
    excess: float = 0.0  # the largest excess of the corrected goal over the limits (0: all held)
    refused: str = ""  # why the goal went uncorrected (the cycle is not learned from)


class MrilcMovesMode:
    """The MRILC-per-move adapter of the learner node (see the module docstring)."""

    def __init__(self, node: LearnerBase) -> None:
        self.node = node
        self.params = declare(node, MrilcMovesParams)
        v = self.params.value.mrilc_moves
        self.operator = load_operator(str(v.operator))
        self.settings = PlanSettings(spacing=float(v.spacing), tail=float(v.tail), fine_spacing=float(v.fine_spacing),
                                     fine_tail=float(v.fine_tail))
        self.learner_settings = {"gain": float(v.gain), "regularisation": float(v.regularisation),
                                 "patience": int(v.patience), "growth": float(v.growth),
                                 "noise_floor": float(v.noise_floor), "max_fallbacks": int(v.max_fallbacks)}
        self._limit_values = [list(v.position_min), list(v.position_max), list(v.velocity), list(v.acceleration)]
        for name, values in zip(("position_min", "position_max", "velocity", "acceleration"), self._limit_values,
                                strict=True):
            if not values or not all(math.isfinite(x) for x in values):
                raise ValueError(f"mrilc_moves.{name} must be one or more finite numbers, got {values}")
        self.match_timeout = float(v.match_timeout)
        self._saved_payload: dict[str, Any] | None = None
        restored = node.restore(self._build, {"per_move": "mrilc"})
        self.payload = PayloadGlue(node, self.params, self.operator, self._saved_payload)
        self.moves, warned = restored if restored is not None else ({}, False)
        self._resumed = len(self.moves)
        self.cycles: MoveCycles[_Cycle] = MoveCycles(lambda c: c.applied is None and not c.refused,
                                                     lambda key, goal: _Cycle(key, math.nan, goal))
        self._samples: collections.deque[tuple[float, float, float, float]] = collections.deque(maxlen=MAX_SAMPLES)
        self.latest_imu = -math.inf
        topics = self.params.value.topics
        self.events_topic, self.imu_topic, self.stands_in = topics.cycle_events, topics.imu, True
        subscribe_imu(node, topics, self._on_imu, MutuallyExclusiveCallbackGroup())
        self.proxy = TrajectoryActionProxy(node, "~/follow_joint_trajectory", str(v.controller), self._check,
                                           self._refused, lambda: None, float(v.action_timeout), self._correct)
        self.drift = DriftWarnings(node, str(v.drift_status).strip(), self.relearn, warned)

    # ----------------------------------------------------------------- state
    def _build(self, doc: dict[str, Any]) -> tuple[dict[str, _Move], bool]:
        if set(doc) - {"version", "per_move", "moves", FLAG, KEY, "saved_at"} or not isinstance(doc.get("moves"),
                                                                                            dict):
            raise MrilcError(f"per-move MRILC state entries differ: got {sorted(doc)}")
        out = {}
        for key, entry in doc["moves"].items():
            if not isinstance(entry, dict) or set(entry) != _ENTRY or not isinstance(entry["learner"], dict):
                raise MrilcError(f"move {key}: entries {sorted(_ENTRY)} expected")
            try:
                if move_key(entry["start"], entry["goal"]) != key:
                    raise MrilcError(f"move {key}: its key does not match its start and goal")
            except MoveError as err:
                raise MrilcError(f"move {key}: {err}") from None
            names = entry["joint_names"]
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise MrilcError(f"move {key}: joint_names must be a list of names")
            out[key] = _Move(key, [float(x) for x in entry["start"]], [float(x) for x in entry["goal"]], names,
                             saved=entry["learner"])
        warned = saved_flag(doc, MrilcError)
        self._saved_payload = saved_payload(doc)
        return out, warned

    def state(self) -> dict[str, Any]:
        moves = {}
        for key, m in self.moves.items():
            learner = m.learner.to_dict() if m.learner is not None else m.saved
            if learner is not None:
                moves[key] = {"start": m.start, "goal": m.goal, "joint_names": m.names, "learner": learner}
        return {"per_move": "mrilc", "moves": moves, FLAG: self.drift.warned, **self.payload.state()}

    async def relearn(self, warning: str) -> None:
        """A drift warning: every move's correction dropped, its learner restarted at its next goal (module
        docstring)."""
        keys = [k for k, m in self.moves.items() if m.learner is not None or m.saved is not None]
        self.payload.from_drift(self.drift.values, {k: m.goal for k, m in self.moves.items()})
        for m in self.moves.values():
            m.learner = m.saved = m.plan = m.times = None
        for cyc in [*self.cycles.open.values(), self.cycles.early]:  # under way: its goal ran with the correction
            if cyc is not None and cyc.applied is not None:  # dropped now
                cyc.refused = cyc.refused or RESET
        self.node.save()
        text = self.drift.relearn_line(keys, warning, "the correction of ", "from the current schedule (none)")
        self.node.get_logger().warning(text)
        self.node.diagnostics.publish("moves", WARN, text)

    def describe(self) -> str:
        return (f"MRILC per move on {self.imu_topic}, corrections added to the goals of ~/follow_joint_trajectory"
                f" sent to {self.proxy.controller_name}; {len(self.moves)} moves saved")

    def latest(self) -> float:
        return self.latest_imu

    def ready(self) -> bool:
        return True

    async def start(self) -> bool:
        text = f"MRILC per move: {self._resumed} moves resumed from the state file"
        self.node.get_logger().info(text)
        self.node.diagnostics.publish("moves", OK, text, [(k, "saved") for k in self.moves])
        return True

    async def hold(self, on: bool) -> tuple[bool, str]:
        for m in self.moves.values():
            lr = m.learner
            if lr is None:
                continue
            lr.holding = on
            if on and lr.best is not None:
                lr.coefficients = lr.best[1].copy()
            if not on:
                lr.fallbacks = 0
        return True, "holding every move at its best correction" if on else "learning resumed on every move"

    # ----------------------------------------------------------------- inputs
    def _on_imu(self, t: float, a: tuple[float, float, float]) -> None:
        self._samples.append((t, a[0], a[1], a[2]))
        self.latest_imu = max(self.latest_imu, t)
        keep = self.latest_imu - self.node.max_cycle_duration
        while self._samples and self._samples[0][0] < keep:
            self._samples.popleft()

    def _check(self, traj: JointTrajectory) -> JointTrajectory:
        """The goal request's check (its arrays must read); the correction comes at execution."""
        trajectory_arrays(traj, list(traj.joint_names), True)
        return traj

    def _refused(self, err: InputError) -> None:
        self.node.get_logger().error(f"goal refused: {err}")
        self.node.diagnostics.report("goal", ERROR, f"goal refused: {err}")

    async def _correct(self, traj: JointTrajectory) -> JointTrajectory | None:
        """The goal with its move's correction (None: as it came; module docstring)."""
        names = list(traj.joint_names)
        times, fields = trajectory_arrays(traj, names, True)
        first = fields["positions"][0].copy()  # the move's start (a known move's goal matches at once by it)
        # a point at time 0 (a planner's start; the controller starts from the measured state) passes as it came: the
        # move's profile and correction are the points after it
        lead = int(np.count_nonzero(times <= 0.0))
        head = {k: fields[k][:lead] if k in fields else np.zeros((lead, len(names)))
                for k in ("positions", "velocities", "accelerations", "effort")}
        times, fields = times[lead:], {k: x[lead:] for k, x in fields.items()}
        q = fields["positions"]
        moves = lambda: ((k, m.start, m.goal) for k, m in self.moves.items())  # noqa: E731
        cyc = await await_match(self.node, lambda: self.cycles.for_goal(first, q[-1], moves()), self.match_timeout)
        if cyc is None:
            self.node.get_logger().warning("a goal matched no move's START (its last point is no START's goal):"
                                           " sent uncorrected")
            return None
        move = self.moves[cyc.key]
        v = fields.get("velocities")
        a = fields.get("accelerations")
        if v is None:
            v = np.gradient(q, times, axis=0)
        if a is None:
            a = np.gradient(v, times, axis=0)
        try:
            lr = self._learner(move, times, q, v, a)
        except (MrilcError, ValueError) as err:
            cyc.refused = f"no correction ({err}); sent uncorrected"
            self.node.get_logger().error(f"move {move.key}: {cyc.refused}")
            return None
        dq, dv, da = lr.correction()
        limits = self._limits(q.shape[1])
        breach = limit_breach(q + dq, v + dv, a + da, limits, names, (q, v, a))
        if breach is not None:
            cyc.refused = f"correction refused, it would break a limit: {breach}; sent uncorrected"
            self.node.get_logger().error(f"move {move.key}: {cyc.refused}")
            return None
        qc, vc, ac = clip_into(q + dq, v + dv, a + da, limits, (q, v, a))  # rounding at a limit: onto it
        cyc.applied = (float(np.max(np.abs(qc - q))), float(np.max(np.abs(vc - v))), float(np.max(np.abs(ac - a))))
        cyc.excess = profile_excess(qc, vc, ac, limits, (q, v, a))
        out = {"positions": qc, "velocities": vc, "accelerations": ac}
        if "effort" in fields:
            out["effort"] = fields["effort"]
        out = {k: np.vstack([head[k], x]) for k, x in out.items()}
        return trajectory_msg(traj.header, names, [p.time_from_start for p in traj.points], out)

    def _limits(self, joints: int) -> JointLimits:
        vals = []
        for name, values in zip(("position_min", "position_max", "velocity", "acceleration"), self._limit_values,
                                strict=True):
            if len(values) not in (1, joints):
                raise ValueError(f"mrilc_moves.{name} has {len(values)} values for {joints} joints")
            vals.append(np.resize(np.asarray(values, dtype=float), joints))
        return JointLimits(*vals)

    def _learner(self, move: _Move, times: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> MoveLearner:
        """The move's learner for this goal's profile: built at its first goal (from its saved state after a
        restart), rebuilt (keeping its state) when the profile changed."""
        if move.learner is not None and move.times is not None and move.times.shape == times.shape and np.allclose(
                move.times, times) and move.plan is not None and np.allclose(move.plan.profile.positions, q):
            return move.learner
        plan = plan_move(times, q, v, a, move.start, self.settings)
        limits = self._limits(q.shape[1])
        mass = self.payload.mass()
        op = plan_operator(plan, self.payload.provider(), move.goal, q.shape[1], self.settings.output_period)
        self.node.get_logger().info(f"move {move.key}: operator built for "
                                    + (f"a payload of {mass:g} kg" if mass > 0 else "the provider's own payload"))
        state = move.learner.to_dict() if move.learner is not None else move.saved
        kw: dict[str, Any] = {**self.learner_settings, "weights": plan.weights}
        learner = None
        if state is not None:
            try:
                learner = MoveLearner.from_dict(state, op, plan.profile, limits, **kw)
                self.node.get_logger().info(f"move {move.key}: resumes at cycle {learner.cycle} from its saved state")
            except MrilcError as err:
                self.node.get_logger().error(f"move {move.key}: {err}; it starts afresh")
                self.node.diagnostics.report("state_file", ERROR, f"move {move.key}: {err}")
        move.learner = learner or MoveLearner(op, plan.profile, limits, **kw)
        move.plan, move.times, move.saved = plan, times.copy(), None
        return move.learner

    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        cycle = int(msg.cycle)
        if msg.event == START:
            try:
                key = move_key(msg.start_positions, msg.goal_positions)
            except MoveError as err:
                self.node.get_logger().error(f"cycle {cycle}: the move cannot be identified: {err}")
                return None
            new = key not in self.moves
            if new:
                self.moves[key] = _Move(key, [float(x) for x in msg.start_positions],
                                        [float(x) for x in msg.goal_positions], list(msg.joint_names))
            opened = self.cycles.started(cycle, _Cycle(key, stamp, np.asarray(msg.goal_positions, dtype=float)),
                                         stood_in)
            if stood_in:  # its samples must reach back to the stand-in's stamp, and its goal must have been matched
                held = self._samples[0][0] if self._samples else None
                opened.refused = opened.refused or unseen_window(stamp, held) \
                    or ("" if opened.applied is not None else unmatched(new, UNMATCHED))
            self.payload.seen(cycle, key)
            return None
        if msg.event != END:
            return None
        cyc = self.cycles.ended(cycle)
        if cyc is None:
            return self.node.skipped(msg, (math.nan, stamp), "END without its START")
        move = self.moves[cyc.key]
        lr, plan = move.learner, move.plan
        shaped = self.node.goals.refusal(cycle, False)  # its goal shaped with the active shaper as a fallback
        if cyc.refused or shaped or cyc.applied is None or lr is None or plan is None:
            why = cyc.refused or shaped or "no goal of the move came through the learner"
            return self.node.skipped(msg, (cyc.start, stamp), why)
        window = (cyc.start + plan.motion_end, cyc.start + float(plan.grid[-1]))
        samples = [s for s in self._samples if cyc.start <= s[0] <= window[1] + self.settings.output_period]
        try:
            arr = np.asarray(samples, dtype=float).reshape(-1, 4)
            e = residual_error(plan, arr[:, 0] - cyc.start, arr[:, 1:], self.settings.trend_degree)
            upd = lr.update(e)
        except MrilcError as err:
            return self.node.skipped(msg, window, str(err))
        self.node.save()
        index = list(self.moves).index(cyc.key)
        names = ["move", "iteration", "cost", f"action.{upd.action}", "gain", "max_correction_rad",
                 "max_correction_rad_s", "max_correction_rad_s2", "limit_excess"]
        values = [float(index), float(upd.cycle), upd.cost, 1.0, upd.gain, *cyc.applied, cyc.excess]
        self.node.get_logger().info(f"cycle {cycle}, move {cyc.key}: cost {upd.cost:.4g} m/s^2, {upd.action}"
                                    f" (iteration {upd.cycle}); correction used {cyc.applied[0]:.3g} rad")
        return self.node.report(msg, window, names, values, residual=upd.cost)
