"""MRILC per move on the arm: the schedule alone against the schedule with a learned feedforward per move.

``python -m reproductions.arm_mrilc [--cycles N] [--noise S] [--json PATH]`` (``./run exec python -m
reproductions.arm_mrilc``) runs the demo's pick-and-place cycle on the ROS-free arm and controller
(:mod:`sim_plant_node.arm.offline`, deterministic) with each goal shaped for the modes at its final
pose by the calibrated schedule (:func:`reproductions.arm_calibration.offline_calibration`), for N
cycles, as two cases:

- ``scheduled``: the schedule alone (no learning);
- ``scheduled + MRILC per move``: the same, each move's commanded joint profile corrected by a
  feedforward learned cycle by cycle (:mod:`shaper_nodes.core.learning.mrilc.moves`) so that the
  flange accelerometer tracks the rigid arm following the shaped profile (the reference model).

The learning operator of a move is the arm linearised at rest at the move's goal pose
(:func:`sim_plant_node.arm.modal.linearised`, the position loop's drive as input, the flange
accelerometer's specific force as output), sampled like the controller (2 ms hold), on cubic
B-splines every :data:`SPACING` s inside the shaped motion. The IMU noise (``--noise``, m/s^2 per
axis) is added to what the learner sees and to the reported ``residual_rms``; ``residual_rms_noise_free``
is the same measure without it (the arm itself is noise-free, so the vibration learned away is seen
apart from the sensor's noise). Rows follow issue 31's schema: case, move, cycle, residual_rms
(m/s^2), peak_mm, settle_s, move_settle_s (0.05 mm band), speed_factor (1.0), and for the MRILC case
the largest correction per move (rad, rad/s, rad/s^2) and the learner's action.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from reproductions.common import docs_option

RATE = 500.0          # Hz, the controller's update rate (the IMU samples at twice it)
DWELL = 1.5           # s at rest after each move, as in the demo
SPACING = 0.04        # s between the correction's B-spline knots (resolves up to about 12 Hz)
OUTPUT_PERIOD = 2e-3  # s between the accelerometer samples the learner compares (every second one)
#: UR5e joint position range, rad: +-360 deg on every joint (Universal Robots, UR5e technical
#: specifications, "Working range"); the velocity and acceleration limits held are the moves'
#: planning limits (sim_plant_node.arm.task: 1.5 rad/s, 6 rad/s^2), tighter than the UR5e's published
#: 180 deg/s (3.14 rad/s) per joint; UR publishes no joint acceleration limit.
POSITION_LIMIT = 2 * math.pi
#: output samples the linearised response is delayed by: the controller emulation takes a new setpoint at its
#: next update, one period (2 ms) after the linear model's hold starts (measured: the response to one B-spline
#: on the offline arm peaks one sample later than the model's, with or without the shift the correlation is 0.995)
DELAY = 1
#: the correction acts in the last TAIL s of the shaped motion only, where the arm is near the goal pose and its
#: linearisation there holds (measured: over the whole move the model's prediction of home->pick is off enough that
#: learning diverges; see docs/design/mrilc.md)
TAIL = 0.4
#: s after the shaped motion's end the learner's window starts: the rigid reference's last acceleration steps
#: (0.1 m/s^2 on home->rotated, in the first two samples) are no vibration and no correction can follow them
SKIP = 0.02
#: degree of the drift taken out of the error (tracking_error)
TREND_DEGREE = 2
#: weight of the error during the motion against 1 after it (see docs/design/mrilc.md)
MOTION_WEIGHT = 0.0
CASES = ("scheduled", "scheduled + MRILC per move")


@dataclass
class MovePlan:
    """One move of the cycle, shaped: waypoints from its start (s, (N, 6) fields), the learner's set-up."""

    name: str
    start: np.ndarray           # the pose the move starts at, rad
    planned_duration: float
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    motion_end: float
    grid: np.ndarray            # output sample times from the move's start, s
    reference: np.ndarray       # (len(grid), 3) the rigid arm's specific force, m/s^2
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (grid x 3,) weight of each output sample
    profile: Any = None         # moves.Profile
    operator: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # the lifted G


