"""The arm demo's ``payload`` case: the payload changed mid-run, the drift watch's warning, the moves relearned.

Opt-in (``./run demo --cases none,payload --calibration DIR``). The case runs as ``scheduled_list_moves``
does (the calibrated schedule, every move marked as its own cycle on ``/cycle_events``, the learner's LIST
per move over the scheduler), with the identifier's drift watch rating every move's residual against the
shaper that move ran with (the identifier's ``watch.scheduler``: the scheduler's ``~/shaper_at`` for the
move, :mod:`shaper_nodes.nodes.identifier_moves`; without it the watch rates against the shaper node's
active shaper, which the schedule does not change, and never warns). Before cycle ``--payload-cycle`` + 1
of the case, the client sets the sim plant's ``arm.payload_mass`` from 2 kg to ``--payload-mass`` (4.5 kg)
through the plant's parameter service (``ros2 param set /sim_plant arm.payload_mass 4.5`` does the same);
the case runs ``--list-cycles`` cycles in all. At the watch's first WARN (``identifier: drift`` on
``/diagnostics``, after ``watch.confirm`` moves in a row outside their shaper's working band) the learner
relearns every move from the current schedule (nodes/learner_drift.py, nodes/learner_moves.py).
With ``--payload-learner mrilc`` the case runs as ``scheduled_mrilc_moves`` does instead (MRILC per move over the
schedule; at the WARN every move's correction is dropped, nodes/learner_moves_mrilc.py); with ``--payload-told`` too,
the client tells the learner the payload at the change (its ``mrilc_moves.payload_mass``, through its parameter
service, as a robot is told its payload), so that the relearn builds the moves' operators for it.

:class:`PayloadWatch` is the client's side: the payload change, the drift statuses (which cycle and move,
what mode) and the learner's relearn lines on ``/rosout``; :meth:`PayloadWatch.table` is the case's table,
per cycle and move: residual RMS (m/s^2), peak (mm: the flange's largest distance from where it comes to
rest in the residual window), move + settle time (s), the drift statuses of that move, and whether the move
is within the tolerance (its peak within 0.05 mm, :data:`~sim_plant_node.arm.metrics.SETTLE_TOLERANCE`).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

CASE = "payload"
#: the payload the arm carries before the change, kg (the sim plant's default arm.payload_mass)
LIGHT = 2.0
#: the drift watch's status on /diagnostics (the identifier's; the learner's list.drift_status)
DRIFT = "identifier: drift"
WARN_LEVEL = 1  # diagnostic_msgs/DiagnosticStatus.WARN


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The case's options."""
    p.add_argument("--payload-cycle", type=int, default=3,
                   help=f"the {CASE} case: cycles run with {LIGHT:g} kg before the payload changes (default 3;"
                   " the case runs --list-cycles cycles in all)")
    p.add_argument("--payload-mass", type=float, default=4.5,
                   help=f"the {CASE} case: the payload after the change, kg (default 4.5)")
    p.add_argument("--payload-learner", choices=("list", "mrilc"), default="list",
                   help=f"the {CASE} case's learner: LIST per move (default) or MRILC per move")
    p.add_argument("--payload-told", action="store_true",
                   help=f"the {CASE} case with --payload-learner mrilc: tell the learner the payload at the change"
                   " (mrilc_moves.payload_mass), so that it relearns on the operator for it")


def check_args(args: argparse.Namespace, cases: list[str]) -> str:
    """One line naming what is wrong with the case's options ("" if nothing, or the case is not run)."""
    if CASE not in cases:
        return ""
    if not 1 <= args.payload_cycle < args.list_cycles:
        return (f"--payload-cycle must be at least 1 and below --list-cycles ({args.list_cycles}), got"
                f" {args.payload_cycle}")
    if not (math.isfinite(args.payload_mass) and args.payload_mass > 0.0):
        return f"--payload-mass must be a finite mass > 0 kg, got {args.payload_mass}"
    if getattr(args, "payload_told", False) and getattr(args, "payload_learner", "list") != "mrilc":
        return "--payload-told goes with --payload-learner mrilc"
    return ""


