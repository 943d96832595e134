"""MRILC per move after a payload change: 2 -> 4.5 kg mid-run, the drift warning, every move relearned (issue 31
item 5 with MRILC).

``python -m reproductions.arm_mrilc_payload [--cycles N] [--operator default|told|drift|all] [--json PATH]``
(``./run exec python -m reproductions.arm_mrilc_payload``) runs :mod:`reproductions.arm_mrilc`'s cycle (the
calibrated schedule, MRILC per move, the ROS-free arm, deterministic) with the payload changed from 2 to
:data:`~reproductions.arm_learning.HEAVY` kg after :data:`~reproductions.arm_learning.PAYLOAD_AT` cycles, as
``reproductions.arm_learning``'s ``payload`` case does for LIST:

- a drift watch per move (:class:`~shaper_nodes.core.identification.drift.DriftWatch`, 2 checks in a row) on the
  strongest lightly damped mode identified in the move's residual (from 0.1 s after the commanded motion), rated
  against the move's scheduled shaper, as that case does; the status is WARN while any move's watch warns (as the
  identifier node publishes it);
- at the first WARN of an episode (an OK ends it) every move's learner is dropped with its correction, as the
  learner node's ``relearn`` does (``nodes/learner_moves_mrilc.py``): the move whose END brought the warning is not
  learned from (its goal ran with the old correction), each move's next goal runs as the current schedule shaped it
  (the schedule does not change), and its learner starts again from zero;
- the learner restarted with the operator ``--operator`` names: ``default``, the arm linearised at its default
  payload (what the node's ``sim_plant_node.arm.lifted:arm_operator`` gives, whatever the payload), or ``told``, the
  arm linearised with the payload the robot is told (:func:`told_operators`, the payload the controller's gravity
  feedforward already follows: ``ArmModel.set_payload``), or ``drift``, the arm linearised with the payload worked
  out from the warning's modes (:func:`drift_estimate`: the modes identified in the residual of the move whose END
  brought the warning, the strongest (rated) first, matched to the model's modes at its goal as the learner node's
  ``mrilc_moves.payload_from_drift`` does; refused, the default operator), with the estimate's error and its
  scatter when 0.01 m/s^2 of noise is added to that residual (20 seeds).

Rows: case (the operator), move, cycle, payload_kg, residual_rms (m/s^2, noise-free), peak_mm (the flange's largest
distance from its rest in the residual window, against 0.05 mm), move_settle_s, servo_rms / vibration_rms, the
learner's cycle, action (learn, fallback, hold; "" for a cycle not learned from) and cost, the correction used,
limit_excess (0: every limit held), warning (the status after the move) and relearn (the learner dropped after it).
:func:`convergence` states why it converges or not: the eigenvalues of the lifted law L times the 4.5 kg arm's G.
Writes docs/results/arm_mrilc_payload.md.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from reproductions.arm_mrilc import OUTPUT_PERIOD, RATE, TREND_DEGREE, MovePlan, limits, plan_moves, run_move
from reproductions.common import docs_option

OPERATORS = ("default", "told", "drift")
#: the IMU noise of the scatter trials at the warning cycle, m/s^2 (the demo's)
NOISE = 0.01
#: s after the commanded motion the drift watch's identification starts (reproductions.arm_learning's payload case)
IDENTIFY_SKIP = 0.1
#: the flange's settle tolerance, mm (sim_plant_node.arm.metrics.SETTLE_TOLERANCE)
TOLERANCE_MM = 0.05


def told_operators(plans: list[MovePlan], mass: float) -> list[np.ndarray]:
    """Each move's lifted operator on the arm linearised with a payload of ``mass`` kg (same plan and basis)."""
    from shaper_nodes.core.learning.mrilc.plan import plan_operator
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.lifted import lifted_operator

    model = ArmModel()
    model.set_payload(mass)

    def provider(pose: np.ndarray, count: int, samples: int, first: int, spacing: float,
                 period: float) -> np.ndarray:
        return lifted_operator(model, pose, count, samples, first, spacing, period)

    return [plan_operator(p.core, provider, p.positions[-1], 6, OUTPUT_PERIOD) for p in plans]


