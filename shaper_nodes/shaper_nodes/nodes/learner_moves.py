"""The learner node's LIST mode per move (``list.per_move: true``): one learned factor per move, over the schedule.

A cycle event's START names the move that runs (its ``start_positions`` and ``goal_positions``:
the move's identity is :func:`shaper_nodes.core.learning.moves.move_key` of them). For each move
the learner keeps its own LIST learner (:mod:`shaper_nodes.core.learning.list`), learns it from
that move's own residual window only, and sends the move's two-impulse factor to the scheduler
named by ``shaper`` (``<shaper>/set_move_shaper``, shaper_msgs/SetMoveShaper, with the move's start
and goal). The scheduler convolves the factor with its schedule at the goal pose for every goal of
that move the shaper node's proxy asks it about (``~/shaper_at`` with the goal's first point as
``start``; nodes/scheduler_moves.py). The shaper node's active shaper is not touched.

- **A new move** runs its first cycle with the schedule alone (the scheduler has no factor for it):
  that cycle is the LIST reference. The move's learner starts from the schedule's lowest mode at
  the goal pose (asked of ``<shaper>/shaper_at``; ZV formulas) and stays on it: its T2 is bounded to
  :data:`T2_BAND` (+-10 %) of that mode's frequency unless ``list.t2_bounds`` is set
  (:func:`schedule_config`). Its residual window starts after the schedule's shaper there plus the
  factor's longest T2 (unless ``list.window_delay`` is set). Without joint names in the event, or
  without an answer, or with ``list.start: identified`` (LIST per move with no calibration: a scheduler of
  family ``none`` only carries the factors to the shaper node's proxy; the demo's ``list_moves``), the start
  is the mode identified in the reference cycle, as the task-wide LIST does.
- **A factor is kept only when it pays** (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays`): the
  reference cycle's M (the schedule alone) is the move's base; a trial that measures more stops the
  move's learning at the best measured: LIST holds at its best factor if one beat the base, otherwise
  the move is held at the schedule alone (its cycles are then reported with the metric ``held``, not
  learned from, until ``~/hold`` false). So at most one cycle per move is worse than the schedule.
- **State**: every move's learner in the state file, one entry per move
  (:class:`~shaper_nodes.core.learning.moves.MoveStore`, ``{"version": 1, "structure", "per_move",
  "moves", "joint_names", "at_schedule", "saved_at"}``), saved atomically after each update and loaded entry by
  entry: a broken entry is left out and reported (``/diagnostics``, ``learner: state_file``), its
  move starts afresh, the others resume. At start the learner sends every saved move's factor to
  the scheduler again, so each move resumes from its saved state (also after a kill -9, and for a
  restarted scheduler).
- **A correction not acknowledged** (the scheduler refused or did not answer) is sent again at the
  move's next START, and that cycle is not learned from (it may have run with either).
- **A cycle whose goal ran with the active shaper** (the shaper node's ``~/shaped_goals``: the scheduler did not
  answer, or no ``action.scheduler``) is not learned from, with the reason (core/learning/goal_shaping.py).
- ``~/hold``: every move holds at its best factor (or learns again).
- ``/diagnostics``: once the saved factors are sent at start, an OK status ``learner: moves`` with the
  number of moves resumed and, per move key, what its goals run with.
- **A drift warning relearns every move** (a payload change: what was learned no longer fits). At the
  first WARN of the status ``list.drift_status`` (default the identifier's ``identifier: drift``) on
  ``/diagnostics`` (:mod:`.learner_drift`: once per warning episode, an OK ends it), every move starts
  again from the current schedule (:meth:`~shaper_nodes.core.learning.moves.MoveStore.relearn`): its
  learner, factor, base and hold are dropped, one line on the log names the moves reset, the state is
  saved (atomically, with the episode flag ``drift_warned``), and every move's factor is withdrawn from the
  scheduler (``set_move_shaper`` with family ``none``: the schedule alone). Each move's next cycle is
  then its new reference, its learner made as for a new move from the schedule's lowest mode at its goal, or in the
  episode from the lowest mode the drift watch identified in the move's latest cycle (its statuses' ``modes_hz``)
  when that is more than :data:`T2_BAND` off the schedule's (the payload moved it; not kept over a restart);
  a cycle under way at the warning is not learned from; a withdrawal the scheduler did not acknowledge is
  sent again at the move's next START (and that cycle is not learned from).

- **Each factor chosen to pay** (``payback.enabled``, :mod:`.learner_payback`): instead of the iterative LIST
  learner, each move's factor is picked after its reference cycle from the components of its residual and the
  time cost predicted from its goal (recorded by the learner's own ``~/follow_joint_trajectory``, in front of the
  shaper node's), tried once and kept only if it pays: the rule of the reproduction's ``scheduled_list_factor``;
  with ``payback.max_factors`` > 1 the move takes a new reference with its kept factors and may stack the next one
  (sent convolved, one impulse sequence).

Reports (``~/reports``): one per cycle as in the task-wide mode, the metric ``move`` being the
move's index in the state file's order (stable across restarts).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import JointState

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetMoveShaper, ShaperAt
from shaper_nodes.core.cycles import END, STAND_IN_SPAN, START
from shaper_nodes.core.learning.list import ListConfig, ListError, ListLearner, ListParams, ListSession
from shaper_nodes.core.learning.list.stack import Wanted, stack_shaper
from shaper_nodes.core.learning.list.stack import factors_of as _factors
from shaper_nodes.core.learning.moves import MoveEntry, MoveError, MoveStore, keep_when_it_pays
from shaper_nodes.core.shaping import Mode, ShaperError, none_shaper
from shaper_nodes.ros.conversions import mode_from_msg, shaper_to_msg
from shaper_nodes.ros.diagnostics import OK
from shaper_nodes.ros.parameters import declare
from shaper_nodes.ros.shaper_client import ServiceClient

from .learner_base import LearnerBase
from .learner_drift import FLAG, DriftWarnings, saved_flag
from .learner_list import subscribe_imu
from .learner_payback import PaybackMoves, PaybackParams
from .move_goals import load_moves

#: why a move's cycle is not learned from once it is held at the schedule alone
HELD = "held at the schedule alone: no factor was measured better than it (~/hold false learns again)"
_DOC_KEYS = {"version", "structure", "per_move", "moves", "joint_names", "at_schedule", FLAG, "stacks", "poles",
             "saved_at"}
#: why a cycle under way when the moves were relearned is not learned from
RESET = "every move was relearned (drift warning) while this cycle ran"


#: a move's factor started from the schedule's lowest mode stays within this fraction of that mode's frequency
#: (:meth:`~shaper_nodes.core.learning.list.ListParams.t2_band`; the reproduction's ``LIST_BAND``)
T2_BAND = 0.1


def resumed_line(moves: int) -> str:
    """The start-up line (log and ``/diagnostics`` ``learner: moves``) once every saved move's factor was acknowledged
    by the scheduler: from then on a move's START is learned from (before it, the START sends the factor again and
    its cycle is not: it may have run with either)."""
    return f"learning per move: {moves} moves resumed from the state file"


def schedule_config(config: ListConfig, initial: ListParams, shaper_end: float | None) -> ListConfig:
    """The LIST configuration of a move whose learner starts from the schedule's lowest mode (``initial``).

    Its T2 is bounded to ``initial.t2_band(T2_BAND)`` (unless ``config.t2_bounds`` is set), so the
    factor's frequency stays within +-10 % of that mode's and cannot drift between two modes (or
    to a longer, slower pair). With ``shaper_end`` (s, the schedule's shaper's last impulse at the
    goal; None keeps ``config.window_delay``) the residual window starts after that shaper plus the
    factor's longest duration (its T2 bound, twice for ``zvd3``).

    Parameters
    ----------
    config : ListConfig
        The node's LIST configuration.
    initial : ListParams
        The move's start (ZV formulas at the schedule's lowest mode at its goal).
    shaper_end : float or None
        The schedule's shaper duration at the goal, s, or None.

    Returns
    -------
    ListConfig
        ``config`` with ``t2_bounds`` (and ``window_delay``) set.
    """
    bounds = config.t2_bounds if config.t2_bounds is not None else initial.t2_band(T2_BAND)
    out = dataclasses.replace(config, t2_bounds=bounds)
    if shaper_end is not None:
        longest = bounds[1] * (2.0 if config.structure == "zvd3" else 1.0)
        out = dataclasses.replace(out, window_delay=shaper_end + longest)
    return out


def _sent(learner: ListLearner) -> ListParams | None:
    """What a move's learner has its goals run with next (None: the schedule alone, its reference cycle)."""
    return learner.params if learner.reference is not None else None


