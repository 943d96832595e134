"""The side cases that measure what a factor costs: on a mode that rings (``tradeoff``) and on the loop's
transient (``servo_cost``)."""

from __future__ import annotations

from typing import Any

from reproductions.arm_learning.factors import JOINT_TOLERANCE, LIST_BAND, SERVO_EXTRA, _components, _times
from reproductions.arm_learning.runs import RATE, Cell, Context, Row, register, row
from reproductions.residual_split import SERVO_ZETA  # more damped than this: the position loop's transient

#: the time the ``tradeoff`` case lets a single factor cost, s (one 2 ms sample, then more)
TRADEOFF_BUDGETS = (0.0021, 0.0061, 0.0121, 0.0241, 0.0481)


@register("tradeoff")
def tradeoff(ctx: Context, cycles: int) -> list[Row]:
    """What a factor on a mode that rings costs (one cycle whatever ``cycles``; not a learning case): per move, the
    schedule; the schedule with the loop's factor (as ``scheduled_list_factor`` chooses it, if any) and the
    zero-vibration pair on the strongest mode that rings in the schedule's residual (``shaping`` ``ringing_zv``);
    and, for each time budget of :data:`TRADEOFF_BUDGETS`, the one factor
    :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks within it (``budget_<ms>``). Each variant
    runs on its own arm through the whole cycle; ``t2`` the pair's T2 (s), ``predicted_cost_s`` its time cost
    predicted from the command."""
    from shaper_nodes.core.learning.list import ListParams
    from shaper_nodes.core.learning.list.payback import paying_factor, time_cost
    from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S
    from shaper_nodes.core.shaping import Mode, Shaper
    from sim_plant_node.arm.task import cycle_moves

    names = ["scheduled", "ringing_zv"] + [f"budget_{1e3 * b:.0f}" for b in TRADEOFF_BUDGETS]
    sched, cells, rows = ctx.schedule(), {n: Cell(ctx) for n in names}, []
    for mv in cycle_moves():
        base = sched(mv.positions[-1])
        run = cells["scheduled"].run(mv, base)
        rows.append(row("tradeoff", 1, run, shaping="scheduled"))
        comps = _components(run)

        def cost(p: Any, mv: Any = mv, base: Any = base) -> float:
            return time_cost(mv.times, mv.positions, mv.velocities, base, p, RATE, JOINT_TOLERANCE)

        def with_factors(*factors: Any, base: Any = base) -> Any:
            imp = (base.amplitudes, base.times)
            for f in factors:
                sh = f.shaper()
                imp = _times(imp, (sh.amplitudes, sh.times))  # type: ignore[assignment]
            return Shaper(imp[0], imp[1], "custom")

        loop = paying_factor([c for c in comps if c.zeta >= SERVO_ZETA], cost, TIME_TOLERANCE_S, band=LIST_BAND)
        ringing = sorted((c for c in comps if c.zeta < SERVO_ZETA), key=lambda c: -c.amplitude)
        if ringing:
            zv = ListParams.from_mode(Mode(ringing[0].omega, ringing[0].zeta))
            shaper = with_factors(*([loop.params] if loop else []), zv)
            rows.append(row("tradeoff", 1, cells["ringing_zv"].run(mv, shaper), shaping="ringing_zv", t2=zv.t2,
                            hz=ringing[0].hz, predicted_cost_s=cost(zv)))
        else:
            cells["ringing_zv"].run(mv, base)
        for budget, name in zip(TRADEOFF_BUDGETS, names[2:], strict=True):
            pick = paying_factor(comps, cost, budget, band=LIST_BAND)
            if pick is None:
                cells[name].run(mv, base)
                continue
            rows.append(row("tradeoff", 1, cells[name].run(mv, with_factors(pick.params)), shaping=name,
                            t2=pick.params.t2, a1=pick.params.a1, hz=pick.component.hz,
                            predicted_cost_s=pick.cost_s, budget_s=budget))
    return rows


@register("servo_cost")
def servo_cost(ctx: Context, cycles: int) -> list[Row]:
    """What a factor on the loop's transient costs (one cycle whatever ``cycles``; not a learning case): per move,
    the schedule; the zero-vibration pair on the strongest damped component identified in its residual (damping >=
    SERVO_ZETA, as ``scheduled_list_factor`` identifies them; ``shaping`` ``servo_zv``) over it; and the pair on that
    component that :func:`~shaper_nodes.core.learning.list.payback.paying_factor` picks within one 2 ms sample of
    move + settle (``servo_within``). Each variant runs on its own arm through the whole cycle; ``hz``, ``zeta`` the
    component's, ``t2``, ``a1`` the pair's, ``predicted_cost_s`` its time cost predicted from the command."""
    from shaper_nodes.core.learning.list import ListParams
    from shaper_nodes.core.learning.list.payback import component_energy, paying_factor, time_cost
    from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S
    from shaper_nodes.core.shaping import Mode, Shaper
    from shaper_nodes.core.shaping.families import convolve
    from sim_plant_node.arm.task import cycle_moves

    names = ("scheduled", "servo_zv", "servo_within")
    sched, cells, rows = ctx.schedule(), {n: Cell(ctx) for n in names}, []
    for mv in cycle_moves():
        base = sched(mv.positions[-1])
        run = cells["scheduled"].run(mv, base)
        rows.append(row("servo_cost", 1, run, shaping="scheduled"))
        damped = [c for c in _components(run, SERVO_EXTRA) if c.zeta >= SERVO_ZETA]
        if not damped:
            for n in names[1:]:
                cells[n].run(mv, base)
            continue
        comp = max(damped, key=component_energy)

        def cost(p: Any, mv: Any = mv, base: Any = base) -> float:
            return time_cost(mv.times, mv.positions, mv.velocities, base, p, RATE, JOINT_TOLERANCE, interpolate=True)

        def over(p: Any, base: Any = base) -> Any:
            sh = p.shaper()
            a, t = convolve((base.amplitudes, base.times), (sh.amplitudes, sh.times))
            return Shaper(a, t, "custom")

        zv = ListParams.from_mode(Mode(comp.omega, comp.zeta))
        within = paying_factor([comp], cost, TIME_TOLERANCE_S, band=LIST_BAND)
        for name, params in (("servo_zv", zv), ("servo_within", None if within is None else within.params)):
            if params is None:
                cells[name].run(mv, base)
                continue
            rows.append(row("servo_cost", 1, cells[name].run(mv, over(params)), shaping=name, hz=comp.hz,
                            zeta=comp.zeta, t2=params.t2, a1=params.a1, predicted_cost_s=cost(params)))
    return rows
