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
accelerometer's specific force as output), the setpoint held 2 ms as the controller does, sampled
every :data:`OUTPUT_PERIOD` s, on two families of cubic B-splines in the shaped motion's tail
(:data:`SPACING` s apart in its last :data:`TAIL` s, :data:`FINE_SPACING` s apart in its last
:data:`FINE_TAIL` s); the learner's error is the residual as measured (the accelerometer less its mean
over the 1 s after the motion), so it learns away the position loop's transient and the arm's
vibration both (the move's set-up is the learner node's: :mod:`shaper_nodes.core.learning.mrilc.plan`).
The IMU noise (``--noise``, m/s^2 per axis) is added to what the learner sees and to the reported
``residual_rms``; ``residual_rms_noise_free`` is the same measure without it (the arm itself is
noise-free, so the vibration learned away is seen apart from the sensor's noise).
Rows follow issue 31's schema: case, move, cycle, residual_rms
(m/s^2), peak_mm, settle_s, move_settle_s (0.05 mm band), speed_factor (1.0), and for the MRILC case
the largest correction per move (rad, rad/s, rad/s^2) and the learner's action. The page (docs/results/
arm_mrilc.md, arm_mrilc_noise.md with noise) has the goals, a per-cycle table and the residual per cycle
(img/arm_mrilc_residual[_noise].png); ``--render`` writes it from the rows of an earlier ``--json`` run.
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

from reproductions.common import docs_option, save_figure

RATE = 500.0          # Hz, the controller's update rate (the IMU samples at twice it)
DWELL = 1.5           # s at rest after each move, as in the demo
SPACING = 0.04        # s between the correction's B-spline knots (resolves up to about 12 Hz)
OUTPUT_PERIOD = 1e-3  # s between the accelerometer samples the learner compares: every one (the IMU samples at 1 kHz)
#: UR5e joint position range, rad: +-360 deg on every joint (Universal Robots, UR5e technical
#: specifications, "Working range"); the velocity and acceleration limits held are the moves'
#: planning limits (sim_plant_node.arm.task: 1.5 rad/s, 6 rad/s^2), tighter than the UR5e's published
#: 180 deg/s (3.14 rad/s) per joint; UR publishes no joint acceleration limit.
POSITION_LIMIT = 2 * math.pi
#: the correction acts in the last TAIL s of the shaped motion only, where the arm is near the goal pose and its
#: linearisation there holds (measured: over the whole move the model's prediction of home->pick is off enough that
#: learning diverges; see docs/design/mrilc.md)
TAIL = 0.4
#: the second family of B-splines, FINE_SPACING s apart in the last FINE_TAIL s of the shaped motion: the position
#: loop's transient (eigenvalues at 30-100 Hz, damped 17-26 %) that the motion's last acceleration step starts is
#: over within about 20 ms of its end (measured: 0.0111 of home->pick's 0.0130 m/s^2 servo part in the first 20 ms,
#: 0.0068 in the next 80 ms) and the 40 ms B-splines have no authority there (their spectrum at 30 Hz is 6e-4 of
#: their gain at 0)
FINE_SPACING = 0.004
FINE_TAIL = 0.048
#: s after the shaped motion's end the learner's window starts: 0, the residual's window (the rigid reference is at
#: rest there, a constant)
SKIP = 0.0
#: degree of the polynomial taken out of the error over the window: 0, its mean, as the residual's measure does
#: (so the learner's cost is the residual as measured, its servo part included)
TREND_DEGREE = 0
CASES = ("scheduled", "scheduled + MRILC per move")
#: the cycles the per-cycle table shows (and the last one run)
TABLE_CYCLES = (1, 2, 3, 4, 6, 8, 12, 16, 20)


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
    profile: Any = None         # profile.Profile
    operator: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # the lifted G
    core: Any = None            # shaper_nodes.core.learning.mrilc.plan.MovePlan: the learner node's set-up


def limits() -> Any:
    from shaper_nodes.core.learning.mrilc.profile import JointLimits
    from sim_plant_node.arm.task import MAX_ACCELERATION, MAX_VELOCITY

    return JointLimits(np.full(6, -POSITION_LIMIT), np.full(6, POSITION_LIMIT), np.full(6, MAX_VELOCITY),
                       np.full(6, MAX_ACCELERATION))