def convergence(plans: list[MovePlan], true_ops: list[np.ndarray], gain: float = 0.5,
                settings: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Per move, the lifted iteration c <- c + gain L e on the arm whose operator is ``true_ops``, with L the
    learner's law on the move's own operator (``plans``): the coefficients' error evolves with I - gain L G_true, so
    learning converges where every eigenvalue lambda of L G_true has |1 - gain lambda| < 1 (its real part > 0 for a
    small gain: the lifted form of "the model's phase error inside 90 degrees"). Gives the smallest real part, the
    largest |1 - gain lambda| and how many eigenvalues have it above 1 (directions that grow), against the same
    with G_true = the move's own operator (the model exact)."""
    from shaper_nodes.core.learning.mrilc.moves import MoveLearner

    out = []
    for p, g_true in zip(plans, true_ops, strict=True):
        law = MoveLearner(p.operator, p.profile, limits(), **{"weights": p.weights, **(settings or {})})._law
        row: dict[str, Any] = {"move": p.name}
        for tag, g in (("own", p.operator), ("true", g_true)):
            lam = np.linalg.eigvals(law @ g)
            rate = np.abs(1.0 - gain * lam)
            row[f"{tag}_min_real"] = float(np.min(lam.real))
            row[f"{tag}_max_rate"] = float(np.max(rate))
            row[f"{tag}_growing"] = int(np.sum(rate > 1.0 + 1e-9))
        row["operator_change"] = float(np.linalg.norm(g_true - p.operator) / np.linalg.norm(p.operator))
        out.append(row)
    return out


def frequency_response(model: Any, pose: np.ndarray, hz: float) -> np.ndarray:
    """(3, 6): the flange accelerometer's specific force per joint setpoint (m/s^2 per rad) at ``hz``, on the arm
    linearised at rest holding ``pose`` (the model of :func:`sim_plant_node.arm.lifted.lifted_operator`, continuous,
    the setpoint's rate its derivative)."""
    from sim_plant_node.arm.modal import state_matrix, tool_output

    n = 6
    a, minv = state_matrix(model, pose)
    drive = np.zeros((2 * n, 2 * n))
    drive[n:, :n] = np.diag(model.kp) + model.gravity_stiffness(np.asarray(pose, dtype=float))
    drive[n:, n:] = np.diag(model.kd)
    b = np.vstack([np.zeros((2 * n, 2 * n)), minv @ drive])
    w = 2 * math.pi * hz
    g = tool_output(model, pose, a) @ np.linalg.solve(1j * w * np.eye(a.shape[0]) - a, b)
    return np.asarray(g[:, :n] + 1j * w * g[:, n:])


def phase_error(poses: dict[str, np.ndarray], mass: float, band: tuple[float, float] = (5.0, 25.0),
                step: float = 0.05) -> list[dict[str, Any]]:
    """Per move (its goal pose): the modes below ``band[1]`` at 2 kg and at ``mass`` kg, and where in ``band`` the
    model at 2 kg is more than 90 degrees off the arm at ``mass`` kg in phase (the channel, joint to axis, that
    responds most on the heavy arm at each frequency): the bands (Hz) and the largest error (Hz, degrees)."""
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.modal import modes

    light, heavy = ArmModel(), ArmModel()
    heavy.set_payload(mass)
    out = []
    for name, pose in poses.items():
        bands: list[list[float]] = []
        worst = (0.0, 0.0)
        for hz in np.arange(band[0], band[1], step):
            gl, gh = frequency_response(light, pose, hz), frequency_response(heavy, pose, hz)
            k, j = np.unravel_index(np.argmax(np.abs(gh)), gh.shape)
            deg = float(np.degrees(np.angle(gh[k, j] / gl[k, j])))
            if abs(deg) > abs(worst[1]):
                worst = (float(hz), deg)
            if abs(deg) > 90.0:
                if bands and hz - bands[-1][1] < 1.5 * step:
                    bands[-1][1] = float(hz)
                else:
                    bands.append([float(hz), float(hz)])
        def below(model: Any, pose: np.ndarray = pose) -> list[float]:
            return [hz for hz in (md.omega / (2 * math.pi) for md in modes(model, pose)) if hz < band[1]]

        out.append({"move": name, "light_hz": below(light), "heavy_hz": below(heavy), "bands": bands,
                    "worst_hz": worst[0], "worst_deg": worst[1]})
    return out


def payload_run(plans: list[MovePlan], shapers: list[Any], cycles: int, operator: str = "default",
                settings: dict[str, Any] | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """``cycles`` cycles of ``plans`` (shaped by ``shapers``) with MRILC per move, the payload changed after
    PAYLOAD_AT cycles, the drift watch and the relearn (module docstring); rows and notes."""
    from reproductions.arm_learning import HEAVY, PAYLOAD_AT
    from reproductions.residual_split import SERVO_ZETA
    from shaper_nodes.core.identification import IdentificationError, identify
    from shaper_nodes.core.identification.drift import DriftWatch, check_mode
    from shaper_nodes.core.learning.mrilc.moves import MoveLearner
    from shaper_nodes.core.learning.mrilc.plan import residual_error
    from shaper_nodes.core.learning.mrilc.profile import profile_excess
    from sim_plant_node.arm.offline import OfflineArm

    if operator not in OPERATORS:
        raise ValueError(f"operator must be one of {OPERATORS}, got {operator!r}")
    lim = limits()
    kw = {**(settings or {})}
    told = told_operators(plans, HEAVY) if operator == "told" else [p.operator for p in plans]

    def fresh(i: int, heavy: bool) -> Any:
        p = plans[i]
        return MoveLearner(told[i] if heavy else p.operator, p.profile, lim, **{"weights": p.weights, **kw})

    estimate: dict[str, Any] = {}

    learners = [fresh(i, False) for i in range(len(plans))]
    watches = [DriftWatch(confirm=2) for _ in plans]
    closed = np.allclose(plans[-1].positions[-1], plans[0].start)  # the moves come back to the start
    arm = OfflineArm(plans[0].start, RATE, states=True)
    linear: dict[Any, Any] = {}
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    warned, mass = False, 2.0
    for cycle in range(1, cycles + 1):
        if not closed and cycle > 1:  # a part of the cycle: each from rest at its start (as arm_mrilc.run_case)
            arm = OfflineArm(plans[0].start, RATE, states=True)
        if cycle == PAYLOAD_AT + 1:
            mass = HEAVY
            notes.append(f"cycle {cycle}: payload 2 -> {HEAVY:g} kg")
        if arm.plant.model.payload[0] != mass:
            arm.plant.set_payload(mass)  # the arm swings under it from its old rest
            if not closed:
                arm.plant.reset(plans[0].start)  # a fresh arm: at rest with it
        for i, p in enumerate(plans):
            lr = learners[i]
            base = (p.positions, p.velocities, p.accelerations)
            points = lr.corrected()
            start, it, imu, m, parts = run_move(arm, p, points, linear)
            t = it - start
            upd = lr.update(residual_error(p.core, t, imu, TREND_DEGREE))
            sel = t > p.motion_end + IDENTIFY_SKIP
            try:
                fits = [f for f in identify(t[sel], imu[sel], max_modes=3) if 2.0 < f.hz < 40.0 and f.zeta < SERVO_ZETA]
            except IdentificationError:
                fits = []
            sh = shapers[i]
            if fits:
                strongest = max(fits, key=lambda f: f.amplitude)
                design_hz = [md.omega / (2 * math.pi) for md in sh.modes]
                watches[i].update(check_mode(sh.amplitudes, sh.times, design_hz, strongest, 0.05))
            else:
                watches[i].quiet()
            status = any(w.warning for w in watches)
            relearn = status and not warned
            warned = status
            if relearn:
                last = watches[i].last
                said = last.describe() if last is not None else ""
                notes.append(f"cycle {cycle}, {p.name}: drift WARN ({said}); every move's correction dropped, its"
                             f" learner restarted ({operator} operator); this move's update not kept")
                if operator == "drift":  # the payload from the warning's modes at this move's goal
                    estimate = drift_estimate(p.positions[-1], [strongest, *[f for f in fits if f is not strongest]],
                                              (t[sel], imu[sel]))
                    notes.append(estimate["note"])
                    if estimate.get("mass") is not None:
                        told = told_operators(plans, estimate["mass"])
                learners = [fresh(j, operator in ("told", "drift")) for j in range(len(plans))]
            rows.append({"case": operator, "move": p.name, "cycle": cycle, "payload_kg": mass,
                         "residual_rms": m.residual_rms, "peak_mm": m.peak_mm, "move_settle_s": m.move_and_settle_s,
                         "servo_rms": parts.servo_rms, "vibration_rms": parts.vibration_rms,
                         "learner_cycle": upd.cycle, "action": "" if relearn else upd.action,
                         "cost": upd.cost, "gain": upd.gain,
                         "max_correction_rad": float(np.max(np.abs(points[0] - base[0]))),
                         "limit_excess": profile_excess(points[0], points[1], points[2], lim, base),
                         "warning": status, "relearn": relearn,
                         "estimated_kg": estimate.get("mass") if relearn else None})
    return rows, notes


def drift_estimate(pose: np.ndarray, fits: list[Any], window: tuple[np.ndarray, np.ndarray] | None = None,
                   trials: int = 20) -> dict[str, Any]:
    """The payload from the warning's modes ``fits`` (the rated one first) at ``pose``, as the learner node's
    ``payload_from_drift`` works it out (:func:`~shaper_nodes.core.learning.mrilc.payload.payload_from_modes` on
    ``sim_plant_node.arm.lifted:arm_modes``): ``mass`` (None: refused, the learner keeps the default operator),
    ``note``; with the residual ``window`` (t, imu), ``trials`` identifications of it with :data:`NOISE` m/s^2 of
    white noise added (seeds 1..trials), the rated (strongest) mode and the mass each gives: ``scatter``."""
    from reproductions.arm_learning import HEAVY
    from reproductions.residual_split import SERVO_ZETA
    from shaper_nodes.core.identification import IdentificationError, identify
    from shaper_nodes.core.learning.mrilc.payload import PayloadRefused, payload_from_modes
    from sim_plant_node.arm.lifted import arm_modes

    def modes_at(mass: float) -> list[float]:
        return arm_modes(pose, mass)

    hz = [f.hz for f in fits]
    out: dict[str, Any] = {"modes_hz": hz, "mass": None}
    try:
        est = payload_from_modes(hz, modes_at)
        out["mass"] = est.mass
        out["note"] = (f"from the drift's modes ({', '.join(f'{f:.4g}' for f in hz)} Hz, the first rated): "
                       f"{est.describe()}; the true {HEAVY:g} kg missed by {est.mass - HEAVY:+.3g} kg"
                       f" ({100 * (est.mass - HEAVY) / HEAVY:+.2g} %)")
    except PayloadRefused as err:
        out["note"] = (f"from the drift's modes ({', '.join(f'{f:.4g}' for f in hz)} Hz): refused ({err});"
                       " default operator")
    if window is None or trials <= 0:
        return out
    scatter: list[dict[str, Any]] = []
    for seed in range(1, trials + 1):
        t, imu = window
        noisy = imu + np.random.default_rng(seed).normal(0.0, NOISE, imu.shape)
        try:
            got = [f for f in identify(t, noisy, max_modes=3) if 2.0 < f.hz < 40.0 and f.zeta < SERVO_ZETA]
        except IdentificationError:
            got = []
        if not got:
            scatter.append({"seed": seed, "modes_hz": [], "mass": None, "why": "no mode"})
            continue
        rated = max(got, key=lambda f: f.amplitude)
        modes = [rated.hz, *[f.hz for f in got if f is not rated]]
        try:
            scatter.append({"seed": seed, "modes_hz": modes, "mass": payload_from_modes(modes, modes_at).mass})
        except PayloadRefused as err:
            scatter.append({"seed": seed, "modes_hz": modes, "mass": None, "why": str(err)})
    out["scatter"] = scatter
    kg = np.array([x["mass"] for x in scatter if x["mass"] is not None])
    rated_hz = np.array([x["modes_hz"][0] for x in scatter if x["modes_hz"]])
    refused = [str(x.get("why", "")) for x in scatter if x["mass"] is None]
    kinds = sorted({w.split(":")[0].split(" (")[0] for w in refused})
    out["note"] += (f". With {NOISE:g} m/s^2 of noise on the same residual ({trials} seeds): the rated mode "
                    + (f"{rated_hz.mean():.4g} +- {rated_hz.std():.2g} Hz ({rated_hz.min():.4g}-{rated_hz.max():.4g})"
                       if rated_hz.size else "never identified")
                    + (f", the payload {kg.mean():.3g} +- {kg.std():.2g} kg ({kg.min():.3g}-"
                       f"{kg.max():.3g}) in {kg.size}" if kg.size else ", no payload")
                    + (f", refused in {len(refused)} ({'; '.join(kinds)})" if refused else ", none refused"))
    return out


def within_from(rows: list[dict[str, Any]], change: int) -> dict[str, int | None]:
    """Per move (and ``"all"``): the first cycle from which its flange peak stays within the tolerance to the last
    cycle, counted from ``change`` (the first cycle with the new payload); None if never."""
    cycles = sorted({r["cycle"] for r in rows})
    moves = list(dict.fromkeys(r["move"] for r in rows))
    peak = {(r["move"], r["cycle"]): r["peak_mm"] for r in rows}
    out: dict[str, int | None] = {}
    for name in [*moves, "all"]:
        names = moves if name == "all" else [name]
        first = None
        for c in reversed([c for c in cycles if c >= change]):
            if all(peak[(n, c)] <= TOLERANCE_MM for n in names):
                first = c
            else:
                break
        out[name] = first
    return out


def report(rows: list[dict[str, Any]], notes: dict[str, list[str]], conv: list[dict[str, Any]],
           phase: list[dict[str, Any]] | None = None) -> str:
    """The page's body: per operator, the per-cycle table (peak mm / residual m/s^2 / action) and the verdict."""
    from reproductions.arm_learning import HEAVY, PAYLOAD_AT

    change = PAYLOAD_AT + 1
    lines = ["## Why (the lifted law on the 4.5 kg arm)", "",
             "Per move: L is the learner's law built on the operator at 2 kg; eigenvalues lambda of L G, G the"
             " operator at 2 kg (the model exact) and at 4.5 kg (the arm after the change); the iteration converges"
             " where |1 - 0.5 lambda| < 1 for every lambda.", "",
             "| move | ||G(4.5) - G(2)|| / ||G(2)|| | min Re lambda, G(2) | min Re lambda, G(4.5) |"
             " max abs(1 - 0.5 lambda), G(4.5) | growing directions |", "|---|---|---|---|---|---|"]
    for c in conv:
        lines.append(f"| {c['move']} | {c['operator_change']:.3f} | {c['own_min_real']:.2e} | {c['true_min_real']:.2e}"
                     f" | {c['true_max_rate']:.6f} | {c['true_growing']} |")
    if phase:
        lines += ["", "Per frequency (the lifted law's eigenvalues come from here): the arm's modes below 25 Hz at 2"
                  f" and {HEAVY:g} kg at the move's goal, and the bands of 5-25 Hz where the model at 2 kg is more than"
                  f" 90 degrees off the {HEAVY:g} kg arm in phase (in the joint-to-axis channel that responds most at"
                  " each frequency; 0.05 Hz steps): there a step of the law along the model makes the error grow.", "",
                  f"| move | modes 2 kg, Hz | modes {HEAVY:g} kg, Hz | beyond 90 degrees, Hz | largest error |",
                  "|---|---|---|---|---|"]
        for ph in phase:
            lines.append(f"| {ph['move']} | {', '.join(f'{x:.2f}' for x in ph['light_hz'])} |"
                         f" {', '.join(f'{x:.2f}' for x in ph['heavy_hz'])} |"
                         f" {', '.join(f'{a:.2f}-{b:.2f}' for a, b in ph['bands']) or 'none'} |"
                         f" {ph['worst_deg']:+.0f} deg at {ph['worst_hz']:.2f} Hz |")
    for case in dict.fromkeys(r["case"] for r in rows):
        mine = [r for r in rows if r["case"] == case]
        cycles = sorted({r["cycle"] for r in mine})
        moves = list(dict.fromkeys(r["move"] for r in mine))
        by = {(r["move"], r["cycle"]): r for r in mine}
        lines += ["", f"## Operator: {case}", ""] + [f"- {n}" for n in notes.get(case, [])] + [
            "", "Flange peak mm / residual m/s^2 / the learner's action (W: drift WARN after the move, R: every"
            " learner dropped after it; bold: above 0.05 mm):", "",
            "| move | " + " | ".join(f"c{c} ({by[(moves[0], c)]['payload_kg']:g} kg)" for c in cycles) + " |",
            "|---|" + "---|" * len(cycles)]
        for n in moves:
            cells = []
            for c in cycles:
                r = by[(n, c)]
                pk = f"{r['peak_mm']:.4f}"
                pk = f"**{pk}**" if r["peak_mm"] > TOLERANCE_MM else pk
                flag = ("R" if r["relearn"] else "W" if r["warning"] else "")
                cells.append(f"{pk} / {r['residual_rms']:.4f} / {r['action'] or '-'}{' ' + flag if flag else ''}")
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        back = within_from(mine, change)
        guard = [f"{r['move']} c{r['cycle']} {r['action']}" for r in mine if r["action"] in ("fallback", "hold")]
        excess = max(r["limit_excess"] for r in mine)
        a = back["all"]
        lines += ["", f"Every move within {TOLERANCE_MM:g} mm to the last cycle from cycle {a if a else 'never'}"
                  + (f" (the {a - change + 1}th cycle with {HEAVY:g} kg; the must-show: within 5)" if a else "")
                  + "; per move from: " + ", ".join(f"{n} {f'c{back[n]}' if back[n] else 'never'}" for n in moves)
                  + f". Divergence guard: {', '.join(guard) or 'no fallback, no hold'}."
                  f" Largest excess over the joint limits: {excess:.3g} (0: every limit held)."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_mrilc_payload", description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=12, help="cycles in all (default 12: 3 at 2 kg, 9 at 4.5 kg)")
    p.add_argument("--operator", choices=(*OPERATORS, "all"), default="all",
                   help="the operator the learners restart with (default all, one run each)")
    p.add_argument("--json", type=pathlib.Path, default=None, help="write the rows to this JSON file")
    p.add_argument("--no-docs", action="store_true", help="do not write the docs page")
    docs_option(p, "arm_mrilc_payload.md")
    args = p.parse_args(argv)
    from reproductions.arm_learning import HEAVY, PAYLOAD_AT
    from reproductions.arm_mrilc import schedule
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.task import cycle_moves

    if args.cycles <= PAYLOAD_AT:
        p.error(f"--cycles must be more than {PAYLOAD_AT} (the payload changes after cycle {PAYLOAD_AT})")
    t0 = time.monotonic()
    shaper_for: Callable[[np.ndarray], Any] = schedule()
    plans = plan_moves(shaper_for, ArmModel())
    shapers = [shaper_for(mv.positions[-1]) for mv in cycle_moves()]
    conv = convergence(plans, told_operators(plans, HEAVY))
    phase = phase_error({p.name: p.positions[-1] for p in plans}, HEAVY)
    rows, notes = [], {}
    for op in OPERATORS if args.operator == "all" else (args.operator,):
        r, n = payload_run(plans, shapers, args.cycles, op)
        rows += r
        notes[op] = n
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "notes": notes, "convergence": conv, "phase": phase}, indent=1))
    text = report(rows, notes, conv, phase)
    took = f"({time.monotonic() - t0:.0f} s, {args.cycles} cycles, noise-free)"
    print(text)
    print(took)
    if not args.no_docs:
        args.docs.mkdir(parents=True, exist_ok=True)
        (args.docs / "arm_mrilc_payload.md").write_text(
            f"# MRILC per move after a payload change (2 -> {HEAVY:g} kg after cycle {PAYLOAD_AT})\n\nGenerated by"
            f" `python -m reproductions.arm_mrilc_payload --cycles {args.cycles}` {took}: the calibrated schedule"
            " with MRILC per move ([arm_mrilc.md](arm_mrilc.md)), the payload changed, the drift watch per move,"
            " every move's learner dropped at the first WARN and restarted with the operator named (module"
            " docstring of `reproductions/arm_mrilc_payload.py`).\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