def identifier_params(cases: list[str], per_move: tuple[str, ...] = (CASE,)) -> dict[str, Any]:
    """The identifier's parameters when any of ``per_move`` runs (the cases whose learners relearn at a drift
    warning): its drift watch rates each move against the scheduler's shaper for it. Without it the watch rates
    against the shaper node's active shaper, which the schedule does not change: it may warn of what the schedule
    shapes (a noise-free run warned of the position loop at 31.6 Hz), and a learner would relearn at it."""
    return {"watch.scheduler": "/scheduler"} if any(c in per_move for c in cases) else {}


@dataclass
class Drift:
    """One drift status of the identifier: the cycle it rated, its level, its message, the mode (Hz)."""

    cycle: int
    level: int
    message: str
    mode_hz: float


def _label(d: Drift) -> str:
    """A drift status in a table cell: WARN (the status: some move's mode out of its band), else whether this
    move's mode was inside or outside its shaper's band, outside but not drift (baseline: present since the
    move's first cycles; above: far above every design mode), or not rated (no sharp mode: the noise floor); the
    rated mode, Hz."""
    aside = d.message.endswith(": not drift")
    what = ("WARN" if d.level == WARN_LEVEL else "baseline" if aside and "first cycles" in d.message
            else "above" if aside else "outside" if " is outside " in d.message
            else "inside" if " is inside " in d.message else "no mode" if d.level == 0 else f"level {d.level}")
    return what + (f" {d.mode_hz:.3f} Hz" if math.isfinite(d.mode_hz) else "")