def limits() -> Any:
    from shaper_nodes.core.learning.mrilc.moves import JointLimits
    from sim_plant_node.arm.task import MAX_ACCELERATION, MAX_VELOCITY

    return JointLimits(np.full(6, -POSITION_LIMIT), np.full(6, POSITION_LIMIT), np.full(6, MAX_VELOCITY),
                       np.full(6, MAX_ACCELERATION))


def plan_moves(shaper_for: Callable[[np.ndarray], Any], model: Any, moves: int | None = None) -> list[MovePlan]:
    """The cycle's moves shaped by ``shaper_for(goal)``, with their basis, reference and operator."""
    from reproductions.arm_calibration import goal_waypoints
    from shaper_nodes.core.learning.mrilc.moves import Profile, spline_basis
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW, motion_end
    from sim_plant_node.arm.task import cycle_moves

    out = []
    for move in cycle_moves()[:moves]:
        times, pos, vel, acc = goal_waypoints(move, shaper_for(move.positions[-1]), RATE, DWELL)
        end = motion_end(np.append(0.0, times), np.vstack([move.positions[0], pos]))
        grid = OUTPUT_PERIOD * np.arange(1, int(round((end + RESIDUAL_WINDOW) / OUTPUT_PERIOD)) + 1)
        offset = max(0.0, math.floor((end - TAIL) / OUTPUT_PERIOD + 1e-9) * OUTPUT_PERIOD)
        count = int((end - offset) / SPACING + 1e-9) - 3
        plan = MovePlan(move.name, move.positions[0], move.duration, times, pos, vel, acc, end, grid,
                        rigid_reference(model, np.append(0.0, times), np.vstack([move.positions[0], pos]),
                                        np.vstack([np.zeros(6), vel]), np.vstack([np.zeros(6), acc]), grid))
        plan.profile = Profile(pos, vel, acc, spline_basis(times - offset, SPACING, count))
        plan.weights = np.repeat(np.where(grid < end + SKIP, MOTION_WEIGHT, 1.0), 3)
        plan.operator = lifted_operator(model, move.positions[-1], count, grid.size, int(round(offset / OUTPUT_PERIOD)))
        out.append(plan)
    return out


def rigid_reference(model: Any, times: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray,
                    grid: np.ndarray) -> np.ndarray:
    """The flange accelerometer's specific force (grid, 3), m/s^2, on the rigid arm following the profile,
    its links where the springs let them sag at rest (q - K^-1 g(q)): the reference model."""
    import pinocchio as pin

    from sim_plant_node.arm.dynamics import GRAVITY

    out = np.empty((grid.size, 3))
    m, d = model.model, model.data
    for k, t in enumerate(grid):
        q = np.array([np.interp(t, times, pos[:, j]) for j in range(6)])
        v = np.array([np.interp(t, times, vel[:, j]) for j in range(6)])
        a = np.array([np.interp(t, times, acc[:, j]) for j in range(6)])
        q = q - model.gravity(q) / model.stiffness
        pin.forwardKinematics(m, d, q, v, a)
        frame = pin.updateFramePlacement(m, d, model.tool)
        lin = pin.getFrameClassicalAcceleration(m, d, model.tool, pin.ReferenceFrame.LOCAL).linear
        out[k] = np.array(lin) + frame.rotation.T @ np.array([0.0, 0.0, GRAVITY])
    return out


def lifted_operator(model: Any, pose: np.ndarray, count: int, samples: int, first: int = 0) -> np.ndarray:
    """G on the arm linearised at ``pose`` (:func:`sim_plant_node.arm.lifted.lifted_operator`, with this module's
    knot spacing and output period)."""
    from sim_plant_node.arm.lifted import lifted_operator as lifted

    return lifted(model, pose, count, samples, first, SPACING, OUTPUT_PERIOD, DELAY)


