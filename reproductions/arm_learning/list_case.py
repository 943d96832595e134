"""The ``list`` case: LIST per move with no calibration, a factor on each mode that rings in turn."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from reproductions.arm_learning.factors import LIST_BAND, _factor_count, _times
from reproductions.arm_learning.runs import Cell, Context, Row, Run, _save, register, row
from reproductions.residual_split import SERVO_ZETA  # more damped than this: the position loop's transient

#: the ``list`` case learns a factor for at most this many trials (or until LIST holds, or until a trial does not
#: pay), then freezes it at its best kept trial and starts on the next mode that rings
FACTOR_CYCLES = 3


def _ringing(run: Run, covered: list[float]) -> list[Any]:
    """The arm modes identified in a run's residual that no factor covers (5 %), lowest first (up to three);
    when none rings (damped below SERVO_ZETA), the lowest uncovered damped one, looked for from the commanded end
    too (the position loop's transient, nearly gone 0.1 s later: a factor on it is tried, and kept only if it
    pays)."""
    from shaper_nodes.core.identification import IdentificationError, identify

    def found(skip: float) -> list[Any]:
        sel = run.times > run.planned_end + run.measures.delay_s + skip
        try:
            fits = identify(run.times[sel], run.imu[sel], max_modes=3)
        except IdentificationError:
            return []
        return [f for f in fits if f.hz > 2.0 and all(abs(f.hz / h - 1) > 0.05 for h in covered)]

    fits = found(0.1)  # the modes that ring: after the loop's first 0.1 s
    ringing = sorted((f for f in fits if f.zeta < SERVO_ZETA), key=lambda f: f.omega)
    if ringing:
        return ringing
    # the loop's transient has decayed to a few % 0.1 s after the commanded end: look from the end itself
    damped = sorted((f for f in fits + found(0.0) if f.zeta >= SERVO_ZETA), key=lambda f: f.omega)
    return damped[:1]


@register("list")
def list_alone(ctx: Context, cycles: int) -> list[Row]:
    """LIST per move with no calibration (module docstring): a reference cycle identifies the modes that ring;
    LIST learns a factor on the lowest, within LIST_BAND of it, over ZV factors on the others; the stage is kept
    only when it pays (:func:`~shaper_nodes.core.learning.moves.keep_when_it_pays` against the cycle without it:
    a lower residual, and a move + settle time no longer than the move's unshaped cycle), frozen at its best
    kept trial, and a new reference looks for modes still ringing."""
    from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
    from shaper_nodes.core.learning.moves import MoveStore, keep_when_it_pays
    from shaper_nodes.core.shaping import Shaper, design
    from sim_plant_node.arm.task import cycle_moves

    cell, store, rows = Cell(ctx), MoveStore(), []
    frozen: dict[str, tuple[Any, Any]] = {}  # the kept factors' product
    others: dict[str, tuple[Any, Any] | None] = {}  # the present stage's ZV factors on its higher modes
    covered: dict[str, list[float]] = {}
    budget: dict[str, float] = {}  # the move's unshaped move + settle time, s: no kept state is slower
    learning: dict[str, int] = {}  # trials the present stage has run
    kept: dict[str, Any] = {}  # the present stage's best kept trial (parameters), None if none paid yet
    for c in range(1, cycles + 1):
        for mv in cycle_moves():
            entry, _ = store.entry(mv.positions[0], mv.positions[-1], origin="identified")
            fixed = frozen.get(entry.key)
            learner = entry.learner()
            decision = ""
            if learner is None or learner.params is None:  # a reference cycle: the kept factors only
                run = cell.run(mv, None if fixed is None else Shaper(fixed[0], fixed[1], "custom"))
                budget.setdefault(entry.key, run.measures.move_and_settle_s)
                keep_when_it_pays(entry, run.measures.residual_rms, False, move_settle_s=budget[entry.key])
                modes = _ringing(run, covered.setdefault(entry.key, []))
                action = "reference"
                if modes:
                    lowest = modes[0]
                    zv = ListParams.from_mode(lowest.mode)
                    lo, hi = ListConfig().a1_bounds  # a heavily damped pole's ZV may ask for more than A1 allows
                    start = ListParams(min(max(zv.a1, lo), hi), zv.t2)
                    rest = design("zv", [f.mode for f in modes[1:]]) if len(modes) > 1 else None
                    others[entry.key] = None if rest is None else (rest.amplitudes, rest.times)
                    ahead = _times(fixed, others[entry.key])
                    learner = ListLearner(ListConfig(window_delay=(0.0 if ahead is None else float(ahead[1][-1]))
                                                     + 2.2 * math.pi / lowest.omega,
                                                     t2_bounds=start.t2_band(LIST_BAND)), start)
                    learner.update(run.times, run.imu, run.planned_end, run.end, None)
                    covered[entry.key] += [f.hz for f in modes]
                    learning[entry.key], kept[entry.key] = 0, None
                    ctx.note("list", f"{mv.name}, cycle {c}: LIST from {lowest.hz:.2f} Hz, zeta {lowest.zeta:.3f}"
                                     + (" (the lowest mode that rings)" if lowest.zeta < SERVO_ZETA else
                                        " (no mode rings: the lowest damped one, the loop's transient)")
                             + (" over ZV on " + ", ".join(f"{f.hz:.2f}" for f in modes[1:]) + " Hz"
                                if len(modes) > 1 else ""))
                used = None
            else:
                used = learner.params
                pair = used.shaper()
                a, t = _times(_times(fixed, others.get(entry.key)), (pair.amplitudes, pair.times))  # type: ignore[misc]
                run = cell.run(mv, Shaper(a, t, "custom"))
                decision = keep_when_it_pays(entry, run.measures.residual_rms, True,
                                             move_settle_s=run.measures.move_and_settle_s)
                if decision == "learn" and entry.best == {"residual_rms": run.measures.residual_rms,
                                                          "move_settle_s": run.measures.move_and_settle_s}:
                    kept[entry.key] = used  # paid, and the best so far
                action = learner.update(run.times, run.imu, run.planned_end, run.end, used).action
                learning[entry.key] += 1
                done = learner.holding or learner.phase == "hold" or learning[entry.key] >= FACTOR_CYCLES
                if decision != "learn" or done:
                    best = kept.pop(entry.key, None)
                    if best is None:  # no trial paid: the stage is dropped, its modes stay covered
                        ctx.note("list", f"{mv.name}, cycle {c}: no trial of the factors from"
                                         f" {covered[entry.key][-1]:.2f} Hz paid: dropped")
                    else:
                        covered[entry.key].append(1.0 / (2.0 * best.t2))  # where it ended, too
                        bp = best.shaper()
                        frozen[entry.key] = _times(_times(fixed, others.get(entry.key)),  # type: ignore[assignment]
                                                   (bp.amplitudes, bp.times))
                    learner = None
            entry.list_state = None if learner is None else learner.to_dict()
            entry.cycles += 1
            f = frozen.get(entry.key)
            entry.correction = None if f is None else (np.asarray(f[0]).tolist(), np.asarray(f[1]).tolist())
            rows.append(row("list", c, run, a1=None if used is None else used.a1,
                            t2=None if used is None else used.t2, action=action, keep=decision,
                            factors=0 if f is None else _factor_count(f)))
    _save(ctx, "list", store)
    return rows