def plan_settings() -> Any:
    """The move's set-up (:class:`shaper_nodes.core.learning.mrilc.plan.PlanSettings`) with this module's values."""
    from shaper_nodes.core.learning.mrilc.plan import PlanSettings
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW

    return PlanSettings(spacing=SPACING, tail=TAIL, fine_spacing=FINE_SPACING, fine_tail=FINE_TAIL,
                        output_period=OUTPUT_PERIOD, residual_window=RESIDUAL_WINDOW, skip=SKIP,
                        trend_degree=TREND_DEGREE)


def plan_moves(shaper_for: Callable[[np.ndarray], Any], model: Any, moves: int | None = None) -> list[MovePlan]:
    """The cycle's moves shaped by ``shaper_for(goal)``, with their basis, reference and operator (the set-up of
    :func:`shaper_nodes.core.learning.mrilc.plan.plan_move` and
    :func:`~shaper_nodes.core.learning.mrilc.plan.plan_operator`, as the learner node has them)."""
    from reproductions.arm_calibration import goal_waypoints
    from shaper_nodes.core.learning.mrilc.plan import plan_move, plan_operator
    from sim_plant_node.arm.task import cycle_moves

    out = []
    settings = plan_settings()
    for move in cycle_moves()[:moves]:
        times, pos, vel, acc = goal_waypoints(move, shaper_for(move.positions[-1]), RATE, DWELL)
        core = plan_move(times, pos, vel, acc, move.positions[0], settings)
        plan = MovePlan(move.name, move.positions[0], move.duration, times, pos, vel, acc, core.motion_end, core.grid,
                        rigid_reference(model, np.append(0.0, times), np.vstack([move.positions[0], pos]),
                                        np.vstack([np.zeros(6), vel]), np.vstack([np.zeros(6), acc]), core.grid))
        plan.profile, plan.weights, plan.core = core.profile, core.weights, core

        def provider(pose: np.ndarray, count: int, samples: int, first: int, spacing: float,
                     period: float) -> np.ndarray:
            from sim_plant_node.arm.lifted import lifted_operator as lifted

            return lifted(model, pose, count, samples, first, spacing, period)

        plan.operator = plan_operator(core, provider, move.positions[-1], 6, OUTPUT_PERIOD)
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


def run_move(arm: Any, p: MovePlan, points: tuple[np.ndarray, np.ndarray, np.ndarray],
             linear: dict[Any, Any]) -> tuple[float, np.ndarray, np.ndarray, Any, Any]:
    """Run the move ``p`` with ``points`` (positions, velocities, accelerations) on the offline ``arm``; its start
    (s), the IMU's window (times, samples), its measures (:func:`sim_plant_node.arm.metrics.measure_move`) and the
    residual's parts (:func:`reproductions.residual_split.residual_parts`; ``linear`` their cache)."""
    from reproductions.residual_split import residual_parts
    from sim_plant_node.arm.metrics import measure_move

    start = arm.run(p.times, *points)
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
    return start, it, imu, m, parts