class PayloadWatch:
    """The client's side of the case (module docstring).

    Parameters
    ----------
    conductor : Conductor
        The demo's client node (its ``set_plant`` and ``spin_until``).
    args : argparse.Namespace
        The demo's options (``payload_cycle``, ``payload_mass``).
    cases : list of str
        The demo's cases: without this one, the watch does nothing (no subscription, no table).
    """

    def __init__(self, conductor: Any, args: argparse.Namespace, cases: list[str]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rcl_interfaces.msg import Log

        self.c = conductor
        self.active = CASE in cases
        self.at, self.mass = int(args.payload_cycle), float(args.payload_mass)
        self.told = bool(getattr(args, "payload_told", False))  # the learner told the payload at the change
        self.drifts: list[Drift] = []
        #: the learner's lines that say it relearned the moves (``/rosout``)
        self.relearned: list[str] = []
        #: per cycle of the case (from 0), the learner's cycle of its first move
        self.first: list[int] = []
        if self.active:
            conductor.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 100)
            conductor.create_subscription(Log, "/rosout", self._on_log, 100)

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name != DRIFT:
                continue
            values = {kv.key: kv.value for kv in status.values}
            try:
                cycle, hz = int(values.get("cycle", "")), float(values.get("mode_hz", "nan"))
            except ValueError:
                continue
            level = status.level[0] if isinstance(status.level, (bytes, bytearray)) else int(status.level)
            self.drifts.append(Drift(cycle, level, str(status.message), hz))

    def _on_log(self, msg: Any) -> None:
        if msg.name == "learner" and "relearning" in msg.msg:
            self.relearned.append(str(msg.msg))

    @property
    def warnings(self) -> list[Drift]:
        return [d for d in self.drifts if d.level == WARN_LEVEL]

    def before_cycle(self, case: str, k: int, first: int) -> None:
        """Before cycle ``k`` (from 0) of ``case``, whose first move is the learner's cycle ``first``: for this
        case, the payload changed before cycle ``--payload-cycle`` (from 0), through the plant's parameter
        service; nothing for another case."""
        if case != CASE:
            return
        self.first.append(first)
        if k == self.at:
            self.c.set_plant(arm__payload_mass=self.mass)
            if self.told:
                self._tell_learner()

    def _tell_learner(self) -> None:
        """The learner's ``mrilc_moves.payload_mass`` set to the new payload, through its parameter service."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        cli = self.c.create_client(SetParameters, "/learner/set_parameters")
        try:
            req = SetParameters.Request(parameters=[Parameter("mrilc_moves.payload_mass",
                                                              value=self.mass).to_parameter_msg()])
            bad = [r.reason for r in self.c.call(cli, req).results if not r.successful]
        finally:
            self.c.destroy_client(cli)
        if bad:
            raise RuntimeError(f"the learner refused mrilc_moves.payload_mass {self.mass:g}: {bad}")

    def where(self, cycle: int) -> tuple[int, int] | None:
        """The case's cycle (from 0) and move index of the learner's cycle ``cycle``."""
        for k, first in enumerate(self.first):
            nxt = self.first[k + 1] if k + 1 < len(self.first) else math.inf
            if first <= cycle < nxt:
                return k, cycle - first
        return None

    def table(self, per_move: list[list[tuple[Any, Any, Any]]], noise: float) -> list[str]:
        """The case's table (module docstring) and what it shows, as Markdown lines after an empty one (none if
        the case did not run)."""
        from ..arm.metrics import SETTLE_TOLERANCE

        if not self.active:
            return []
        tol_mm = SETTLE_TOLERANCE * 1e3
        by_move: dict[tuple[int, int], list[Drift]] = {}
        for d in self.drifts:
            at = self.where(d.cycle)
            if at is not None:
                by_move.setdefault(at, []).append(d)
        out = ["", f"Payload {LIGHT:g} -> {self.mass:g} kg before cycle {self.at + 1} (accelerometer noise {noise:g}"
               f" m/s^2). Per cycle and move: residual RMS m/s^2 / peak mm / move + settle s; the drift watch's"
               f" rating of the move (its mode outside or inside the working band of the shaper it ran with; WARN:"
               f" the status, some move outside in watch.confirm cycles of its own in a row); within: peak within"
               f" {tol_mm:g} mm.", "",
               "| cycle | payload kg | move | residual RMS m/s^2 | peak mm | move+settle s | drift | within |",
               "|---|---|---|---|---|---|---|---|"]
        for k, cycle in enumerate(per_move):
            kg = self.mass if k >= self.at else LIGHT
            for i, (run, m, _) in enumerate(cycle):
                drift = "; ".join(_label(d) for d in by_move.get((k, i), []))
                within = "yes" if m.peak_mm <= tol_mm else "no"
                out.append(f"| c{k + 1} | {kg:g} | {run.index + 1}. {run.name} | {m.residual_rms:.4f} |"
                           f" {m.peak_mm:.4f} | {m.move_and_settle_s:.3f} | {drift or '-'} | {within} |")
        out += ["", *self.summary(per_move)]
        return out

    def summary(self, per_move: list[list[tuple[Any, Any, Any]]]) -> list[str]:
        """What the table shows: the first WARN, the learner's relearn, and from which cycle every move is within
        the tolerance again."""
        from ..arm.metrics import SETTLE_TOLERANCE

        tol_mm = SETTLE_TOLERANCE * 1e3
        within = [all(m.peak_mm <= tol_mm for _, m, _ in cycle) for cycle in per_move]
        back = next((k for k in range(self.at, len(within)) if all(within[k:])), None)
        warns = self.warnings
        first = self.where(warns[0].cycle) if warns else None
        lines = [f"- payload {LIGHT:g} -> {self.mass:g} kg before cycle {self.at + 1}"]
        if first is not None:
            k, i = first
            lines.append(f"- first drift WARN: cycle {k + 1}, move {per_move[k][i][0].index + 1}."
                         f" {per_move[k][i][0].name}: {warns[0].message}")
        else:
            lines.append("- no drift WARN")
        lines += [f"- the learner: {line}" for line in self.relearned[:3]] or ["- the learner did not relearn"]
        lines.append(f"- every move within {tol_mm:g} mm from cycle {back + 1} ({back - self.at + 1} cycles with the"
                     " new payload) to the last" if back is not None else
                     f"- not every move within {tol_mm:g} mm by the last cycle")
        return lines