def _describe(params: Wanted) -> str:
    return "schedule alone" if params is None else "; ".join(f"factor A1 {p.a1:.5f}, T2 {p.t2:.5f} s"
                                                             for p in _factors(params))


class MovesMode:
    """The per-move LIST adapter of the learner node (see the module docstring)."""

    def __init__(self, node: LearnerBase, declared: tuple[Any, ListConfig]) -> None:
        self.node = node
        self.params, self.config = declared
        v = self.params.value
        self.structure = self.config.structure
        self.user_delay = float(v.list.window_delay) > 0.0
        self.saved_stacks: Any = None  # the payback rule's stacked factors per move, as saved ("stacks")
        self.saved_poles: Any = None  # ... and its pooled windows per move ("poles": learner_payback_pole)
        restored = node.restore(self._build, {"structure": self.structure, "per_move": True})
        #: the moves, their joint names, and those held at the schedule alone (no factor measured better)
        self.store, self.names, self.held, warned = restored if restored is not None else (MoveStore(), {}, set(),
                                                                                             False)
        self._restored = [e.key for e in self.store]  # the moves of the state file, sent again at start
        self.learners: dict[str, ListLearner] = {}
        for entry in self.store:
            learner = entry.learner()
            if learner is not None:
                self.learners[entry.key] = learner
        #: per move, the factor the scheduler acknowledged (absent: not acknowledged since start)
        self.applied: dict[str, Wanted] = {}
        #: the moves whose withdrawal after a relearn the scheduler did not acknowledge (sent again at START)
        self.unreset: set[str] = set()
        self.session = ListSession(ListLearner(self.config), self.structure, float(node.params.value.stale_after),
                                   node.max_cycle_duration, float(v.sensor.max_abs_accel), STAND_IN_SPAN)
        self.events_topic, self.stands_in = v.topics.cycle_events, True
        self.imu_topic = v.topics.imu
        self._cycle_move: dict[int, str] = {}  # cycle -> move key, or why the cycle is not learned from
        self._skip: dict[int, str] = {}
        scheduler = node.shaper.srv_name.rsplit("/", 1)[0]
        self.set_move = ServiceClient(node, SetMoveShaper, f"{scheduler}/set_move_shaper", node.service_timeout,
                                      node.diagnostics)
        self.shaper_at = ServiceClient(node, ShaperAt, f"{scheduler}/shaper_at", node.service_timeout,
                                       node.diagnostics)
        subscribe_imu(node, v.topics, lambda t, a: node.notice(self.session.on_imu(t, a)),
                      MutuallyExclusiveCallbackGroup())
        self.drift = DriftWarnings(node, str(v.list.drift_status).strip(), self.relearn, warned)
        group = declare(node, PaybackParams).value.payback
        #: the payback rule (``payback.enabled``; :mod:`.learner_payback`), None: the iterative LIST per move
        self.payback = PaybackMoves(self, group) if group.enabled else None

    async def close_cycle(self, entry: MoveEntry) -> tuple[Wanted, bool, int]:
        """After a move's cycle was learned from: send what its goals run with next if it changed, count the
        cycle and save the state. Returns what is wanted next, whether the scheduler took it, the move's index."""
        nxt = self._wanted(entry.key)
        applied = True
        if nxt != self.applied.get(entry.key):
            applied = bool(await self._send(entry, nxt))
        entry.cycles += 1
        self.node.save()
        return nxt, applied, [e.key for e in self.store].index(entry.key)

    def _wanted(self, key: str) -> Wanted:
        """What the move's goals run with next (None: the schedule alone)."""
        if self.payback is not None:
            return None if key not in self.store or key in self.held else self.payback.wanted(key)
        learner = self.learners.get(key)
        return None if learner is None or key in self.held else _sent(learner)

    # ----------------------------------------------------------------- state
    def _build(self, doc: dict[str, Any]) -> tuple[MoveStore, dict[str, list[str]], set[str], bool]:
        if set(doc) - _DOC_KEYS or "moves" not in doc:
            raise MoveError(f"per-move state entries differ: expected {sorted(_DOC_KEYS)}, got {sorted(doc)}")
        store, names = load_moves(self.node, doc)
        held = doc.get("at_schedule") or []
        if not isinstance(held, list) or not all(isinstance(k, str) for k in held):
            raise MoveError("at_schedule must be a list of move keys")
        self.saved_stacks, self.saved_poles = doc.get("stacks"), doc.get("poles")
        return store, names, {k for k in held if k in store}, saved_flag(doc)

    def state(self) -> dict[str, Any]:
        for key, learner in self.learners.items():
            entry = self.store.get(key)
            if entry is not None:
                entry.list_state = learner.to_dict()
        doc = {"structure": self.structure, "per_move": True, "moves": self.store.to_doc(),
               "joint_names": self.names, "at_schedule": sorted(self.held), FLAG: self.drift.warned}
        if self.payback is not None:
            doc["stacks"], doc["poles"] = self.payback.stacks_doc(), self.payback.pole.doc()
        return doc

    def describe(self) -> str:
        if self.payback is not None:
            return self.payback.describe()
        return (f"LIST per move ({self.structure}, rule {self.config.rule}) on {self.imu_topic}, factors kept by"
                f" {self.set_move.srv_name}; {len(self.store)} moves saved")

    def latest(self) -> float:
        return float(self.session.latest_imu)

    def ready(self) -> bool:
        return self.set_move.service_is_ready() and self.shaper_at.service_is_ready()

    # ----------------------------------------------------------------- the scheduler
    async def start(self) -> bool:
        """Every saved move's factor to the scheduler (the moves resume from their saved state)."""
        answered = True
        resumes = self.learners if self.payback is None else self.store  # (payback: every entry has its phase)
        for key in self._restored:
            entry = self.store.get(key)
            if entry is not None and key in resumes and key not in self.applied:  # (a START may have sent it)
                answered = await self._send(entry, self._wanted(key)) is not None and answered
        if answered:  # the moves' state, once, on the log and /diagnostics ("learner: moves")
            moves = [(k, _describe(self._wanted(k)) if k in resumes else "afresh") for k in self._restored]
            text = resumed_line(len(moves))
            self.node.get_logger().info(text + "".join(f"; {k}: {d}" for k, d in moves))
            self.node.diagnostics.publish("moves", OK, text, moves)
        return answered

    async def _send(self, entry: MoveEntry, params: Wanted) -> bool | None:
        """The move's factor(s) to the scheduler; True if acknowledged, False if refused, None if unanswered."""
        names = self.names.get(entry.key, [])
        sh = stack_shaper(_factors(params), self.structure)
        msg = ShaperMsg(family="none", source=self.node.shaper.source) if sh is None else \
            shaper_to_msg(sh, self.node.shaper.source, 0)
        req = SetMoveShaper.Request(start=JointState(name=names, position=entry.start),
                                    goal=JointState(name=names, position=entry.goal), shaper=msg)
        answer = await self.set_move.call(req)
        if answer.response is None:
            self.node.get_logger().error(f"move {entry.key}: {answer.error}")
            return None
        if not answer.response.success:
            self.node.get_logger().error(f"move {entry.key}: the scheduler refused the factor:"
                                         f" {answer.response.message}")
            return False
        self.applied[entry.key] = params
        if params is None:
            self.unreset.discard(entry.key)
        entry.correction = None if sh is None else (sh.amplitudes.tolist(), sh.times.tolist())
        return True

    async def relearn(self, warning: str) -> None:
        """A drift warning: every move learns again from the current schedule (module docstring)."""
        keys = self.store.relearn("schedule")
        self.learners.clear()
        self.held.clear()
        if self.payback is not None:
            self.payback.clear()
        for cycle in self._cycle_move:  # under way: it ran with the factor withdrawn now
            self._skip.setdefault(cycle, RESET)
        self.node.save()
        self.node.get_logger().warning(self.drift.relearn_line(keys, warning))
        for key in keys:
            entry = self.store.get(key)
            if entry is not None and not await self._send(entry, None):
                self.applied.pop(key, None)
                self.unreset.add(key)
        if self.unreset:
            self.node.get_logger().error(f"the scheduler did not take the reset of {', '.join(sorted(self.unreset))};"
                                         " sent again at each move's next start")

    async def _learner_for(self, entry: MoveEntry, names: list[str]) -> ListLearner:
        """A new move's learner: from the schedule's lowest mode at the goal (module docstring)."""
        config, initial, why = self.config, None, "no joint names in the cycle event"
        if str(self.params.value.list.start) == "identified":  # no calibration: nothing to ask
            entry.origin = "identified"
            self.node.get_logger().info(f"move {entry.key}: starts from the mode identified in its reference cycle"
                                        " (list.start identified)")
            return ListLearner(self.config)
        if names:
            req = ShaperAt.Request(pose=JointState(name=names, position=entry.goal),
                                   start=JointState(name=names, position=entry.start))
            answer = await self.shaper_at.call(req)
            resp = answer.response
            why = answer.error if resp is None else resp.message
            if resp is not None and resp.success and len(resp.estimate.modes):
                try:
                    lowest = min((mode_from_msg(m) for m in resp.estimate.modes), key=lambda m: m.omega)
                    drifted = self.drift.drifted_mode(entry.key, lowest.hz, T2_BAND)
                    initial = ListParams.from_mode(Mode(lowest.omega if drifted is None else 2 * math.pi * drifted,
                                                        lowest.zeta))
                    end = float(resp.shaper.times[-1]) if len(resp.shaper.times) else 0.0
                    config = schedule_config(self.config, initial, None if self.user_delay else end)
                    learner = ListLearner(config, initial)
                    entry.origin = "schedule"
                    lo, hi = config.t2_bounds or (math.nan, math.nan)
                    start = (f"the schedule's lowest mode {lowest.hz:.4g} Hz" if drifted is None else
                             f"the lowest mode the drift watch identified in its last cycle, {drifted:.4g} Hz (the"
                             f" schedule's {lowest.hz:.4g} Hz is the unchanged plant's)")
                    self.node.get_logger().info(f"move {entry.key}: starts from {start}, zeta {lowest.zeta:.3g} at its"
                                                f" goal; T2 within {lo * 1e3:.1f}-{hi * 1e3:.1f} ms")
                    return learner
                except (ShaperError, ListError, ValueError) as err:
                    why = str(err)
        entry.origin = "identified"
        self.node.get_logger().warning(f"move {entry.key}: no schedule at its goal ({why}); the mode identified"
                                       " in its reference cycle is the start")
        return ListLearner(self.config)

    # ----------------------------------------------------------------- inputs
    async def hold(self, on: bool) -> tuple[bool, str]:
        if self.payback is not None:
            self.payback.hold(on)
        ok = True
        for entry in list(self.store):
            learner = self.learners.get(entry.key)
            if learner is None and self.payback is None:
                continue
            if learner is not None and not on:
                learner.resume()
                self.held.discard(entry.key)
            elif learner is not None and learner.reference is not None and entry.key not in self.held:
                learner.hold()
            wanted = self._wanted(entry.key)
            if entry.key not in self.applied or self.applied[entry.key] != wanted:
                ok = bool(await self._send(entry, wanted)) and ok
        what = "holding every move at its best factor" if on else "learning resumed on every move"
        return ok, what + ("" if ok else "; the scheduler did not take every factor")

    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        cycle = int(msg.cycle)
        self.node.unended(self._cycle_move, msg, self._skip)
        if msg.event == START:
            await self._on_start(msg, stamp, stood_in)
            return None
        if msg.event == END and not self._skip.get(cycle):  # its goal shaped otherwise: no update (goal_shaping)
            shaped = self.node.goals.refusal(cycle, True)
            if shaped:
                self._skip[cycle] = shaped
                self.session.drop(cycle)
                if self.payback is not None:
                    self.payback.forget(cycle)
        result = self.session.on_event(msg.event, cycle, stamp, msg.start_positions, msg.goal_positions)
        if msg.event != END:
            return None
        key = self._cycle_move.pop(cycle, None)
        skip = self._skip.pop(cycle, "")
        if skip == HELD and key is not None:  # not learned from, and not a fault: a report saying so
            self.node.get_logger().info(f"cycle {cycle}, move {key}: {HELD}")
            index = [e.key for e in self.store].index(key)
            return self.node.report(msg, (math.nan, stamp), ["move", "held"], [float(index), 1.0])
        if result is None or key is None or skip:
            window = (math.nan, stamp) if result is None else (result.start, result.end)
            why = skip or (result.skipped if result is not None else "") or "END without its START"
            return self.node.skipped(msg, window, why, result.refusal if result is not None else "")
        if self.payback is not None:
            return await self.payback.on_end(msg, key, result)
        return await self._on_end(msg, key, result)

    async def _on_start(self, msg: CycleEvent, stamp: float, stood_in: bool) -> None:
        cycle = int(msg.cycle)
        self.session.expect_start(stamp)  # the samples that come while this START awaits the scheduler are kept
        try:
            entry, new = self.store.entry(msg.start_positions, msg.goal_positions)
        except MoveError as err:
            self._skip[cycle] = f"the cycle's move cannot be identified: {err}"
            return
        self._cycle_move[cycle] = entry.key
        self.drift.ran(cycle, entry.key)
        if new:
            self.names[entry.key] = list(msg.joint_names)
        if self.payback is not None:
            await self.payback.on_start(msg, stamp, entry, new, stood_in)
            return
        learner = self.learners.get(entry.key)
        if learner is None:
            learner = self.learners[entry.key] = await self._learner_for(entry, list(msg.joint_names))
            if entry.key not in self.unreset:  # a new or relearned move: the scheduler has no factor for it
                self.applied[entry.key] = None
        wanted = self._wanted(entry.key)
        if entry.key not in self.applied or self.applied[entry.key] != wanted:
            await self._send(entry, wanted)  # (again): the cycle may have run with either
            self._skip[cycle] = "the move's factor was not acknowledged by the scheduler before its start"
        if entry.key in self.held:
            self._skip[cycle] = HELD  # not learned from either way
        if cycle in self._skip:
            return
        self.session.switch(learner, (*_factors(wanted), None)[0])  # (the iterative LIST: one factor at most)
        self.session.on_event(msg.event, cycle, stamp, msg.start_positions, msg.goal_positions, stood_in)

    async def _on_end(self, msg: CycleEvent, key: str, result: Any) -> CycleReport:
        entry = self.store.get(key)
        assert entry is not None
        update = result.update
        window = (result.start, result.end)
        if update is None or update.action == "rejected" or update.next is None:
            return self.node.skipped(msg, window, result.skipped or (update.reason if update else ""),
                                     result.refusal)
        learner = self.learners[key]
        kept = self._keep_when_it_pays(entry, learner, update)
        nxt, applied, index = await self.close_cycle(entry)
        used = update.used or ListParams(math.nan, math.nan)
        after = (*_factors(nxt), ListParams(math.nan, math.nan))[0]
        names = ["move", "M", "phi", "iteration", "a1_used", "t2_used", "a1_next", "t2_next", "applied", "held",
                 f"action.{update.action}", f"parameter.{update.parameter}"]
        values = [float(index), update.m, update.phi, float(update.iteration), used.a1, used.t2, after.a1, after.t2,
                  1.0 if applied else 0.0, 1.0 if key in self.held or learner.holding else 0.0, 1.0, 1.0]
        report = self.node.report(msg, window, names, values, residual=update.m)
        report.shaper_used = self._shaper_msg(update.used)
        report.shaper_next = self._shaper_msg(nxt)
        text = (f"cycle {msg.cycle}, move {key}: M {update.m:.4g}, {update.action} ({update.parameter}):"
            f" {_describe(update.used)} -> {_describe(nxt)}" + kept + ("" if applied else "; not acknowledged"))
        # one call site per severity: rclpy refuses a call site whose severity changes between calls
        if applied:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().error(text)
        return report

    def _keep_when_it_pays(self, entry: MoveEntry, learner: ListLearner, update: Any) -> str:
        """A factor is kept only when it pays (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays`);
        returns what was decided, for the log ("" if the move learns on)."""
        best = learner.best
        decision = keep_when_it_pays(entry, update.m, update.used is not None, None if best is None else best[1])
        base = entry.base["residual_rms"] if entry.base is not None else math.nan
        if decision == "best":
            learner.hold()
            return f"; M above the schedule's ({base:.4g}): holding at the best factor measured"
        if decision == "base":
            self.held.add(entry.key)
            return f"; M above the schedule's ({base:.4g}) and no factor better: the schedule alone, held"
        return ""

    def _shaper_msg(self, params: Wanted) -> ShaperMsg:
        shaper = stack_shaper(_factors(params), self.structure) or none_shaper()
        return shaper_to_msg(shaper, self.node.shaper.source, 0)
