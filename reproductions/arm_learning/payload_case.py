"""The ``payload`` case: the payload changed after :data:`~reproductions.arm_learning.runs.PAYLOAD_AT`
cycles, a drift watch per move, the moves re-learned on its warning."""

from __future__ import annotations

import math
from typing import Any

from reproductions.arm_learning.runs import HEAVY, PAYLOAD_AT, Cell, Context, Row, _save, register, row
from reproductions.residual_split import SERVO_ZETA  # more damped than this: the position loop's transient


@register("payload")
def payload(ctx: Context, cycles: int) -> list[Row]:
    """The schedule; 2 -> 4.5 kg after PAYLOAD_AT cycles; drift watch per move; re-learned on its warning."""
    from shaper_nodes.core.identification import IdentificationError, identify
    from shaper_nodes.core.identification.drift import DriftWatch, check_mode
    from shaper_nodes.core.learning.moves import MoveStore
    from shaper_nodes.core.shaping import design
    from sim_plant_node.arm.task import cycle_moves

    sched, cell, store, rows = ctx.schedule(), Cell(ctx), MoveStore(), []
    watches: dict[str, DriftWatch] = {}
    own: dict[str, Any] = {}  # per move: the shaper re-learned from the drift's modes
    for c in range(1, cycles + 1):
        if c == PAYLOAD_AT + 1:
            cell.set_payload(HEAVY)
            ctx.note("payload", f"cycle {c}: payload 2 -> {HEAVY} kg")
        for mv in cycle_moves():
            entry, _ = store.entry(mv.positions[0], mv.positions[-1], origin="schedule")
            shaper = own.get(entry.key) or sched(mv.positions[-1])
            run = cell.run(mv, shaper)
            sel = run.times > run.planned_end + run.measures.delay_s + 0.1
            try:
                fits = [f for f in identify(run.times[sel], run.imu[sel], max_modes=3)
                        if 2.0 < f.hz < 40.0 and f.zeta < SERVO_ZETA]
            except IdentificationError:
                fits = []
            watch = watches.setdefault(entry.key, DriftWatch(confirm=2))
            design_hz = [m.omega / (2 * math.pi) for m in shaper.modes]
            if fits:
                strongest = max(fits, key=lambda f: f.amplitude)
                warn = watch.update(check_mode(shaper.amplitudes, shaper.times, design_hz, strongest, 0.05))
            else:
                warn = watch.quiet()
            if warn:
                # the modes found now, and those of the move's earlier re-learned shaper that none of them is near
                # (a weak mode the noise hid this time stays covered)
                new = [f.mode for f in fits]
                kept = [m for m in (own[entry.key].modes if entry.key in own else ())
                        if all(abs(m.omega / n.omega - 1.0) > 0.05 for n in new)]
                own[entry.key] = design("zv", sorted(new + kept, key=lambda m: m.omega))
                entry.relearn("identified")
                said = watch.last.describe() if watch.last else ""
                ctx.note("payload", f"cycle {c}, {mv.name}: drift warning ({said});"
                                    " re-learned: ZV on "
                                    + ", ".join(f"{m.omega / (2 * math.pi):.2f}" for m in own[entry.key].modes) + " Hz")
                watch.reset()
            entry.cycles += 1
            rows.append(row("payload", c, run, payload_kg=HEAVY if c > PAYLOAD_AT else 2.0, warning=warn))
    _save(ctx, "payload", store)
    return rows
