"""The arm runs every case shares: the schedule (the offline calibration, cached, or the modal one), the
context, the arm cell that runs one move and measures it, the rows, the registry of cases."""

from __future__ import annotations

import hashlib
import json
import math
import pathlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

RATE = 500.0


IMU_RATE = 2.0 * RATE  # Hz: the offline arm's accelerometer samples at each of its two substeps


DWELL = 1.5  # s at rest after each move, as in the demo


OUT = pathlib.Path("out") / "arm_learning"


#: the UR5e's published joint speed limit, all six joints: 180 deg/s (UR5e technical specifications;
#: ur_description's joint_limits.yaml: 3.14159 rad/s), rad/s
UR5E_MAX_VELOCITY = math.pi


#: tolerance of the settled flange, m (sim_plant_node.arm.metrics.SETTLE_TOLERANCE)
PAYLOAD_AT = 3  # the payload changes after this many cycles


HEAVY = 4.5  # kg


Row = dict[str, Any]


CaseFn = Callable[["Context", int], list[Row]]


#: the cases, name -> function(context, cycles) returning rows
CASES: dict[str, CaseFn] = {}


def register(name: str) -> Callable[[CaseFn], CaseFn]:
    """Decorator: add a case to :data:`CASES` (its function takes the context and the cycle count)."""
    def add(fn: CaseFn) -> CaseFn:
        CASES[name] = fn
        return fn
    return add


def _config() -> pathlib.Path:
    return pathlib.Path(__file__).resolve().parents[2] / "shaper_nodes" / "config" / "calibrate.yaml"


def calibration(cache: pathlib.Path | None = OUT / "calibration.json") -> dict[str, Any]:
    """The schedule's rule base, family and joint names from the offline calibration, cached by the plan's hash."""
    from reproductions.arm_calibration import offline_calibration

    digest = hashlib.sha256(_config().read_bytes()).hexdigest()[:16]
    if cache is not None and cache.exists():
        doc = json.loads(cache.read_text())
        if doc.get("plan_sha256") == digest:
            return dict(doc)
    cal = offline_calibration(_config())
    doc = {"plan_sha256": digest, "rule_base": cal.rule_base, "family": cal.family,
           "joints": list(cal.plan.config.joint_names),
           "home_modes": [[m.omega, m.zeta] for m in cal.results[0].modes]}
    if cache is not None:
        from shaper_nodes.core.files import write_atomic

        write_atomic(cache, json.dumps(doc))
    return doc


def modal_calibration(poses: tuple[tuple[float, ...], tuple[float, ...]] = ((-1.9, -1.57, -1.0), (0.5, 1.57, 2.4)),
                      n_modes: int = 3) -> dict[str, Any]:
    """A schedule of the same shape as the calibration's (shoulder_lift x elbow grid, ZV) from the modal
    analysis of the linearised arm at its grid poses (under a second; for quick runs and the tests)."""
    from sim_plant_node.arm.description import JOINT_NAMES
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.modal import modes
    from sim_plant_node.arm.task import HOME

    model, rules = ArmModel(), {}
    lift, elbow = poses

    def tri(grid: tuple[float, ...], i: int) -> list[float]:
        return [grid[max(i - 1, 0)], grid[i], grid[min(i + 1, len(grid) - 1)]]

    for i, a in enumerate(lift):
        for j, b in enumerate(elbow):
            q = HOME.copy()
            q[1], q[2] = a, b
            found = sorted(modes(model, q), key=lambda m: m.omega)[:n_modes]
            rules[f"r_{i}_{j}"] = {"membership": ["triangular", "triangular"],
                                   "membership_params": tri(lift, i) + tri(elbow, j),
                                   "natural_frequency": [m.omega for m in found],
                                   "damping_ratio": [m.zeta for m in found]}
    home = sorted(modes(model, HOME), key=lambda m: m.omega)[:n_modes]
    return {"plan_sha256": "modal", "family": "zv", "joints": list(JOINT_NAMES),
            "rule_base": {"premises": [JOINT_NAMES[1], JOINT_NAMES[2]], "rules": rules,
                          "range": [lift[0], lift[-1], elbow[0], elbow[-1]]},
            "home_modes": [[m.omega, m.zeta] for m in home]}


