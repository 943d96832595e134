"""LIST's paying factors per move over the schedule (:class:`PayingFactors`) and the
``scheduled_list_factor`` case that runs them."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from reproductions.arm_learning.factors import (
    JOINT_TOLERANCE,
    LIST_BAND,
    SERVO_EXTRA,
    _components,
    _factor_count,
    _shaper,
    _times,
)
from reproductions.arm_learning.runs import RATE, Cell, Context, Row, Run, _save, register, row
from reproductions.residual_split import SERVO_ZETA  # more damped than this: the position loop's transient
from shaper_nodes.core.learning.list.pole_rule import POOL_CYCLES  # the node's payback.pool_cycles default

__all__ = ["POOL_CYCLES", "PayingFactors", "scheduled_list_factor"]


class PayingFactors:
    """LIST's paying factors per move over the schedule, one move's cycle at a time (the rule of
    ``scheduled_list_factor``, whose docstring says it; rows and notes under ``case``)."""

    def __init__(self, ctx: Context, case: str) -> None:
        from shaper_nodes.core.learning.moves import MoveStore

        self.ctx, self.case, self.sched, self.store = ctx, case, ctx.schedule(), MoveStore()
        self.kept: dict[str, tuple[Any, Any] | None] = {}  # the kept factors' product per move
        self.trial: dict[str, Any] = {}  # the factor the move's next cycle tries (a PaybackChoice)
        self.budget: dict[str, float] = {}  # the schedule's move + settle time, s: no kept state is slower
        self.stopped: set[str] = set()
        self.pool: dict[str, list[tuple[Any, Any, float]]] = {}  # the move's reference windows (pooled_pick)
        self.at_pole: dict[str, tuple[list[complex], tuple[float, float], Any]] = {}  # a trial's poles, reference
        self.trial_pool: dict[str, list[tuple[Any, Any, float]]] = {}  # its trial windows (judge_at_pole)
        self.pool_only: set[str] = set()  # moves whose trial from one window did not pay: pooled references only

    def shaper(self, mv: Any) -> Any:
        """The move's shaper without a trial: the schedule at its goal and the factors kept."""
        base = self.sched(mv.positions[-1])
        fixed = self.kept.get(self.store.entry(mv.positions[0], mv.positions[-1], origin="schedule")[0].key)
        return base if fixed is None else _shaper(_times((base.amplitudes, base.times), fixed))

    def step(self, cell: Cell, mv: Any, c: int) -> Row:
        """Run the move's cycle ``c`` (a reference or a trial) and learn from it; returns its row."""
        from shaper_nodes.core.learning.list.payback import paying_factor, time_cost
        from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S, keep_when_it_pays
        from shaper_nodes.core.shaping import Shaper

        ctx, case, kept, trial, budget, stopped = self.ctx, self.case, self.kept, self.trial, self.budget, self.stopped
        entry, _ = self.store.entry(mv.positions[0], mv.positions[-1], origin="schedule")
        base = self.sched(mv.positions[-1])
        fixed = kept.get(entry.key)
        current = base if fixed is None else _shaper(_times((base.amplitudes, base.times), fixed))
        choice, decision, used = trial.pop(entry.key, None), "", None
        if choice is None:  # a reference cycle (or a stopped move): the schedule and the kept factors
            run = cell.run(mv, current)
            ms = run.measures.move_and_settle_s
            action = "stopped" if entry.key in stopped else "reference"
            if entry.key not in stopped:
                budget.setdefault(entry.key, ms)
                keep_when_it_pays(entry, run.measures.residual_rms, False, move_settle_s=budget[entry.key])
                allowed = TIME_TOLERANCE_S

                def cost(p: Any, mv: Any = mv, base: Any = base, fixed: Any = fixed) -> float:
                    """The time cost of the kept factors and ``p`` together, against the schedule alone."""
                    pair = p.shaper()
                    both = _times(fixed, (pair.amplitudes, pair.times))
                    assert both is not None
                    return time_cost(mv.times, mv.positions, mv.velocities, base,
                                     Shaper(both[0], both[1], "custom"), RATE, JOINT_TOLERANCE, interpolate=True)

                pick = (None if entry.key in self.pool_only
                        else paying_factor(_components(run, SERVO_EXTRA), cost, allowed, band=LIST_BAND))
                if pick is None and fixed is None:  # the loop's pole in the move's pooled references
                    pick = self.pooled_pick(mv, run, cost, c)
                    if pick is None and len(self.pool[entry.key]) < POOL_CYCLES:
                        return self._row(entry, c, run, None, "pooling", "")
                if pick is None:
                    stopped.add(entry.key)
                    ctx.note(case, f"{mv.name}, cycle {c}: no factor predicted to pay"
                                   f" (within {1e3 * allowed:.1f} ms of the schedule's move +"
                                   " settle):"
                                   " the schedule" + (" and the factors kept" if fixed else "")
                                   + " from here on")
                else:
                    trial[entry.key] = pick
                    comp = pick.component
                    ctx.note(case, f"{mv.name}, cycle {c}: factor on {comp.hz:.2f} Hz,"
                                   f" zeta {comp.zeta:.3f} ("
                                   + ("the loop's transient" if comp.zeta >= SERVO_ZETA else
                                      "a mode that rings") + "): A1 "
                                   f"{pick.params.a1:.3f}, T2 {1e3 * pick.params.t2:.1f} ms"
                                   + ("" if pick.full else " (partial: what the time allows)")
                                   + f"; predicted residual {pick.predicted:.4f} against"
                                   f" {pick.without:.4f} m/s^2, time cost"
                                   f" {1e3 * pick.cost_s:+.1f} ms (the factors kept"
                                   " included, against the schedule)")
        else:  # a trial: the chosen factor over the schedule and the kept factors
            used = choice.params
            pair = used.shaper()
            run = cell.run(mv, _shaper(_times((current.amplitudes, current.times), (pair.amplitudes, pair.times))))
            m, ms = run.measures.residual_rms, run.measures.move_and_settle_s
            judged = self.at_pole.pop(entry.key, None)
            if judged is None:
                decision = keep_when_it_pays(entry, m, True, move_settle_s=ms)
            else:  # judged where the part lives: its measured amplitude at the pole (judge_at_pole)
                decision = self.judge_at_pole(entry, run, judged, mv.name, c)
            if decision == "again" and judged is not None:  # not resolved yet: the same trial again, windows pooled
                trial[entry.key], self.at_pole[entry.key] = choice, judged
                return self._row(entry, c, run, used, "trial", decision)
            action = "trial"
            if decision == "learn":  # paid: kept; the next cycle is the new reference
                kept[entry.key] = _times(fixed, (pair.amplitudes, pair.times))
            elif judged is not None:  # judge_at_pole's note says why
                stopped.add(entry.key)
            else:
                b = entry.base or {}
                pool = fixed is None and entry.key not in self.pool_only
                if pool:  # a factor from one noisy window that did not pay: the pooled references look again
                    self.pool_only.add(entry.key)
                else:
                    stopped.add(entry.key)
                ctx.note(case, f"{mv.name}, cycle {c}: the trial did not pay (residual"
                               f" {m:.4f} m/s^2, move + settle {ms:.3f} s against"
                               f" {b.get('residual_rms', math.nan):.4f},"
                               f" {b.get('move_settle_s', math.nan):.3f} s): "
                               + ("the schedule alone" if fixed is None else
                                  "the factors kept before it")
                               + ("; its references pooled from here on" if pool else ""))
        return self._row(entry, c, run, used, action, decision)

    def _row(self, entry: Any, c: int, run: Run, used: Any, action: str, decision: str) -> Row:
        f = self.kept.get(entry.key)
        entry.correction = None if f is None else (np.asarray(f[0]).tolist(), np.asarray(f[1]).tolist())
        entry.cycles += 1
        return row(self.case, c, run, a1=None if used is None else used.a1,
                   t2=None if used is None else used.t2, action=action, keep=decision,
                   factors=0 if f is None else _factor_count(f))

    def pooled_pick(self, mv: Any, run: Run, cost: Callable[[Any], float], c: int) -> Any:
        """A factor on the loop's pole found in the move's reference windows pooled (:mod:`~shaper_nodes.core.
        learning.list.loop_pole`): this reference's window joins the pool; the modes that ring are identified in the
        pooled mean, the loop's pole searched beside them, its amplitude measured with the pole fixed, and
        :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks a factor on it by the same time rule.
        None if no pole stands above the noise or no factor on it is predicted to pay."""
        from shaper_nodes.core.learning.list.loop_pole import pooled
        from shaper_nodes.core.learning.list.pole_rule import pole_pick
        from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S

        key = self.store.entry(mv.positions[0], mv.positions[-1], origin="schedule")[0].key
        ce = run.planned_end + run.measures.delay_s
        pool = self.pool.setdefault(key, [])
        pool.append((run.times, run.imu, ce))
        t, y = pooled(pool)
        found = pole_pick(t, y, cost, TIME_TOLERANCE_S, SERVO_ZETA, LIST_BAND)
        if found is None:
            return None
        loop, err = found.loop, found.error
        self.at_pole[key] = (list(found.poles), found.reference, found.response)
        self.ctx.note(self.case, f"{mv.name}, cycle {c}: the loop's pole in {len(pool)} reference windows pooled:"
                                 f" {loop.hz:.1f} Hz, zeta {loop.zeta:.3f}, amplitude {loop.amplitude:.4f}"
                                 f" +- {err:.4f} m/s^2 (with the pole fixed; beside {found.ringing} mode(s) that"
                                 " ring)")
        return found.choice

    def judge_at_pole(self, entry: Any, run: Run, judged: tuple[list[complex], tuple[float, float], Any], name: str,
                      c: int) -> str:
        """The keep rule for a factor chosen from pooled references: the trial pays when its measured response at
        the loop's pole (least squares with the reference's poles fixed, on the trial's windows pooled) is below the
        pooled reference's by :data:`~shaper_nodes.core.learning.list.loop_pole.LOWER` standard errors of the change
        (:func:`~shaper_nodes.core.learning.list.loop_pole.change_at_pole`) AND its move + settle time is within
        one 2 ms sample of the schedule's (the 1 s RMS cannot resolve the part: it is 0.0001-0.0002 m/s^2 of it, the
        noise's scatter per window 0.0002). Lower but not by that much: ``"again"``, the same trial once more (up to
        :data:`POOL_CYCLES` windows); otherwise ``"base"``."""
        from shaper_nodes.core.learning.list.loop_pole import pooled
        from shaper_nodes.core.learning.list.pole_rule import judge_pole
        from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S

        poles, ref, response = judged
        pool = self.trial_pool.setdefault(entry.key, [])
        pool.append((run.times, run.imu, run.planned_end + run.measures.delay_s))
        t, y = pooled(pool)
        ms = run.measures.move_and_settle_s
        base = entry.base or {}
        in_time = ms <= base.get("move_settle_s", math.inf) + TIME_TOLERANCE_S
        decision, trial, change = judge_pole(t, y, tuple(poles), ref, len(pool), in_time, POOL_CYCLES, response)
        paid, again = decision == "learn", decision == "again"
        self.ctx.note(self.case, f"{name}, cycle {c}: amplitude at the loop's pole {trial[0]:.4f} +- {trial[1]:.4f}"
                                 f" m/s^2 ({len(pool)} trial window(s) pooled) against the pooled reference's"
                                 f" {ref[0]:.4f} +- {ref[1]:.4f}, lower by {change:.2f} standard errors of the"
                                 f" change; move + settle {ms:.3f} s against"
                                 f" {base.get('move_settle_s', math.nan):.3f} s: "
                                 + ("paid, kept" if paid else "lower, not resolved: tried again" if again
                                    else "did not pay"))
        if paid:
            entry.best = {"residual_rms": run.measures.residual_rms, "move_settle_s": ms}
        return "learn" if paid else "again" if again else "base"


@register("scheduled_list_factor")
def scheduled_list_factor(ctx: Context, cycles: int) -> list[Row]:
    """Per move, factors convolved with the scheduled shaper, each chosen to pay before it is tried and kept only
    when it pays (module docstring): a reference cycle (the schedule, then the schedule with the factors kept so
    far) identifies the components of the residual (the modes that ring, the loop's damped poles);
    :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks the two-impulse factor (T2 within
    LIST_BAND of a component) with the least predicted residual among those whose time cost, predicted from the
    shaped command, keeps the move + settle time within one 2 ms sample of the schedule's; the next cycle tries
    it, and :func:`~shaper_nodes.core.learning.moves.keep_when_it_pays` keeps it only if the measured cycle pays
    (a lower residual than the reference AND a move + settle time no longer than the schedule's). A move stops
    at the first trial that does not pay, or when no factor is predicted to pay."""
    from sim_plant_node.arm.task import cycle_moves

    pay = PayingFactors(ctx, "scheduled_list_factor")
    cell, rows = Cell(ctx), []
    for c in range(1, cycles + 1):
        rows += [pay.step(cell, mv, c) for mv in cycle_moves()]
    _save(ctx, "scheduled_list_factor", pay.store)
    return rows