def run_case(plans: list[MovePlan], cycles: int, noise: float, learn: bool, case: str, seed: int = 0,
             settings: dict[str, Any] | None = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``cycles`` cycles of ``plans`` on one offline arm (the moves run back to back); rows and the learners."""
    from shaper_nodes.core.learning.mrilc.moves import MoveLearner
    from shaper_nodes.core.learning.mrilc.plan import residual_error
    from shaper_nodes.core.learning.mrilc.profile import excess, profile_excess
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW, window_residual
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
                base = (pos, vel, acc)
                pos, vel, acc = lr.corrected()  # the corrected points, clipped into the limits
                extra = {"max_correction_rad": float(np.max(np.abs(pos - base[0]))),
                         "max_correction_rad_s": float(np.max(np.abs(vel - base[1]))),
                         "max_correction_rad_s2": float(np.max(np.abs(acc - base[2]))),
                         "limit_excess": profile_excess(pos, vel, acc, lim, base),
                         "coefficient_excess": excess(lr.coefficients, p.profile, lim),
                         "profile_excess": lim.violation(pos, vel, acc)}
            start, it, imu, m, parts = run_move(arm, p, (pos, vel, acc), linear)
            extra.update(servo_rms=parts.servo_rms, vibration_rms=parts.vibration_rms)
            seen = imu + (noise * rng.standard_normal(imu.shape) if noise > 0 else 0.0)
            noisy = window_residual(it, seen, start + p.motion_end, start + p.motion_end + RESIDUAL_WINDOW).rms
            if learn:
                upd = learners[p.name].update(residual_error(p.core, it - start, seen, TREND_DEGREE))
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
    residual's servo and vibration parts (:mod:`reproductions.residual_split`); the largest correction; the
    goals (the residual, and its vibration part, at most 25 % of the schedule's at the last cycle on every move,
    every limit held exactly, no move slower)."""
    from sim_plant_node.arm.metrics import noise_floor

    sched = {r["move"]: r for r in rows if r["case"] == CASES[0]}
    learned = [r for r in rows if r["case"] == CASES[1]]
    last = max(r["cycle"] for r in learned)
    # one rule for "above the noise floor" (docs/guide/learning.md): the schedule's residual as measured above the
    # floor by more than twice the scatter of the noise's RMS over one window (N samples per axis: F / sqrt(6 N))
    floor, scatter, threshold = noise_floor(noise, 2.0 * RATE)  # the IMU samples at twice the controller
    lines = [f"| move | scheduled residual (noise-free) | MRILC at cycle {last} | ratio | best cycle ratio |"
             " servo / vibration part, scheduled | the same, MRILC | vibration ratio (best) |"
             " move + settle s sched -> MRILC | largest correction rad, rad/s, rad/s^2 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    missed, vib_missed, above, noisy, above_missed = [], [], [], [], []
    for name, s in sched.items():
        mine = [r for r in learned if r["move"] == name]
        r = mine[-1]
        ratio = r["residual_rms_noise_free"] / s["residual_rms_noise_free"]
        best = min(x["residual_rms_noise_free"] for x in mine)
        vib = r["vibration_rms"] / s["vibration_rms"]
        best_vib = min(x["vibration_rms"] for x in mine) / s["vibration_rms"]
        if ratio > 0.25:  # with noise: how the schedule's residual compares with the noise floor
            own = s["residual_rms_noise_free"]
            note = f" [the schedule's {own:.4f} m/s^2 is {100 * own / floor:.0f} % of the floor]" if noise > 0 else ""
            missed.append(f"{name} {100 * ratio:.0f} %{note}")
        if vib > 0.25:
            vib_missed.append(f"{name} {100 * vib:.0f} %")
        if noise > 0 and s["residual_rms"] > threshold:
            above.append(name)
            noisy.append(f"{name} {s['residual_rms']:.5f} -> {r['residual_rms']:.5f}")
            if ratio > 0.25:
                above_missed.append(f"{name} {100 * ratio:.0f} %")
        lines.append(f"| {name} | {s['residual_rms_noise_free']:.5f} ({s['residual_rms']:.5f} measured) |"
                     f" {r['residual_rms_noise_free']:.5f} ({r['residual_rms']:.5f}) |"
                     f" {ratio:.3f} | {best / s['residual_rms_noise_free']:.3f} |"
                     f" {s['servo_rms']:.5f} / {s['vibration_rms']:.5f} |"
                     f" {r['servo_rms']:.5f} / {r['vibration_rms']:.5f} | {vib:.3f} ({best_vib:.3f}) |"
                     f" {s['move_settle_s']:.3f} -> {r['move_settle_s']:.3f} |"
                     f" {max(x['max_correction_rad'] for x in mine):.2e},"
                     f" {max(x['max_correction_rad_s'] for x in mine):.2e},"
                     f" {max(x['max_correction_rad_s2'] for x in mine):.2e} |")
    excess = max(r["limit_excess"] for r in learned)
    slower = [r["move"] for r in learned if r["cycle"] == last
              and r["move_settle_s"] > sched[r["move"]]["move_settle_s"] + 0.0021]
    lines.append(f"\nLargest excess of the points sent over the joint limits in any cycle: {excess:.3g}"
                 " (0: every limit held exactly).")
    held = excess == 0.0 and not slower
    seen = " (the arm's, noise-free; the learner saw the noisy IMU)" if noise > 0 else ""
    lines.append(f"\n**Goal** (the residual at cycle {last} at most 25 % of the schedule's on every move{seen}, every"
                 f" limit held, no move slower): {'met' if held and not missed else 'not met'}"
                 + (f" (above 25 %: {', '.join(missed)})" if missed else "")
                 + (f" (slower: {', '.join(slower)})" if slower else "") + ".")
    lines.append(f"\n**Its vibration part** at cycle {last} at most 25 % of the schedule's on every move:"
                 f" {'met' if held and not vib_missed else 'not met'}"
                 + (f" (above 25 %: {', '.join(vib_missed)})" if vib_missed else "") + ".")
    if noise > 0:
        at = [n for n in sched if n not in above]
        lines.append(f"\nAs measured with the noise, the schedule's residual is above the noise floor"
                     f" ({floor:.4f} m/s^2, sqrt(3) x the noise, plus twice the {scatter:.5f} m/s^2 scatter of the"
                     f" noise's RMS over one window: above {threshold:.5f} m/s^2; the rule of docs/guide/learning.md)"
                     f" on: {', '.join(above) or 'no move'}"
                     + (f" (measured residual, the schedule -> cycle {last}: {'; '.join(noisy)})" if noisy else "")
                     + (f"; at the floor: {', '.join(at)}" if at else "") + ".")
        lines.append(f"\n**Goal on every move above the noise floor** (the residual at cycle {last} at most 25 % of"
                     f" the schedule's, noise-free, every limit held, no move slower):"
                     f" {'met' if held and not above_missed and above else 'not met'}"
                     + (f" (above 25 %: {', '.join(above_missed)})" if above_missed else "")
                     + (f" (slower: {', '.join(slower)})" if slower else "")
                     + (f"; the moves at the floor ({', '.join(at)}) are not judged: what the learner sees there is"
                        " the noise" if at else "") + ".")
    return "\n".join(lines)


def per_cycle(rows: list[dict[str, Any]]) -> str:
    """Per move, the MRILC case's residual (noise-free) at the cycles of :data:`TABLE_CYCLES` as a percentage of
    the schedule's."""
    sched = {r["move"]: r["residual_rms_noise_free"] for r in rows if r["case"] == CASES[0]}
    learned = [r for r in rows if r["case"] == CASES[1]]
    cycles = sorted({r["cycle"] for r in learned})
    shown = [c for c in cycles if c in TABLE_CYCLES or c == cycles[-1]]
    lines = ["| move | scheduled m/s^2 | " + " | ".join(f"cycle {c}" for c in shown) + " |",
             "|---|---|" + "---|" * len(shown)]
    for name, base in sched.items():
        by = {r["cycle"]: r["residual_rms_noise_free"] for r in learned if r["move"] == name}
        lines.append(f"| {name} | {base:.5f} | " + " | ".join(f"{100 * by[c] / base:.1f} %" for c in shown) + " |")
    return "\n".join(lines)


def figure(rows: list[dict[str, Any]], docs: pathlib.Path, tag: str) -> str:
    """The residual (noise-free) of each move against the cycle, the schedule's dashed; the image's name under
    ``docs/img``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sched = {r["move"]: r["residual_rms_noise_free"] for r in rows if r["case"] == CASES[0]}
    fig, ax = plt.subplots(figsize=(7, 4))
    for i, (name, base) in enumerate(sched.items()):
        mine = [r for r in rows if r["case"] == CASES[1] and r["move"] == name]
        color = f"C{i}"
        ax.plot([r["cycle"] for r in mine], [r["residual_rms_noise_free"] for r in mine], marker="o", ms=3,
                color=color, label=name)
        ax.axhline(base, color=color, ls="--", lw=0.8)
    ax.set_xlabel("cycle (dashed: the schedule alone)")
    ax.set_ylabel("residual RMS, noise-free, m/s^2")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, docs, f"arm_mrilc_residual{tag}.png")


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
            " RMS m/s^2 over the 1 s after the commanded motion (from the goal's last changing point, as the learner"
            " node has it: one 2 ms controller period later than the window of arm_learning.md, which starts at the"
            " controller's last changing command, hence its higher scheduled residuals), noise-free (what the arm"
            " does; in brackets as measured with the noise), and its servo and vibration parts (noise-free;"
            " [arm_residual_parts.md](arm_residual_parts.md)).\n\n"
            + text + "\n\n## Per cycle\n\nThe residual (noise-free) of the MRILC case as a percentage of the"
            " schedule's, per move and cycle:\n\n" + per_cycle(rows)
            + f"\n\n![residual per cycle](img/{figure(rows, args.docs, tag)})\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
