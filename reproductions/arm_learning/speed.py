"""The speed-up cases: ``speedup`` over the schedule and ``scheduled_list_speedup`` over LIST's paying
factors (opt-in)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from reproductions.arm_learning.factors import _factor_count
from reproductions.arm_learning.paying import PayingFactors
from reproductions.arm_learning.runs import UR5E_MAX_VELOCITY, Cell, Context, Row, Run, _save, register, row


def speed_violations(run: Any, flange: bool = True, first: list[str] | None = None) -> list[str]:
    """What a speed-up trial broke, in the learner's words: the flange's residual peak beyond the tolerance (when
    judged at the flange), after ``first`` (an estimate's judgement), then the torque and the velocity limits."""
    from sim_plant_node.arm.metrics import SETTLE_TOLERANCE

    why = list(first or [])
    if flange and run.measures.peak_mm > 1e3 * SETTLE_TOLERANCE:
        why.insert(0, f"residual {run.measures.peak_mm:.4f} mm > {1e3 * SETTLE_TOLERANCE:g} mm")
    if run.torque_ratio > 1.0:
        why.append(f"torque {100 * run.torque_ratio:.0f} % of the limit")
    if run.velocity_ratio > 1.0:
        why.append(f"velocity {100 * run.velocity_ratio:.0f} % of 180 deg/s")
    return why


@register("speedup")
def speedup(ctx: Context, cycles: int) -> list[Row]:
    """The schedule with a time-scaling factor learned per move (module docstring)."""
    from shaper_nodes.core.learning.moves import MoveStore
    from shaper_nodes.core.learning.speed import SpeedLearner, SpeedSettings, limit_ceiling
    from sim_plant_node.arm.task import cycle_moves

    sched, cell, store, rows = ctx.schedule(), Cell(ctx), MoveStore(), []
    for c in range(1, cycles + 1):
        for mv in cycle_moves():
            entry, new = store.entry(mv.positions[0], mv.positions[-1], origin="schedule")
            if new:
                ceiling = limit_ceiling(mv.velocities, mv.accelerations, [UR5E_MAX_VELOCITY] * 6, [np.inf] * 6)
                sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=ceiling))
            else:
                sp = entry.speed() or SpeedLearner()
            factor = sp.factor
            run = cell.run(mv, sched(mv.positions[-1]), factor)
            why = speed_violations(run)
            sp.update(not why, "; ".join(why))
            entry.speed_state, entry.cycles = sp.to_dict(), entry.cycles + 1
            rows.append(row("speedup", c, run, factor, violation="; ".join(why)))
    _save(ctx, "speedup", store)
    return rows


#: cases run only when named with ``--cases`` (not in the default list: docs/results/arm_learning.md stays as it was)
OPTIONAL_CASES = ("scheduled_list_speedup",)


def node_speed_estimate(run: Run, shaper: Any, lowest: Any) -> tuple[float, float, float]:
    """What the learner node's ``speed_moves`` mode judges a move by (nodes/learner_speed.py): the peak of the tool
    IMU's deviation from its mean from the commanded motion's end (the scaled plan's end plus the shaper's
    duration) + 0.1 s to 1 s after it, m/s^2; the same converted to the flange at the schedule's lowest mode
    ``lowest`` (x = a / (2 pi f)^2), mm; and the tolerance 0.05 mm converted there, m/s^2."""
    from shaper_nodes.core.learning.speed import acceleration_tolerance
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW, SERVO_TRANSIENT, SETTLE_TOLERANCE, window_residual

    end = run.planned_end + float(shaper.times[-1])
    peak = window_residual(run.times, run.imu, end + SERVO_TRANSIENT, end + RESIDUAL_WINDOW).peak
    f = lowest.omega / (2.0 * math.pi)
    return peak, 1e3 * peak / (2.0 * math.pi * f) ** 2, acceleration_tolerance(SETTLE_TOLERANCE, f)


@register("scheduled_list_speedup")
def scheduled_list_speedup(ctx: Context, cycles: int) -> list[Row]:
    """Scheduled + LIST per move + speed-up, learned in turn as the learner nodes do it when both run
    (docs/guide/learning.md, tests/test_learning_speed_list.py): first LIST's paying factors per move over the
    schedule (:class:`PayingFactors`, the rule of ``scheduled_list_factor``) at the planned speed, the speed
    learner held; once every move's LIST has stopped (its factors kept, nothing more predicted or measured to
    pay: LIST held), from the next cycle on each move's time-scaling factor is learned over the schedule and
    its kept factors (the ``speedup`` case's :class:`~shaper_nodes.core.learning.speed.SpeedLearner`, step
    0.1, the ceiling from the UR5e's 180 deg/s). A cycle is good when the torque and velocity limits hold and
    the settled residual is within 0.05 mm: noise-free by the flange's true peak (as ``speedup``); with
    ``--noise`` by the node's accelerometer estimate (:func:`node_speed_estimate`, the robot's measure).
    Extra row fields: phase (list, speed), imu_peak and tolerance (m/s^2), estimate_mm, judged_by, violation."""
    from shaper_nodes.core.learning.speed import SpeedLearner, SpeedSettings, limit_ceiling
    from sim_plant_node.arm.task import cycle_moves

    name = "scheduled_list_speedup"
    pay = PayingFactors(ctx, name)
    cell, rows, speeding = Cell(ctx), [], False
    moves = cycle_moves()
    for c in range(1, cycles + 1):
        if not speeding and len(pay.stopped) == len(moves) and not pay.trial:
            speeding = True
            ctx.note(name, f"cycle {c}: every move's LIST has stopped: LIST held, the speed-up learns from here on")
        for mv in moves:
            if not speeding:
                rows.append({**pay.step(cell, mv, c), "phase": "list"})
                continue
            entry, _ = pay.store.entry(mv.positions[0], mv.positions[-1], origin="schedule")
            sp = entry.speed()
            if sp is None:
                ceiling = limit_ceiling(mv.velocities, mv.accelerations, [UR5E_MAX_VELOCITY] * 6, [np.inf] * 6)
                sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=ceiling))
            factor, shaper = sp.factor, pay.shaper(mv)
            run = cell.run(mv, shaper, factor)
            lowest = min(pay.sched(mv.positions[-1]).modes, key=lambda m: m.omega)
            peak, estimate, tol = node_speed_estimate(run, shaper, lowest)
            judged = "estimate" if ctx.noise > 0 else "flange"
            why = [f"IMU peak {peak:.4f} m/s^2 > {tol:.4f} m/s^2 ({estimate:.4f} mm estimated)"] if (
                judged == "estimate" and peak > tol) else []
            why = speed_violations(run, flange=judged == "flange", first=why)
            sp.update(not why, "; ".join(why))
            entry.speed_state, entry.cycles = sp.to_dict(), entry.cycles + 1
            f = pay.kept.get(entry.key)
            rows.append(row(name, c, run, factor, phase="speed", imu_peak=peak, tolerance=tol, estimate_mm=estimate,
                            judged_by=judged, violation="; ".join(why), factors=0 if f is None else _factor_count(f)))
    _save(ctx, name, pay.store)
    return rows
