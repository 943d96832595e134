"""The learner node's speed-up per move (``mode: speed_moves``): each move learns to run faster while it settles.

Issue 31's item 4 over DDS, on the ROS-free :class:`~shaper_nodes.core.learning.speed.SpeedLearner` (the one the
reproduction ``reproductions.arm_learning``'s ``speedup`` case runs).

**Where the factor is applied: before shaping.** The learner serves ``~/follow_joint_trajectory``
(control_msgs/FollowJointTrajectory, :class:`~.trajectory_action.TrajectoryActionProxy`) in front of the shaper
node's proxy: the motion source sends its goals to ``/learner/follow_joint_trajectory``, the learner time-scales each
and sends it on to ``speed.controller`` (the shaper node's ``/shaper/follow_joint_trajectory``), which shapes it for
its final pose and sends it to the controller. A shaper's impulses are tuned to the mode; scaling a shaped
trajectory would shift them off it, so the scaling comes first. Each goal is matched to the move whose cycle START
came last (``/cycle_events``: its goal pose equal to the goal's last point), or at once to a known move whose start
and goal are its first and last points (its START not come yet, or missed: the START or its stand-in claims it;
core/learning/move_cycles.py); a goal of a move not known yet waits up to ``speed.match_timeout`` s for its START.
Its points run ``s`` times faster
(:func:`~shaper_nodes.core.learning.speed.time_scale`: times / s up to the motion's last point, velocities x s,
accelerations x s^2; a hold at the goal keeps its length). A goal matched to no move goes on as planned.

**Limits.** Every goal's planned points are checked against ``speed.velocity`` and ``speed.acceleration`` (one
value per joint or one for all) at its request: a goal past a limit is rejected, and one line names the joint, the
limit and the point. A move's factor never exceeds ``speed.max_factor`` nor the largest factor its planned profile
allows within the limits (:func:`~shaper_nodes.core.learning.speed.limit_ceiling`), and the scaled points are
checked again before they are sent. Torque cannot be computed before the move (the node has no dynamic model of
the robot): it is measured during it. The joint efforts and velocities the robot reports on ``speed.joint_states``
(a UR: joint torques, N m; the simulated arm: its motor torques) are watched from the move's START to its residual
window's end (:mod:`.learner_efforts`), and a move whose largest |effort| exceeded ``speed.max_effort`` on a joint
(one value per joint or one for all; inf: not watched), or whose largest measured |velocity| exceeded
``speed.velocity`` (a robot may overshoot its plan), is a bad cycle, its factor lowered at once as for the residual
(:func:`~shaper_nodes.core.learning.speed.peak_check`). With a finite effort limit, a move without efforts measured
is not learned from. **Before a raise** the move's peaks are predicted at the new factor from those it measured at
the factors it ran at (:mod:`~shaper_nodes.core.learning.speed_peaks`: torque a + b s^2, speed b s), and the raise
stops where a prediction passes its limit less ``speed.limit_margin`` of it (the log line says which joint).

**What is good.** At the move's END, the settled residual is the peak of the tool accelerometer's deviation from
its mean (``topics.imu``; the three axes' magnitude) in the window of ``speed.window`` s after the commanded motion
ends, less the position loop's transient (``speed.transient`` s). The motion ends at the scaled plan's end plus the
schedule's shaper at the goal (its duration from ``<speed.scheduler>/shaper_at``; ``speed.shaper_delay`` when there
is no scheduler). The tolerance ``speed.tolerance`` (m at the flange) is converted to the accelerometer level at
the goal's lowest mode f (the schedule's, or ``speed.frequency_hz``): tolerance x (2 pi f)^2
(:func:`~shaper_nodes.core.learning.speed.acceleration_tolerance`; 0.05 mm at 10 Hz: 0.197 m/s^2). A cycle is good
when the peak is within it and the measured efforts within their limits (its plan held the velocity and
acceleration limits: it was checked). After a good cycle the move's factor is
raised, after a bad one lowered at once to the largest good one
(:class:`~shaper_nodes.core.learning.speed.SpeedLearner`).

**A drift warning starts every move again at the planned speed** (a payload change: a heavier payload lowers
the modes and rings more at the same speed, so the factors learned no longer hold). At the first WARN of the status
``speed.drift_status`` (default the identifier's ``identifier: drift``) on ``/diagnostics`` (:mod:`.learner_drift`:
once per warning episode, an OK ends it), every move's speed learner starts again from 1 (the planned speed;
:meth:`~shaper_nodes.core.learning.speed.SpeedLearner.relearn`): its good and
failed factors are forgotten, one line on the log names the moves, and the state is saved (atomically, with the
episode flag ``drift_warned``). A cycle under way at the warning is not learned from (its goal ran with the old
factor on the changed arm). Why 1 and not the last good factor lowered: nothing learned on the old payload bounds
the new one's good factor (the modes moved, and the schedule's shaper with them); at 1 the move runs as planned and
as scheduled, and climbs again by ``speed.step`` per good cycle.

**State.** Every move's speed learner in ``state_file`` (:class:`~shaper_nodes.core.learning.moves.MoveStore`, the
entry's ``speed``), with its joint names, saved atomically after each update and loaded entry by entry (a broken
entry is left out and reported; its move starts afresh); after a restart each move resumes at its saved factor.

Reports (``~/reports``): per move's END, the metrics ``move`` (index in the state's order), ``speed_factor`` (the
factor the goal ran with), ``factor_next``, ``ceiling``, ``peak`` and ``tolerance`` (m/s^2), ``peak_mm`` (the peak
converted to the flange, mm), ``frequency_hz``, ``motion_s`` (the scaled plan's motion, s), ``velocity_ratio`` and
``acceleration_ratio`` (the scaled plan's largest against its limit), ``effort_ratio`` (the largest measured
|effort| against its limit; nan: not watched), ``effort_joint`` (that joint's index; -1: none) and ``effort_ok``,
``speed_ratio``, ``speed_joint`` and ``speed_ok`` (the same of the measured |velocity| against ``speed.velocity``;
nan: none reported), ``allowed_factor`` (the factor the predicted peaks allowed; nan: none predicted), ``held`` (1:
the raise was held or cut short by the prediction), ``ok`` and ``holding``; residual_rms: the window's RMS. A bad
cycle's reason (residual, effort or speed: the joint named) and a held raise's (the joint predicted past its limit)
are on the log line and in the move's saved history.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.cycles import END, START, unseen_window
from shaper_nodes.core.learning.move_cycles import MoveCycles, unmatched
from shaper_nodes.core.learning.moves import MoveError, MoveStore
from shaper_nodes.core.learning.speed import (
    SpeedError,
    SpeedLearner,
    SpeedSettings,
    acceleration_tolerance,
    limit_breach,
    limit_ceiling,
    motion_end_index,
    peak_check,
    time_scale,
)
from shaper_nodes.core.learning.speed_peaks import UNITS, PeakLimits
from shaper_nodes.core.shaping.vibration import residual_vibration
from shaper_nodes.ros.conversions import mode_from_msg, trajectory_arrays, trajectory_msg
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN
from shaper_nodes.ros.parameters import declare
from shaper_nodes.ros.shaper_client import ServiceClient

from .learner_base import LearnerBase
from .learner_drift import FLAG, DriftWarnings, saved_flag
from .learner_efforts import EffortWatch
from .learner_list import subscribe_imu
from .learner_speed_parameters import SpeedMovesParams, on_set, refusal
from .move_goals import await_match, load_moves
from .trajectory_action import TrajectoryActionProxy

#: most accelerometer samples kept (a bound whatever the cycle events do)
MAX_SAMPLES = 400_000
_DOC_KEYS = {"version", "per_move", "moves", "joint_names", FLAG, "saved_at"}
#: why a cycle under way when the moves were relearned is not learned from
RESET = "every move's factor was relearned (drift warning) while this cycle ran"
#: how a goal matched to no cycle went (the reason a cycle whose START was missed is not learned from: unmatched())
UNMATCHED = "it went as planned, its factor not recorded"


@dataclass
class _Cycle:
    key: str
    start: float  # the move's start (the START's stamp), s
    goal: np.ndarray
    factor: float | None = None  # the factor its goal ran with (None: no goal scaled yet)
    ceiling: float = math.nan
    motion: float = math.nan  # the scaled plan's motion, s from the start
    delay: float = 0.0  # the schedule's shaper at the goal, s
    frequency: float | None = None  # the conversion's mode, Hz
    ratios: tuple[float, float] = (math.nan, math.nan)  # the scaled plan's largest velocity, acceleration / limit
    refused: str = ""  # why the goal went as planned, or the moves were relearned meanwhile (not learned from)
    taken: bool = False  # a goal was matched to it (its factor read)


class SpeedMovesMode:
    """The speed-per-move adapter of the learner node (see the module docstring)."""

    def __init__(self, node: LearnerBase) -> None:
        self.node = node
        self.params = declare(node, SpeedMovesParams)
        v = self.params.value.speed
        for name in ("velocity", "acceleration", "max_effort"):
            why = refusal(name, getattr(v, name))
            if why:
                raise ValueError(why)
        node.add_on_set_parameters_callback(on_set)
        self.settings = SpeedSettings(step=float(v.step), floor=1.0, ceiling=float(v.max_factor),
                                      resolution=float(v.resolution))
        restored = node.restore(self._build, {"per_move": "speed"})
        self.store, self.names, warned = restored if restored is not None else (MoveStore(), {}, False)
        self._resumed = len(self.store)
        self.holding = False
        self.cycles: MoveCycles[_Cycle] = MoveCycles(lambda c: not c.taken and not c.refused,
                                                     lambda key, goal: _Cycle(key, math.nan, goal))
        self._samples: collections.deque[tuple[float, float, float, float]] = collections.deque(maxlen=MAX_SAMPLES)
        self.latest_imu = -math.inf
        topics = self.params.value.topics
        self.events_topic, self.imu_topic, self.stands_in = topics.cycle_events, topics.imu, True
        subscribe_imu(node, topics, self._on_imu, MutuallyExclusiveCallbackGroup())
        scheduler = str(v.scheduler).strip().rstrip("/")
        self.shaper_at = (ServiceClient(node, ShaperAt, f"{scheduler}/shaper_at", node.service_timeout,
                                        node.diagnostics) if scheduler else None)
        self.proxy = TrajectoryActionProxy(node, "~/follow_joint_trajectory", str(v.controller), self._check,
                                           self._refused, lambda: None, float(v.action_timeout), self._scale)
        self.drift = DriftWarnings(node, str(v.drift_status).strip(), self.relearn, warned)
        topic = str(v.joint_states).strip()
        self.efforts = EffortWatch(node, topic, node.max_cycle_duration) if topic else None

    # ----------------------------------------------------------------- state
    def _build(self, doc: dict[str, Any]) -> tuple[MoveStore, dict[str, list[str]], bool]:
        if set(doc) - _DOC_KEYS or not isinstance(doc.get("moves"), dict):
            raise MoveError(f"per-move speed state entries differ: expected {sorted(_DOC_KEYS)}, got {sorted(doc)}")
        return (*load_moves(self.node, doc), saved_flag(doc))

    def state(self) -> dict[str, Any]:
        return {"per_move": "speed", "moves": self.store.to_doc(), "joint_names": self.names,
                FLAG: self.drift.warned}

    async def relearn(self, warning: str) -> None:
        """A drift warning: every move's factor starts again from 1 (module docstring)."""
        keys = self.store.relearn("schedule")
        for cyc in [*self.cycles.open.values(), self.cycles.early]:  # under way: its goal ran (or is being
            if cyc is not None and cyc.taken:  # scaled) with the old factor
                cyc.refused = cyc.refused or RESET
        self.node.save()
        text = self.drift.relearn_line(keys, warning, "the speed of ", "from the planned speed (factor 1)")
        self.node.get_logger().warning(text)
        self.node.diagnostics.publish("moves", WARN, text)

    def describe(self) -> str:
        return (f"speed-up per move on {self.imu_topic}, time-scaled goals of ~/follow_joint_trajectory sent to"
                f" {self.proxy.controller_name}; {len(self.store)} moves saved")

    def latest(self) -> float:
        efforts = self.efforts
        if efforts is None or efforts.latest == -math.inf or not self._watching():
            return self.latest_imu
        return min(self.latest_imu, efforts.latest)  # (the END waits for both)

    def _watching(self) -> bool:
        """Whether the efforts are checked (a finite speed.max_effort)."""
        return any(math.isfinite(x) for x in self.params.value.speed.max_effort)

    def ready(self) -> bool:
        return True

    async def start(self) -> bool:
        moves = [(e.key, f"factor {float(e.speed_state['factor']):.3f}" if e.speed_state else "afresh")
                 for e in self.store]
        text = f"speed-up per move: {self._resumed} moves resumed from the state file"
        self.node.get_logger().info(text + "".join(f"; {k}: {d}" for k, d in moves))
        self.node.diagnostics.publish("moves", OK, text, moves)
        return True

    async def hold(self, on: bool) -> tuple[bool, str]:
        self.holding = on
        if on:  # every move at its largest good factor
            for entry in self.store:
                sp = entry.speed()
                if sp is not None:
                    sp.factor = sp.good if sp.good is not None else sp.settings.floor
                    entry.speed_state = sp.to_dict()
        return True, ("holding every move at its largest good factor" if on else "learning resumed on every move")

    # ----------------------------------------------------------------- goals
    def _on_imu(self, t: float, a: tuple[float, float, float]) -> None:
        self._samples.append((t, a[0], a[1], a[2]))
        self.latest_imu = max(self.latest_imu, t)
        keep = self.latest_imu - self.node.max_cycle_duration
        while self._samples and self._samples[0][0] < keep:
            self._samples.popleft()

    def _per_joint(self, name: str, joints: int) -> np.ndarray:
        values = getattr(self.params.value.speed, name)
        if len(values) not in (1, joints):
            raise InputError("wrong_size", f"speed.{name} has {len(values)} values for {joints} joints")
        return np.resize(np.asarray(values, dtype=float), joints)

    def _limits(self, joints: int) -> tuple[np.ndarray, np.ndarray]:
        return self._per_joint("velocity", joints), self._per_joint("acceleration", joints)

    @staticmethod
    def _profile(traj: JointTrajectory) -> tuple[list[str], np.ndarray, dict[str, np.ndarray], np.ndarray,
                                                 np.ndarray]:
        """The goal's arrays and its velocities and accelerations (differentiated where not given)."""
        names = list(traj.joint_names)
        times, fields = trajectory_arrays(traj, names, True)
        q = fields["positions"]
        v = fields.get("velocities")
        a = fields.get("accelerations")
        if v is None:
            v = np.gradient(q, times, axis=0) if len(times) > 1 else np.zeros_like(q)
        if a is None:
            a = np.gradient(v, times, axis=0) if len(times) > 1 else np.zeros_like(q)
        return names, times, fields, v, a

    def _check(self, traj: JointTrajectory) -> JointTrajectory:
        """The goal request's check: its arrays read, and its planned points within the joint limits."""
        names, times, _, v, a = self._profile(traj)
        vmax, amax = self._limits(len(names))
        breach = limit_breach(times, v, a, vmax, amax, names)
        if breach is not None:
            raise InputError("beyond_limits", f"the planned trajectory breaks a joint limit: {breach}")
        return traj

    def _refused(self, err: InputError) -> None:
        self.node.get_logger().error(f"goal refused: {err}")
        self.node.diagnostics.report("goal", ERROR, f"goal refused: {err}")

    async def _scale(self, traj: JointTrajectory) -> JointTrajectory | None:
        """The goal time-scaled by its move's factor (None: as planned; module docstring)."""
        names, times, fields, v, a = self._profile(traj)
        q = fields["positions"]

        moves = lambda: ((e.key, e.start, e.goal) for e in self.store)  # noqa: E731
        cyc = await await_match(self.node, lambda: self.cycles.for_goal(q[0], q[-1], moves()),
                                float(self.params.value.speed.match_timeout))
        if cyc is None:
            self.node.get_logger().warning("a goal matched no move's START (its last point is no START's goal):"
                                           " sent as planned")
            return None
        cyc.taken = True
        entry = self.store.get(cyc.key)
        assert entry is not None
        vmax, amax = self._limits(len(names))
        ceiling = min(self.settings.ceiling, limit_ceiling(v, a, vmax, amax))
        try:
            sp = entry.speed() or SpeedLearner(SpeedSettings(self.settings.step, 1.0, max(ceiling, 1.0),
                                                             self.settings.resolution))
        except SpeedError as err:  # (checked when loaded: not expected)
            cyc.refused = f"its speed state cannot be read ({err}); sent as planned"
            self.node.get_logger().error(f"move {cyc.key}: {cyc.refused}")
            return None
        entry.speed_state = sp.to_dict()
        factor = max(1.0, min(sp.factor, ceiling))
        st, sv, sa = time_scale(times, q, v, a, factor)
        assert sv is not None and sa is not None  # (given: they are)
        breach = limit_breach(st, sv, sa, vmax, amax, names)
        if breach is not None:
            cyc.refused = f"the scaled goal would break a joint limit ({breach}); sent as planned"
            self.node.get_logger().error(f"move {cyc.key}: {cyc.refused}")
            return None
        cyc.delay, cyc.frequency = await self._schedule_at(names, q[0], q[-1])
        cyc.factor, cyc.ceiling = factor, ceiling
        cyc.motion = float(st[motion_end_index(q)])
        cyc.ratios = (float(np.max(np.abs(sv) / vmax)), float(np.max(np.abs(sa) / amax)))
        if factor == 1.0:
            return None  # as planned
        out: dict[str, np.ndarray] = {"positions": q}
        _, gv, ga = time_scale(times, q, fields.get("velocities"), fields.get("accelerations"), factor)
        if gv is not None:
            out["velocities"] = gv
        if ga is not None:
            out["accelerations"] = ga
        if "effort" in fields:
            out["effort"] = fields["effort"]
        return trajectory_msg(traj.header, names, st, out)

    async def _schedule_at(self, names: list[str], start: np.ndarray, goal: np.ndarray) -> tuple[float, float | None]:
        """The schedule's shaper duration (s) and lowest mode (Hz) at the goal; the parameters' where not asked or
        not answered (frequency None: none known)."""
        v = self.params.value.speed
        delay, freq = float(v.shaper_delay), (float(v.frequency_hz) or None)
        if self.shaper_at is None:
            return delay, freq
        req = ShaperAt.Request(pose=JointState(name=names, position=goal.tolist()),
                               start=JointState(name=names, position=start.tolist()))
        answer = await self.shaper_at.call(req)
        resp = answer.response
        if resp is None or not resp.success:
            why = answer.error if resp is None else resp.message
            self.node.get_logger().warning(f"no schedule at the goal ({why}): speed.shaper_delay {delay:g} s"
                                           + ("" if freq else "; no mode for the tolerance: not learned from"))
            return delay, freq
        if len(resp.shaper.times):
            delay = float(resp.shaper.times[-1])
        if freq is None and len(resp.estimate.modes):
            freq = min(mode_from_msg(m).hz for m in resp.estimate.modes)
        return delay, freq

    # ----------------------------------------------------------------- cycles
    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        cycle = int(msg.cycle)
        if msg.event == START:
            try:
                entry, new = self.store.entry(msg.start_positions, msg.goal_positions)
            except MoveError as err:
                self.node.get_logger().error(f"cycle {cycle}: the move cannot be identified: {err}")
                return None
            if new:
                self.names[entry.key] = list(msg.joint_names)
            opened = self.cycles.started(cycle, _Cycle(entry.key, stamp, np.asarray(msg.goal_positions, dtype=float)),
                                         stood_in)
            if stood_in:  # its samples must reach back to the stand-in's stamp, and its goal must have been matched
                held = self._samples[0][0] if self._samples else None
                opened.refused = opened.refused or unseen_window(stamp, held) \
                    or ("" if opened.taken else unmatched(new, UNMATCHED))
            return None
        if msg.event != END:
            return None
        cyc = self.cycles.ended(cycle)
        if cyc is None:
            return self.node.skipped(msg, (math.nan, stamp), "END without its START")
        shaped = self.node.goals.refusal(cycle, bool(str(self.params.value.speed.scheduler).strip()))
        if cyc.refused or shaped or cyc.factor is None:
            return self.node.skipped(msg, (cyc.start, stamp), cyc.refused or shaped or "no goal of the move came"
                                     " through the learner")
        if cyc.frequency is None:
            return self.node.skipped(msg, (cyc.start, stamp), "no mode to convert the tolerance (no schedule at the"
                                     " goal and speed.frequency_hz 0)")
        v = self.params.value.speed
        end = cyc.start + cyc.motion + cyc.delay
        window = (end + float(v.transient), min(end + float(v.window), stamp))
        arr = np.asarray([s for s in self._samples if window[0] <= s[0] < window[1]], dtype=float).reshape(-1, 4)
        if arr.shape[0] < 3:
            return self.node.skipped(msg, window, f"{arr.shape[0]} accelerometer samples in the residual window")
        res = residual_vibration(arr[:, 0], arr[:, 1:], window[0], window[1], remove_mean=True)
        tol = acceleration_tolerance(float(v.tolerance), cyc.frequency)
        joints = self.names.get(cyc.key, [])
        effort, speed = (None, None) if self.efforts is None else self.efforts.peaks(joints, cyc.start, window[1])
        if self._watching() and effort is None:
            return self.node.skipped(msg, window, f"no joint efforts measured during the move on"
                                     f" '{v.joint_states}': speed.max_effort cannot be checked")
        try:
            limits = PeakLimits(tuple(joints), {"effort": self._per_joint("max_effort", len(joints)),
                                                "velocity": self._limits(len(joints))[0]}, float(v.limit_margin))
            watch = {"effort": self._watching(), "velocity": True}
            checks = [peak_check(p, limits.limits[q], joints, q, UNITS[q]) if p is not None and watch[q]
                      else (math.nan, -1, None) for q, p in (("effort", effort), ("velocity", speed))]
        except (InputError, SpeedError) as err:
            return self.node.skipped(msg, window, f"the measured peaks cannot be checked: {err}")
        reasons = [] if res.peak <= tol else [f"settled residual peak {res.peak:.4g} m/s^2 above {tol:.4g} m/s^2"]
        reasons += [c[2] for c in checks if c[2]]
        ok, reason = not reasons, "; ".join(reasons)
        moved = self.store.get(cyc.key)
        assert moved is not None
        sp = moved.speed()
        assert sp is not None
        sp.factor = cyc.factor
        if self.holding:
            sp.record(cyc.factor, {"effort": effort, "velocity": speed})
            nxt = sp.factor
        else:
            nxt = sp.update(ok, reason, {"effort": effort, "velocity": speed}, limits)
        moved.speed_state = sp.to_dict()
        moved.cycles += 1
        self.node.save()
        index = [e.key for e in self.store].index(cyc.key)
        mm = 1e3 * res.peak / (2.0 * math.pi * cyc.frequency) ** 2
        names = ["move", "speed_factor", "factor_next", "ceiling", "peak", "tolerance", "peak_mm", "frequency_hz",
                 "motion_s", "velocity_ratio", "acceleration_ratio", "effort_ratio", "effort_joint", "effort_ok",
                 "speed_ratio", "speed_joint", "speed_ok", "allowed_factor", "held", "ok", "holding"]
        (effort_ratio, effort_joint, breach), (speed_ratio, speed_joint, overshoot) = checks
        values = [float(index), cyc.factor, nxt, cyc.ceiling, res.peak, tol, mm, cyc.frequency, cyc.motion,
                  *cyc.ratios, effort_ratio, float(effort_joint), 0.0 if breach else 1.0, speed_ratio,
                  float(speed_joint), 0.0 if overshoot else 1.0, math.nan if sp.cap is None else sp.cap,
                  1.0 if sp.held else 0.0, 1.0 if ok else 0.0, 1.0 if self.holding or sp.holding else 0.0]
        largest = "".join(f", largest {q} {r:.3g} of its limit ({joints[j]})" for q, (r, j, _) in
                          zip(("effort", "speed"), checks, strict=True) if j >= 0)
        text = (f"cycle {cycle}, move {cyc.key}: factor {cyc.factor:.3f}, settled peak {res.peak:.4g} m/s^2 in"
                f" {window[0]:.3f}-{window[1]:.3f} s ({mm:.4f} mm at {cyc.frequency:.3g} Hz; tolerance {tol:.4g}"
                f" m/s^2){largest}: {'good' if ok else 'bad: ' + reason} -> {nxt:.3f}"
                + (f" (not raised further: {sp.held})" if sp.held else ""))
        if ok:  # (one severity per call site: rclpy refuses a call site that changes it)
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().warning(text)
        return self.node.report(msg, window, names, values, residual=res.rms)
