"""The cases of the schedule: unshaped, fixed, scheduled, the rigid arm, and ``scheduled_list`` (LIST retunes
the schedule's lowest-mode factor per move)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from reproductions.arm_learning.runs import CaseFn, Cell, Context, Row, _save, register, row


def _fixed_case(name: str, shaper_for: Callable[[Any], Any]) -> CaseFn:
    def case(ctx: Context, cycles: int) -> list[Row]:
        from sim_plant_node.arm.task import cycle_moves

        cell, rows = Cell(ctx), []
        for c in range(1, cycles + 1):
            rows += [row(name, c, cell.run(mv, shaper_for(mv))) for mv in cycle_moves()]
        return rows
    return case


@register("unshaped")
def unshaped(ctx: Context, cycles: int) -> list[Row]:
    return _fixed_case("unshaped", lambda mv: None)(ctx, cycles)


@register("fixed")
def fixed(ctx: Context, cycles: int) -> list[Row]:
    shaper = ctx.fallback()
    return _fixed_case("fixed", lambda mv: shaper)(ctx, cycles)


@register("scheduled")
def scheduled(ctx: Context, cycles: int) -> list[Row]:
    sched = ctx.schedule()
    return _fixed_case("scheduled", lambda mv: sched(mv.positions[-1]))(ctx, cycles)


@register("rigid")
def rigid(ctx: Context, cycles: int) -> list[Row]:
    """One cycle unshaped, fixed and scheduled on the arm with its flexibility removed
    (:func:`~sim_plant_node.arm.dynamics.rigid_model`): what the position loop alone leaves at the flange
    (rows ``shaping``: unshaped, fixed, scheduled; not a learning case, one cycle whatever ``cycles``)."""
    from sim_plant_node.arm.dynamics import rigid_model
    from sim_plant_node.arm.task import cycle_moves

    sched, fallback = ctx.schedule(), ctx.fallback()
    rows = []
    for name, shaper_for in (("unshaped", lambda mv: None), ("fixed", lambda mv: fallback),
                             ("scheduled", lambda mv: sched(mv.positions[-1]))):
        cell = Cell(ctx, rigid_model())
        rows += [row("rigid", 1, cell.run(mv, shaper_for(mv)), shaping=name) for mv in cycle_moves()]
    return rows


#: cases shown only in the physics section (not learning over cycles)
SIDE_CASES = ("rigid", "tradeoff", "servo_cost")


def _split_lowest(shaper: Any) -> tuple[Any, Any]:
    """The scheduled shaper's lowest mode and the shaper of its other modes (same family)."""
    from shaper_nodes.core.shaping import design

    modes = sorted(shaper.modes, key=lambda m: m.omega)
    return modes[0], (design("zv", modes[1:]) if len(modes) > 1 else None)


def _with_pair(others: Any, params: Any) -> Any:
    from shaper_nodes.core.shaping import Shaper
    from shaper_nodes.core.shaping.families import convolve

    pair = params.shaper()
    if others is None:
        return pair
    a, t = convolve((others.amplitudes, others.times), (pair.amplitudes, pair.times))
    return Shaper(a, t, "custom", tuple(others.modes) + tuple(pair.modes))


def _learner(entry: Any) -> Any:
    """The move's saved LIST learner (every learning case saves one at the move's first cycle)."""
    learner = entry.learner()
    if learner is None:
        raise RuntimeError(f"move {entry.name}: no LIST state saved")
    return learner


@register("scheduled_list")
def scheduled_list(ctx: Context, cycles: int) -> list[Row]:
    """Per move, LIST retunes the schedule's lowest-mode factor (module docstring); a trial worse than the best
    measured (the schedule itself at first) in residual or in move + settle time stops the learning at that best."""
    from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
    from shaper_nodes.core.learning.moves import MoveStore
    from sim_plant_node.arm.task import cycle_moves

    sched, cell, store, rows = ctx.schedule(), Cell(ctx), MoveStore(), []
    for c in range(1, cycles + 1):
        for mv in cycle_moves():
            entry, new = store.entry(mv.positions[0], mv.positions[-1], origin="schedule")
            base = sched(mv.positions[-1])
            lowest, others = _split_lowest(base)
            start = ListParams.from_mode(lowest)
            if new:
                cfg = ListConfig(t2_bounds=(0.9 * start.t2, start.t2),
                                 a1_bounds=(max(0.5, start.a1 - 0.1), min(0.95, start.a1 + 0.1)),
                                 window_delay=float(base.times[-1]) + 0.1)
                learner = ListLearner(cfg, start)
                used = None  # the reference: the schedule without its lowest-mode factor
                shaper = others
            else:
                learner = _learner(entry)
                used = learner.params
                if entry.extra.get("kept") is not None:  # learning stopped: the best pair measured
                    used = ListParams(*entry.extra["kept"])
                shaper = _with_pair(others, used)
            run = cell.run(mv, shaper)
            m = {"residual_rms": run.measures.residual_rms, "move_settle_s": run.measures.move_and_settle_s}
            if entry.extra.get("kept") is not None:
                up_action = "kept"
            else:
                up_action = learner.update(run.times, run.imu, run.planned_end, run.end, used).action
                if used is not None and entry.base is None:  # the start is the schedule itself: its measures
                    entry.base = entry.best = m
                    entry.extra["best_pair"] = (used.a1, used.t2)
                elif used is not None and entry.best is not None:
                    best = entry.best
                    if m["residual_rms"] <= best["residual_rms"] and m["move_settle_s"] <= best["move_settle_s"]:
                        entry.best, entry.extra["best_pair"] = m, (used.a1, used.t2)
                    else:  # kept only when it pays: a worse trial stops learning at the best pair measured
                        entry.extra["kept"] = entry.extra["best_pair"]
            entry.list_state, entry.cycles = learner.to_dict(), entry.cycles + 1
            pair = entry.extra.get("kept") or entry.extra.get("best_pair")
            if pair is not None:
                sh = ListParams(*pair).shaper()
                entry.correction = (sh.amplitudes.tolist(), sh.times.tolist())
            rows.append(row("scheduled_list", c, run, a1=None if used is None else used.a1,
                            t2=None if used is None else used.t2, action=up_action))
    _save(ctx, "scheduled_list", store)
    return rows