@dataclass
class Context:
    """What every case shares: the calibration, the IMU noise, its seed."""

    cal: dict[str, Any]
    noise: float = 0.0
    seed: int = 0
    out: pathlib.Path = OUT
    notes: dict[str, list[str]] = field(default_factory=dict)

    def schedule(self) -> Callable[[np.ndarray], Any]:
        """The scheduled shaper at a goal pose (as the shaper node's ``action.scheduler``)."""
        from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict

        sched = Scheduler(rule_base_from_dict(self.cal["rule_base"]), "modes", self.cal["family"])
        premises = [list(self.cal["joints"]).index(p) for p in sched.rule_base.premises]
        return lambda pose: sched.shaper(sched.evaluate(np.asarray(pose)[premises].tolist()))

    def fallback(self) -> Any:
        """The calibration's fallback: its family on the home pose's modes."""
        from shaper_nodes.core.shaping import Mode, design

        return design(self.cal["family"], [Mode(w, z) for w, z in self.cal["home_modes"]])

    def note(self, case: str, text: str) -> None:
        self.notes.setdefault(case, []).append(text)


@dataclass
class Run:
    """One move's run: its measures and what a learner sees (times from the move's start)."""

    measures: Any
    times: np.ndarray
    imu: np.ndarray
    planned_end: float
    end: float
    torque_ratio: float
    velocity_ratio: float
    late: float
    parts: Any = None  # reproductions.residual_split.Parts: the residual's servo and vibration parts


class Cell:
    """The arm and its controller, running the cycle's moves one after another (one arm for all cycles)."""

    def __init__(self, ctx: Context, model: Any = None) -> None:
        from sim_plant_node.arm.description import TORQUE_LIMITS
        from sim_plant_node.arm.offline import OfflineArm
        from sim_plant_node.arm.task import HOME

        self.arm = OfflineArm(HOME, RATE, noise=ctx.noise, seed=ctx.seed, model=model, states=True)
        self.torque_limits = np.asarray(TORQUE_LIMITS, dtype=float)
        self.linear: dict[Any, Any] = {}  # the arm linearised at each goal (reproductions.residual_split)

    def set_payload(self, mass: float) -> None:
        self.arm.plant.set_payload(mass)

    def run(self, move: Any, shaper: Any = None, factor: float = 1.0) -> Run:
        """Run ``move`` (time-scaled by ``factor``, shaped by ``shaper``; None: unshaped), then dwell."""
        from reproductions.arm_calibration import goal_waypoints
        from reproductions.residual_split import residual_parts
        from sim_plant_node.arm.metrics import inverse_dynamics_peaks, late_residual, measure_move, motion_end
        from sim_plant_node.arm.task import time_scaled

        mv = time_scaled(move, factor)
        times, pos, vel, acc = goal_waypoints(mv, shaper, RATE, DWELL)
        arm = self.arm
        start = arm.run(times, pos, vel, acc)
        end = start + float(times[-1])
        rec = arm.record
        ct, cq = rec.window("cmd", start, end)
        it, imu = rec.window("imu", start, end)
        lt, link = rec.window("link", start, end)
        tool = arm.plant.model.tool_positions(link)
        c_end = motion_end(ct, cq)
        m = measure_move(mv.name, start, mv.duration, c_end, end, it, imu, lt, tool)
        moving = ct <= c_end + 0.05
        torque = inverse_dynamics_peaks(arm.plant.model, ct[moving], cq[moving])
        qd = np.abs(np.gradient(cq[moving], ct[moving], axis=0)).max(axis=0)
        run = Run(m, it - start, imu, mv.duration, end - start, float(np.max(torque / self.torque_limits)),
                  float(np.max(qd) / UR5E_MAX_VELOCITY), late_residual(it, imu, c_end))
        # the state at the commanded end (stamped at the end of the period before the final command's)
        k = int(np.argmin(np.abs(np.asarray(rec.state_t) - c_end)))
        # the parts of the arm's own response (noise-free: the noise is the sensor's, not the arm's)
        run.parts = residual_parts(arm.plant.model, cq[-1], rec.state[k], it, c_end, self.linear)
        for name in ("imu_t", "imu", "cmd_t", "cmd", "link_t", "link", "state_t", "state"):
            getattr(rec, name).clear()
        return run


def row(case: str, cycle: int, run: Run, factor: float = 1.0, **extra: Any) -> Row:
    m = run.measures
    out = {"case": case, "move": m.move, "cycle": cycle, "residual_rms": m.residual_rms,
           "late_rms": run.late, "peak_mm": m.peak_mm, "settle_s": m.settling_s,
           "move_settle_s": m.move_and_settle_s, "speed_factor": factor, "delay_s": m.delay_s,
           "torque_ratio": run.torque_ratio, "velocity_ratio": run.velocity_ratio}
    if run.parts is not None:
        out.update(servo_rms=run.parts.servo_rms, vibration_rms=run.parts.vibration_rms,
                   linear_rms=run.parts.linear_rms)
    out.update(extra)
    return out


def _save(ctx: Context, case: str, store: Any) -> None:
    store.save(ctx.out / f"moves_{case}.json", saved_at=0.0)