def tracking_error(plan: MovePlan, measured: np.ndarray) -> np.ndarray:
    """e = y_m - y on the move's grid ((grid x 3) flattened), less, per axis, the polynomial of degree
    :data:`TREND_DEGREE` that fits it best over the residual window (there, on all of the move): the reference
    and the sensor differ by a slow drift that no correction ending with the motion changes (measured on
    home->rotated: 0.0229 m/s^2 RMS in the window against 0.0013 of vibration; the links' sag, which the
    reference models to first order only, settling; a sensor's bias). What is left is the vibration."""
    e = plan.reference - measured
    rest = plan.grid >= plan.motion_end + SKIP
    t = plan.grid - plan.motion_end
    fit = np.polynomial.polynomial.polyfit(t[rest], e[rest], TREND_DEGREE)
    return (e - np.polynomial.polynomial.polyval(t, fit).T).ravel()


def _window(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(grid, times, values[:, i]) for i in range(values.shape[1])])


def run_case(plans: list[MovePlan], cycles: int, noise: float, learn: bool, case: str, seed: int = 0,
             settings: dict[str, Any] | None = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``cycles`` cycles of ``plans`` on one offline arm (the moves run back to back); rows and the learners."""
    from reproductions.residual_split import residual_parts
    from shaper_nodes.core.learning.mrilc.moves import MoveLearner, excess
    from shaper_nodes.core.shaping.vibration import residual_vibration
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW, measure_move
    from sim_plant_node.arm.offline import OfflineArm

    lim = limits()
    learners = {p.name: MoveLearner(p.operator, p.profile, lim, **{"weights": p.weights, **(settings or {})})
                for p in plans} if learn else {}
    closed = np.allclose(plans[-1].positions[-1], plans[0].start)  # the moves come back to the start
    arm = OfflineArm(plans[0].start, RATE, states=True)
    rng = np.random.default_rng(seed)
    rows = []
    linear: dict[Any, Any] = {}
    for cycle in range(1, cycles + 1):
        if not closed:
            arm = OfflineArm(plans[0].start, RATE, states=True)  # a part of the cycle: each from rest at its start
        for p in plans:
            pos, vel, acc = p.positions, p.velocities, p.accelerations
            extra: dict[str, Any] = {}
            if learn:
                lr = learners[p.name]
                dq, dv, da = lr.correction()
                pos, vel, acc = pos + dq, vel + dv, acc + da
                extra = {"max_correction_rad": float(np.max(np.abs(dq))),
                         "max_correction_rad_s": float(np.max(np.abs(dv))),
                         "max_correction_rad_s2": float(np.max(np.abs(da))),
                         "limit_excess": excess(lr.coefficients, p.profile, lim),
                         "profile_excess": lim.violation(pos, vel, acc)}
            start = arm.run(p.times, pos, vel, acc)
            end = start + float(p.times[-1])
            it, imu = arm.record.window("imu", start, end)
            lt, link = arm.record.window("link", start, end)
            tool = arm.plant.model.tool_positions(link)
            m = measure_move(p.name, start, p.planned_duration, start + p.motion_end, end, it, imu, lt, tool)
            c_end = start + p.motion_end
            k = int(np.argmin(np.abs(np.asarray(arm.record.state_t) - c_end)))
            parts = residual_parts(arm.plant.model, p.positions[-1], arm.record.state[k], it, c_end, linear)
            arm.record.state_t.clear()
            arm.record.state.clear()
            extra.update(servo_rms=parts.servo_rms, vibration_rms=parts.vibration_rms)
            seen = imu + (noise * rng.standard_normal(imu.shape) if noise > 0 else 0.0)
            noisy = residual_vibration(it, seen, start + p.motion_end, start + p.motion_end + RESIDUAL_WINDOW,
                                       remove_mean=True).rms
            if learn:
                y = _window(it - start, seen, p.grid)
                upd = learners[p.name].update(tracking_error(p, y))
                extra.update(action=upd.action, tracking_rms=upd.cost)
            rows.append({"case": case, "move": p.name, "cycle": cycle, "residual_rms": noisy,
                         "residual_rms_noise_free": m.residual_rms, "peak_mm": m.peak_mm, "settle_s": m.settling_s,
                         "move_settle_s": m.move_and_settle_s, "speed_factor": 1.0, "noise": noise, **extra})
    return rows, learners


def schedule() -> Callable[[np.ndarray], Any]:
    """The calibrated schedule (the calibration's plan run offline, as reproductions.arm_calibration does; cached
    by reproductions.arm_learning under out/arm_learning, keyed by the plan's hash)."""
    from reproductions.arm_learning import Context, calibration

    return Context(calibration()).schedule()


def modal_zv(model: Any) -> Callable[[np.ndarray], Any]:
    """A ZV on the lowest mode of the linearised arm at the goal pose (a stand-in schedule for fast tests)."""
    from shaper_nodes.core.shaping import design
    from shaper_nodes.core.shaping.types import Mode
    from sim_plant_node.arm.modal import lowest

    def shaper(pose: np.ndarray) -> Any:
        m = lowest(model, pose)
        return design("zv", [Mode(m.omega, m.zeta)])
    return shaper


def mrilc_case(cycles: int, noise: float, shaper_for: Callable[[np.ndarray], Any] | None = None,
               moves: int | None = None, settings: dict[str, Any] | None = None,
               scheduled: bool = True) -> list[dict[str, Any]]:
    """Rows (issue 31's schema) of the cases ``scheduled`` (when ``scheduled``) and ``scheduled + MRILC per
    move`` over ``cycles`` cycles; ``shaper_for(goal pose)`` the schedule (default: the offline
    calibration's), ``moves`` the first moves of the cycle only (default all), ``settings`` the
    learner's (:class:`~shaper_nodes.core.learning.mrilc.moves.MoveLearner`)."""
    from sim_plant_node.arm.dynamics import ArmModel

    if cycles < 1 or not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"cycles must be >= 1 and noise finite and >= 0 m/s^2, got {cycles}, {noise}")
    model = ArmModel()
    plans = plan_moves(shaper_for or schedule(), model, moves)
    rows = run_case(plans, 1, noise, False, CASES[0])[0] if scheduled else []
    rows += run_case(plans, cycles, noise, True, CASES[1], settings=settings)[0]
    return rows


def summary(rows: list[dict[str, Any]], noise: float = 0.0) -> str:
    """Per move: the schedule's residual, the learned one at the last cycle and the ratio, the same for the
    residual's vibration part (:mod:`reproductions.arm_physics`); the largest correction; the corrected goal."""
    sched = {r["move"]: r for r in rows if r["case"] == CASES[0]}
    learned = [r for r in rows if r["case"] == CASES[1]]
    last = max(r["cycle"] for r in learned)
    floor = math.sqrt(3.0) * noise
    lines = [f"| move | scheduled residual (noise-free) | MRILC at cycle {last} | ratio | best cycle ratio |"
             " servo / vibration part, scheduled | the same, MRILC | vibration ratio (best) |"
             " move + settle s sched -> MRILC | largest correction rad, rad/s, rad/s^2 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    missed, judged = [], []
    for name, s in sched.items():
        mine = [r for r in learned if r["move"] == name]
        r = mine[-1]
        best = min(x["residual_rms_noise_free"] for x in mine)
        vib = r["vibration_rms"] / s["vibration_rms"]
        best_vib = min(x["vibration_rms"] for x in mine) / s["vibration_rms"]
        if s["vibration_rms"] > floor:
            judged.append(name)
            if vib > 0.25:
                missed.append(f"{name} {100 * vib:.0f} %")
        lines.append(f"| {name} | {s['residual_rms_noise_free']:.5f} ({s['residual_rms']:.5f} measured) |"
                     f" {r['residual_rms_noise_free']:.5f} ({r['residual_rms']:.5f}) |"
                     f" {r['residual_rms_noise_free'] / s['residual_rms_noise_free']:.3f} |"
                     f" {best / s['residual_rms_noise_free']:.3f} |"
                     f" {s['servo_rms']:.5f} / {s['vibration_rms']:.5f} |"
                     f" {r['servo_rms']:.5f} / {r['vibration_rms']:.5f} | {vib:.3f} ({best_vib:.3f}) |"
                     f" {s['move_settle_s']:.3f} -> {r['move_settle_s']:.3f} |"
                     f" {max(x['max_correction_rad'] for x in mine):.2e},"
                     f" {max(x['max_correction_rad_s'] for x in mine):.2e},"
                     f" {max(x['max_correction_rad_s2'] for x in mine):.2e} |")
    excess = max(r["limit_excess"] for r in learned)
    slower = [r["move"] for r in learned if r["cycle"] == last
              and r["move_settle_s"] > sched[r["move"]]["move_settle_s"] + 0.0021]
    lines.append(f"\nLargest excess over the joint limits in any cycle: {excess:.3g} (0: every limit held).")
    verdict = ("not met" if missed or excess > 1e-9 or slower
               else "nothing to judge: every scheduled vibration part is below the floor" if not judged else "met")
    lines.append(f"\n**Corrected goal** (the vibration part at cycle {last} at most 25 % of the schedule's on every"
                 " move"
                 f" whose scheduled vibration part is above the noise floor {floor:.4f} m/s^2, every limit held, no"
                 f" move slower): {verdict}"
                 f" (judged: {', '.join(judged) or 'none'}"
                 + (f"; above 25 %: {', '.join(missed)}" if missed else "")
                 + (f"; slower: {', '.join(slower)}" if slower else "") + ").")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_mrilc", description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=20, help="cycles of the MRILC case (default 20)")
    p.add_argument("--noise", type=float, default=0.0, help="IMU noise per axis, m/s^2 (default 0)")
    p.add_argument("--json", type=pathlib.Path, default=None, help="write the rows to this JSON file")
    p.add_argument("--no-docs", action="store_true", help="do not write the docs page")
    p.add_argument("--render", type=pathlib.Path, default=None,
                   help="write the docs page from the rows of an earlier --json run (no runs; give its --cycles,"
                        " --noise and, as --seconds, how long it took)")
    p.add_argument("--seconds", type=float, default=float("nan"), help="with --render: the run's duration, s")
    docs_option(p, "arm_mrilc.md (arm_mrilc_noise.md with --noise)")
    args = p.parse_args(argv)
    if args.cycles < 1 or not (math.isfinite(args.noise) and args.noise >= 0):
        p.error(f"--cycles must be >= 1 and --noise finite and >= 0, got {args.cycles}, {args.noise}")
    t0 = time.monotonic()
    rows = json.loads(args.render.read_text()) if args.render is not None else mrilc_case(args.cycles, args.noise)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    text = summary(rows, args.noise)
    seconds = args.seconds if args.render is not None else time.monotonic() - t0
    took = f"({seconds:.0f} s, {args.cycles} cycles, noise {args.noise:g} m/s^2)"
    print(text)
    print(took)
    if not args.no_docs:
        tag = "_noise" if args.noise > 0 else ""
        args.docs.mkdir(parents=True, exist_ok=True)
        which = f"IMU noise {args.noise:g} m/s^2 per axis" if args.noise > 0 else "noise-free"
        (args.docs / f"arm_mrilc{tag}.md").write_text(
            f"# MRILC per move on the arm ({which})"
            f"\n\nGenerated by `python -m reproductions.arm_mrilc --cycles {args.cycles}"
            + (f" --noise {args.noise:g}" if args.noise > 0 else "") + f"` {took}. The schedule alone against the"
            " schedule with a feedforward learned per move ([docs/design/mrilc.md](../design/mrilc.md)); residual"
            " RMS m/s^2 over the 1 s after the commanded motion, noise-free (what the arm does; in brackets as"
            " measured with the noise), and its servo and vibration parts (noise-free;"
            " [arm_residual_parts.md](arm_residual_parts.md)).\n\n"
            + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
