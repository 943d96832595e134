"""LIST per move over the schedule, each move's factor chosen to pay before it is tried (``payback.enabled``).

The learner node's per-move LIST (:mod:`.learner_moves`, ``list.per_move: true``) with the rule of the ROS-free
reproduction's ``scheduled_list_factor`` case (``reproductions.arm_learning``) instead of the iterative
:class:`~shaper_nodes.core.learning.list.ListLearner`:

- **the move's planned goal**: the learner serves ``~/follow_joint_trajectory``
  (:class:`~.trajectory_action.TrajectoryActionProxy`) in front of the shaper node's proxy (``payback.controller``,
  ``/shaper/follow_joint_trajectory``): the motion source sends its goals to ``/learner/follow_joint_trajectory``,
  the learner records each goal's waypoints (:class:`GoalRecorder`) and sends the goal on unchanged; the shaper
  node shapes it for its final pose as before. The waypoints are the planned command the factor's time cost is
  predicted from: the goal the shaper node receives, not a copy of it sent by the client.
- **reference cycle** (a new move, or one relearned after a drift warning): the schedule alone. At its END the
  cycle's residual M (m/s^2: RMS of the accelerometer's deviation from its mean, 1 s from the shaped command's end,
  :func:`residual_m`) is the move's base (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays`); the
  components of the residual are identified from the same window
  (:func:`~shaper_nodes.core.learning.list.payback.components`: the modes that ring and the position loop's damped
  poles), and :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks the two-impulse factor with the
  least predicted residual among those whose time cost, predicted from the move's planned goal shaped by the
  schedule at its goal (``<shaper>/shaper_at``) with and without the factor
  (:func:`~shaper_nodes.core.learning.list.payback.time_cost`: every joint within ``payback.joint_tolerance`` rad of
  its goal, commands at ``payback.rate_hz``), is within one 2 ms sample
  (:data:`~shaper_nodes.core.learning.moves.TIME_TOLERANCE_S`). The factor goes to the scheduler
  (``set_move_shaper``). No factor predicted to pay (or no goal recorded for the move): the move is held at the
  schedule alone.
- **trial cycle**: the factor over the schedule. It is kept when its M is below the base's
  (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays`; the node measures no flange position, so the
  measured time is not weighed: the time was predicted before the trial); otherwise it is withdrawn and the move
  is held at the schedule alone.
- **stacked factors** (``payback.max_factors`` > 1, the reproduction's stacking): after a factor is kept, the
  move's next cycle is a new reference with the kept factor(s) in place: its M is the new base, the next factor is
  chosen from its components (their strongest remaining, by the predicted residual) with the time cost of the kept
  factors and the new one together against the schedule alone, tried over the kept factors and kept only if its
  M is below that reference's. The move's factors reach the scheduler convolved, one impulse sequence
  (:func:`~shaper_nodes.core.learning.list.stack.stack_shaper`; the scheduler takes at most 16 impulses, 1 s:
  :data:`~shaper_nodes.core.scheduling.moves.MAX_FACTOR_DURATION`; a factor that would make the sequence longer
  is not tried). A trial that does not pay is withdrawn and the move stays with the factors kept before it.
- **after**: the kept factors (or the schedule alone) stay; each cycle is still measured and reported. The default
  ``payback.max_factors`` 1 is one factor per move.
- **pooled references** (``payback.pool_cycles``, default 5; :mod:`.learner_payback_pole`, the rule of
  :mod:`shaper_nodes.core.learning.list.pole_rule`, the reproduction's): a move over a schedule with no factor kept
  whose reference finds none predicted to pay runs its reference again, up to that many cycles, the windows aligned
  at the shaped command's end and averaged; the loop's pole is searched in the mean and a factor on it chosen by the
  same time rule; its trial is judged at the pole (its own windows pooled: kept when its response there is lower by
  2 standard errors of the change, run again when lower but not resolved, withdrawn otherwise). A factor from one window
  whose trial did not pay sends the move's references to the pool from then on.

State: the move's entry (:class:`~shaper_nodes.core.learning.moves.MoveEntry`): ``base`` (the latest reference's
M), ``correction`` (the factors kept and on trial, convolved), ``best`` (the kept trial's M); the move's
:class:`~shaper_nodes.core.learning.list.stack.FactorStack` (the factors kept, the trial, whether more are looked
for) in the document's ``stacks``; the pooled windows (a running sum, one second of accelerometer per move at
most) and the poles a trial is judged at in ``poles``; moves held at the schedule alone are the document's
``at_schedule``. Saved
atomically after every cycle; after a restart (a kill -9) every move resumes in its phase, its factors sent to the
scheduler again.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.learning.list import ListError, ListParams
from shaper_nodes.core.learning.list.payback import (
    EXTRA_DAMPED,
    Component,
    PaybackChoice,
    components,
    lowest_first,
    paying_factor,
    time_cost,
)
from shaper_nodes.core.learning.list.settle import DEFAULT_HZ, imu_settle, lowest_paying, unshaped_time_cost
from shaper_nodes.core.learning.list.stack import FactorStack, stack_duration, stack_shaper, wanted
from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S, MoveEntry, keep_when_it_pays
from shaper_nodes.core.learning.speed import acceleration_tolerance
from shaper_nodes.core.scheduling.moves import MAX_FACTOR_DURATION
from shaper_nodes.core.shaping import Shaper, ShaperError
from shaper_nodes.ros.diagnostics import ERROR

from .learner_payback_cycle import (
    RESIDUAL_WINDOW,
    Captured,
    CycleCapture,
    factor_of,
    legacy_stack,
    phase,
    residual_m,
    unshaped,
)
from .learner_payback_parameters import PARAMETERS, PaybackGroup, PaybackParams
from .learner_payback_pole import PooledPole
from .move_goals import GoalRecorder, Planned
from .trajectory_action import TrajectoryActionProxy

__all__ = ["PARAMETERS", "RESIDUAL_WINDOW", "Captured", "CycleCapture", "GoalRecorder", "PaybackGroup", "PaybackMoves",
           "PaybackParams", "Planned", "choose", "factor_of", "legacy_stack", "phase", "residual_m", "scheduled_cost",
           "settle_band", "unshaped"]

#: the factor's T2 stays within this fraction of a component's frequency (the reproduction's ``LIST_BAND``)
BAND = 0.1




def settle_band(comps: list[Component], group: PaybackGroup) -> float:
    """A move's settled band on the accelerometer, m/s^2: ``payback.settle_tolerance`` at its lowest mode that rings
    (of ``comps``; the lowest component if none rings, :data:`~shaper_nodes.core.learning.list.settle.DEFAULT_HZ`
    if none)."""
    order = lowest_first(comps, float(group.servo_zeta))
    return acceleration_tolerance(float(group.settle_tolerance), order[0].hz if order else DEFAULT_HZ)


def choose(cap: Captured, command_end: float, planned: Planned, base: Shaper | None, group: PaybackGroup,
           kept: tuple[ListParams, ...] = (), slack: float = 0.0, band: float | None = None) -> PaybackChoice | None:
    """The factor predicted to pay for a move (module docstring), from its reference cycle ``cap`` (shaped
    command's end at ``command_end`` s from START), its planned goal and the schedule at its goal (``base``); with
    ``kept`` factors, the time cost is theirs and the new one's together, against the schedule alone. With no
    schedule (:func:`unshaped`): a full pair per ringing mode, lowest first (``settle.lowest_paying``), the time cost
    against the measured move + settle (``settle.unshaped_time_cost``), within one 2 ms sample plus ``slack`` s
    (how much shorter the reference's measured move + settle is than the move's unshaped one: its budget)."""
    comps = components(cap.times, cap.accel, command_end, float(group.servo_zeta), extra_damped=EXTRA_DAMPED)
    if unshaped(base):
        def command(factors: tuple[ListParams, ...]) -> float:
            sh = stack_shaper(factors)
            return 0.0 if sh is None else time_cost(planned.times, planned.positions, planned.velocities, None, sh,
                                                    float(group.rate_hz), float(group.joint_tolerance),
                                                    interpolate=True)

        band = settle_band(comps, group) if band is None else band
        return lowest_paying(comps, unshaped_time_cost(comps, band, kept, command),
                             TIME_TOLERANCE_S + slack, float(group.servo_zeta), band=BAND, kept=kept)

    return paying_factor(comps, scheduled_cost(planned, base, group, kept), TIME_TOLERANCE_S, band=BAND)


def scheduled_cost(planned: Planned, base: Shaper | None, group: PaybackGroup,
                   kept: tuple[ListParams, ...] = ()) -> Callable[[ListParams], float]:
    """A factor's predicted time cost over the schedule ``base`` at the move's goal, s: the ``kept`` factors and it
    together against the schedule alone (:func:`~shaper_nodes.core.learning.list.payback.time_cost`)."""
    def cost(p: ListParams) -> float:
        factor = stack_shaper((*kept, p)) if kept else p
        assert factor is not None
        return time_cost(planned.times, planned.positions, planned.velocities, base, factor, float(group.rate_hz),
                         float(group.joint_tolerance), interpolate=True)

    return cost


def _pair(factors: tuple[ListParams, ...]) -> tuple[list[float], list[float]] | None:
    sh = stack_shaper(factors)
    return None if sh is None else (sh.amplitudes.tolist(), sh.times.tolist())


class PaybackMoves:
    """The payback rule inside the per-move LIST mode (:class:`~.learner_moves.MovesMode`; module docstring)."""

    def __init__(self, mode: Any, group: PaybackGroup) -> None:  # a MovesMode: learner_moves imports this module
        if mode.structure != "zv2":
            raise ValueError(f"payback.enabled needs list.structure zv2 (a two-impulse factor), got {mode.structure!r}")
        controller = str(group.controller).strip()
        if not controller:
            raise ValueError("payback.enabled needs payback.controller: the action its goals are sent on to")
        self.mode, self.group, self.node = mode, group, mode.node
        self.goals = GoalRecorder()
        self.capture = CycleCapture()
        #: per move, the schedule's shaper at its goal (None: no schedule: unshaped), asked at its first START
        self.schedule: dict[str, Shaper | None] = {}
        self._phase: dict[int, str] = {}  # cycle -> the move's phase at its START
        self._ran: dict[int, tuple[ListParams, ...]] = {}  # cycle -> the factors it ran with
        self.max_factors = int(group.max_factors)
        #: per move, its factors (kept, on trial); a state saved before ``stacks`` is read from its entry's phase
        self.stacks: dict[str, FactorStack] = {}
        saved = mode.saved_stacks if isinstance(mode.saved_stacks, dict) else {}
        for entry in mode.store:
            try:
                self.stacks[entry.key] = FactorStack.from_dict(saved[entry.key]) if entry.key in saved else \
                    legacy_stack(entry, entry.key in mode.held)
            except ListError as err:  # the move keeps its other state; its factors start afresh
                self.node.get_logger().error(f"move {entry.key}: saved factors left out ({err})")
                self.stacks[entry.key] = FactorStack()
        #: per move, the pooled-pole rule's state (``payback.pool_cycles``; :mod:`.learner_payback_pole`)
        self.pole = PooledPole(int(group.pool_cycles), float(group.servo_zeta), BAND, mode.saved_poles,
                               [e.key for e in mode.store], self.node.get_logger().error)
        self.proxy = TrajectoryActionProxy(self.node, "~/follow_joint_trajectory", controller, self.goals.record,
                                           self._refused, lambda: None, float(group.action_timeout))

    def forget(self, cycle: int) -> None:
        """A cycle under way that will not be learned from (its goal shaped with another shaper)."""
        self._phase.pop(int(cycle), None)
        self._ran.pop(int(cycle), None)

    def stack(self, key: str) -> FactorStack:
        return self.stacks.setdefault(key, FactorStack())

    def stacks_doc(self) -> dict[str, Any]:
        return {k: s.to_dict() for k, s in self.stacks.items()}

    def clear(self) -> None:
        """Every move learns again (a drift warning): no factor, nothing pooled."""
        self.stacks.clear()
        self.pole.clear()

    def wanted(self, key: str) -> ListParams | tuple[ListParams, ...] | None:
        """What the move's goals run with (the kept factors and the trial), None: the schedule alone."""
        return wanted(self.stack(key).factors())

    def phase(self, key: str) -> str:
        return self.stack(key).phase(key in self.mode.held, self.max_factors)

    def describe(self) -> str:
        return (f"LIST per move, each factor chosen to pay (payback) on {self.mode.imu_topic}; goals of"
                f" ~/follow_joint_trajectory sent on to {self.proxy.controller_name}, factors kept by"
                f" {self.mode.set_move.srv_name}; {len(self.mode.store)} moves saved")

    def _refused(self, err: InputError) -> None:
        self.node.get_logger().error(f"goal refused: {err}")
        self.node.diagnostics.report("goal", ERROR, f"goal refused: {err}")

    def hold(self, on: bool) -> None:
        """``~/hold`` true: no more trials (a factor on trial is withdrawn, a kept one stays); false: every move
        not kept learns again from a new reference."""
        mode = self.mode
        for entry in mode.store:
            ph, st = self.phase(entry.key), self.stack(entry.key)
            if on and ph in ("reference", "trial"):
                st.trial, st.done = None, True
                self.pole.clear(entry.key)
                if not st.kept:
                    mode.held.add(entry.key)
                entry.correction = _pair(st.factors())
            elif not on and ph == "held":
                mode.held.discard(entry.key)
                entry.base = entry.best = None
                self.stacks[entry.key] = FactorStack()
                self.pole.clear(entry.key)
        self.node.save()

    async def _schedule_at(self, entry: MoveEntry, names: list[str]) -> Shaper | None:
        """The schedule alone at the move's goal (``<shaper>/shaper_at`` without a move), None if none."""
        why = "no joint names in the cycle event"
        if names:
            answer = await self.mode.shaper_at.call(ShaperAt.Request(pose=JointState(name=names,
                                                                                     position=entry.goal)))
            resp = answer.response
            why = answer.error if resp is None else resp.message
            if resp is not None and resp.success:
                try:  # the impulses as the scheduler designed them (its family's name, or "custom")
                    return Shaper(np.asarray(resp.shaper.amplitudes, dtype=float),
                                  np.asarray(resp.shaper.times, dtype=float), "custom")
                except (ShaperError, ValueError) as err:
                    why = str(err)
        self.node.get_logger().warning(f"move {entry.key}: no schedule at its goal ({why}): factors predicted"
                                       " against the unshaped command")
        return None

    async def on_start(self, msg: CycleEvent, stamp: float, entry: MoveEntry, new: bool,
                       stood_in: bool = False) -> None:
        mode, cycle, key = self.mode, int(msg.cycle), entry.key
        if key not in self.schedule:
            self.schedule[key] = await self._schedule_at(entry, mode.names.get(key, list(msg.joint_names)))
        if new and key not in mode.unreset:  # the scheduler has no factor for a new move
            mode.applied[key] = None
        wanted = mode._wanted(key)
        if key not in mode.applied or mode.applied[key] != wanted:
            await mode._send(entry, wanted)  # (again): the cycle may have run with either
            mode._skip[cycle] = "the move's factor was not acknowledged by the scheduler before its start"
            return
        self._phase[cycle] = self.phase(key)
        ran = self._ran[cycle] = self.stack(key).factors()
        mode.session.switch(self.capture, ran[-1] if ran else None)  # (the cycle's own record: _ran)
        mode.session.on_event(msg.event, cycle, stamp, msg.start_positions, msg.goal_positions, stood_in)

    async def on_end(self, msg: CycleEvent, key: str, result: Any) -> CycleReport:
        mode, cycle = self.mode, int(msg.cycle)
        ph = self._phase.pop(cycle, "")
        cap, self.capture.captured = self.capture.captured, None
        entry = mode.store.get(key)
        window = (result.start, result.end)
        if cap is None or entry is None or not ph:
            return self.node.skipped(msg, window, result.skipped or "the cycle's samples were not captured",
                                     result.refusal)
        sched = self.schedule.get(key)
        ran = self._ran.pop(cycle, ())
        used = ran[-1] if ran else None
        shaper_end = (float(sched.times[-1]) if sched is not None else 0.0) + stack_duration(ran)
        m, command_end = residual_m(cap, shaper_end)
        if not math.isfinite(m):
            return self.node.skipped(msg, window, f"no accelerometer sample within {RESIDUAL_WINDOW:g} s of the"
                                     f" shaped command's end ({command_end:.3f} s after the START)", "sensor")
        # with no schedule the vibration sets the move + settle time: measured on the accelerometer, and weighed
        choice, note, st = None, "", self.stack(key)
        ms = None
        if unshaped(sched):
            if st.band is None:  # the move's first cycle, its unshaped reference (or a state saved before bands)
                st.band = settle_band(components(cap.times, cap.accel, command_end, float(self.group.servo_zeta),
                                                 extra_damped=EXTRA_DAMPED), self.group)
            ms = imu_settle(cap.times, cap.accel, cap.motion_end, cap.end, st.band)
        if ph == "reference":
            # the time budget: the move's first (unshaped) reference's, carried over by every later reference
            budget = entry.base.get("move_settle_s") if ms is not None and entry.base is not None else None
            keep_when_it_pays(entry, m, False, move_settle_s=ms if budget is None else budget)
            slack = 0.0 if ms is None or budget is None else max(budget - ms, 0.0)
            choice, note, again = self._choose(entry, cap, command_end, sched, st.kept, slack, st.band)
            st.trial = None if choice is None else choice.params
            st.done = choice is None and not again
            if st.done and not st.kept:
                mode.held.add(key)
        elif ph == "trial" and self.pole.judging(key):  # a factor from pooled references: judged at the pole
            note = self._judged(entry, st, cap, command_end, m)
        elif ph == "trial":
            decision = keep_when_it_pays(entry, m, True, move_settle_s=ms)
            base = entry.base["residual_rms"] if entry.base is not None else math.nan
            t_base = entry.base.get("move_settle_s", math.nan) if entry.base is not None else math.nan
            timed = "" if ms is None else f"; move + settle {ms:.3f} s against the unshaped {t_base:.3f} s"
            if decision == "learn" and st.trial is not None:
                st.kept.append(st.trial)
                more = len(st.kept) < self.max_factors
                note = (f"; M below the {'reference' if len(st.kept) > 1 or ms is not None else 'schedule'}'s"
                        f" ({base:.4g}{timed}): the factor is kept ({len(st.kept)} kept"
                        + ("; the next cycle is a new reference with them)" if more else ")"))
            else:  # with no factor kept over a schedule: its references pooled from here on (learner_payback_pole)
                pool = not st.kept and not unshaped(sched) and self.pole.single_failed(key)
                st.done = not pool
                if not st.kept and not pool:
                    mode.held.add(key)
                note = (f"; {'M not below' if ms is None else 'no lower M or a longer move + settle than'} the"
                        f" reference's ({base:.4g}{timed}): withdrawn, "
                        + ("its references pooled from here on" if pool else "the schedule alone, held"
                           if not st.kept else f"the {len(st.kept)} factor(s) kept stay"))
            st.trial = None
        entry.correction = _pair(st.factors())
        nxt, applied, index = await mode.close_cycle(entry)
        u = used or ListParams(math.nan, math.nan)
        after = st.factors()[-1] if st.factors() else ListParams(math.nan, math.nan)  # the trial or the last kept
        pred = (choice.predicted, choice.without, choice.cost_s, choice.component.hz) if choice is not None else \
            (math.nan,) * 4
        pooled = self.pole.measured.pop(key, (0, math.nan, math.nan))  # (learner_payback_pole)
        names = ["move", "M", "a1_used", "t2_used", "a1_next", "t2_next", "predicted", "without", "cost_s",
                 "component_hz", "applied", "held", "factors_used", "factors_kept", "move_settle_s", "pooled",
                 "at_pole", "at_pole_error", f"phase.{ph}"]
        values = [float(index), m, u.a1, u.t2, after.a1, after.t2, *pred, 1.0 if applied else 0.0,
                  1.0 if key in mode.held else 0.0, float(len(ran)), float(len(st.kept)),
                  math.nan if ms is None else ms, float(pooled[0]), pooled[1], pooled[2], 1.0]
        report = self.node.report(msg, (result.start + command_end, result.start + command_end + RESIDUAL_WINDOW),
                                  names, values, residual=m)
        report.shaper_used = mode._shaper_msg(used)
        report.shaper_next = mode._shaper_msg(nxt)
        with_ = "; ".join(f"factor A1 {p.a1:.4f}, T2 {p.t2 * 1e3:.2f} ms" for p in ran) or \
            ("the schedule alone" if ms is None else "no factor (unshaped)")
        text = (f"cycle {cycle}, move {key} ({ph}): M {m:.4g} m/s^2"
                + ("" if ms is None else f", move + settle {ms:.3f} s (accelerometer, band {st.band:.4g} m/s^2)")
                + f" with {with_}"
                + note + ("" if applied else "; not acknowledged by the scheduler"))
        if applied:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().error(text)
        return report

    def _judged(self, entry: MoveEntry, st: FactorStack, cap: Captured, command_end: float, m: float) -> str:
        """A trial of a factor from pooled references judged at the loop's pole (:mod:`.learner_payback_pole`):
        kept, run again, or withdrawn (the move held); what was decided (for the log)."""
        decision, _, _, note = self.pole.trial(entry.key, cap, command_end)
        if decision == "learn" and st.trial is not None:
            st.kept.append(st.trial)
            entry.best = {"residual_rms": m}
            note += f" ({len(st.kept)} kept" + ("; the next cycle is a new reference with them)"
                                                if len(st.kept) < self.max_factors else ")")
        elif decision == "base":
            st.done = True
            if not st.kept:
                self.mode.held.add(entry.key)
        if decision != "again":
            st.trial = None
        return note

    def _choose(self, entry: MoveEntry, cap: Captured, command_end: float, sched: Shaper | None,
                kept: list[ListParams], slack: float = 0.0,
                band: float | None = None) -> tuple[PaybackChoice | None, str, bool]:
        """The factor predicted to pay for the move after its reference cycle, what was decided (for the log), and
        whether the move runs its reference again (its windows pooled: :mod:`.learner_payback_pole`)."""
        stays = f"the {len(kept)} factor(s) kept stay" if kept else "the schedule alone, held"
        names = self.mode.names.get(entry.key, [])
        planned = self.goals.lookup(names, np.asarray(entry.start), np.asarray(entry.goal)) if names else None
        if planned is None:
            return None, ("; no goal of the move came through ~/follow_joint_trajectory (its waypoints predict a"
                          " factor's time cost): " + stays), False
        pick, why = None, "; its references pooled"
        if not self.pole.pooled_only(entry.key):
            try:
                pick = choose(cap, command_end, planned, sched, self.group, tuple(kept), slack, band)
            except (ListError, ShaperError, ValueError) as err:
                why = f"; no factor chosen ({err})"
            else:
                whose = "the schedule's" if not unshaped(sched) else "the reference's measured"
                why = f"; no factor predicted to pay (within {TIME_TOLERANCE_S * 1e3:.1f} ms of {whose} move + settle)"
        if pick is None and not kept and not unshaped(sched) and self.pole.cycles > 0:  # the loop's pole, pooled
            try:
                cost = scheduled_cost(planned, sched, self.group)
                found, again, note = self.pole.reference(entry.key, cap, command_end, cost)
            except (ListError, ShaperError, ValueError) as err:
                found, again, note = None, False, f"; no loop's pole searched ({err}): " + stays
            if found is None or stack_duration((found.choice.params,)) <= MAX_FACTOR_DURATION:
                return None if found is None else found.choice, why + note, again
        if pick is None:
            return None, why + ": " + stays, False
        if stack_duration((*kept, pick.params)) > MAX_FACTOR_DURATION:
            return None, (f"; the factors with the next ({stack_duration((*kept, pick.params)):.3f} s) would be longer"
                          f" than a move's correction may be ({MAX_FACTOR_DURATION:g} s): not tried; " + stays), False
        c = pick.component
        return pick, (f"; next: factor on {c.hz:.2f} Hz, zeta {c.zeta:.3f}: A1 {pick.params.a1:.4f}, T2"
                      f" {pick.params.t2 * 1e3:.2f} ms{'' if pick.full else ' (partial)'}, predicted M"
                      f" {pick.predicted:.4g} against {pick.without:.4g} m/s^2, time cost {pick.cost_s * 1e3:+.1f} ms"
                      ), False
