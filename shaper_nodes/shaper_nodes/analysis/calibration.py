"""A calibration's results from its recording: the pose map, the report, the scheduler's rule base.

The recording (written by the ``calibrate`` node) is a folder of rosbag2 bags, one per completed
pose (``pose_000``, ``pose_001``, ...), each with

- ``/calibrate/setup`` (std_msgs/String): the plan's configuration and the analysis settings,
  as JSON, so that the recording alone recomputes everything;
- ``/calibrate/events`` (shaper_msgs/CycleEvent): per excitation (``cycle`` = repeat), START
  when the controller began it, MOTION_END when its commanded motion ended, END when its free
  decay is over (header stamps, the robot's clock);
- the accelerometer (sensor_msgs/Imu; linear acceleration, m/s^2) and ``/joint_states``.

:func:`compute` turns setup and per-pose samples into a :class:`Calibration`; the node calls it
on what it recorded, and ``calibrate --from-bag`` on what it reads back, so both give the same
report. :func:`.calibration_report.write_outputs` writes report.json, report.md with its figures, scheduler.yaml
(the scheduler node's parameters) and shaper.yaml (the shaper node's fallback parameters),
each written to a temporary name and renamed, so a folder never holds half a file.
"""

from __future__ import annotations

import json
import math
import pathlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.calibration import (
    Decay,
    IdentifySettings,
    Plan,
    PoseResult,
    PoseStep,
    fallback,
    identify_pose,
    make_plan,
    predicted_residual,
    rule_base_spec,
    worst_residual,
)
from shaper_nodes.core.calibration.plan import PlanError, config_from_dict, config_to_dict, plan_to_dict
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL, out_of_range, sensor_fault
from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict
from shaper_nodes.core.shaping import Shaper
from shaper_nodes.core.stamps import stamp_to_sec

from .worker_pool import worker_pool

SETUP_TOPIC = "/calibrate/setup"
EVENTS_TOPIC = "/calibrate/events"
#: event kinds (shaper_msgs/CycleEvent)
START, MOTION_END, END = 0, 1, 2
REPORT_FORMAT = "shaper_nodes calibration report 1"
#: significant digits of the numbers in report.json (what "the same report" is compared to)
DIGITS = 6
#: how the calibrated nodes are wired to the robot, as the calibration found it (``setup["wiring"]``; a recording
#: made before it was recorded takes these, the simulated arm's and a ros2_control robot's names)
WIRING = {"action": "/joint_trajectory_controller/follow_joint_trajectory", "joint_states": "/joint_states",
          "shaper_node": "/shaper", "scheduler_node": "/scheduler"}
#: the flag of a pose whose accelerometer failed (flat, stuck, saturated, silent): no mode of it is used
SENSOR_FAULT = "sensor_fault"


@dataclass
class PoseData:
    """What was recorded at one pose: excitation events (kind, repeat, stamp s) and the accelerometer."""

    index: int
    events: list[tuple[int, int, float]] = field(default_factory=list)
    imu_t: list[float] = field(default_factory=list)
    imu: list[tuple[float, float, float]] = field(default_factory=list)


@dataclass
class Calibration:
    """The pose map and everything built from it."""

    plan: Plan
    settings: IdentifySettings
    family: str
    results: list[PoseResult]
    rule_base: dict[str, Any] | None
    notes: list[str]
    fallback: Shaper | None
    residuals: list[dict[str, float]]
    wiring: dict[str, str] = field(default_factory=lambda: dict(WIRING))


def setup_dict(plan: Plan, settings: IdentifySettings, family: str, premise_threshold: float,
               wiring: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The setup recorded with the calibration (plan configuration, start, analysis settings, and the
    wiring: the FollowJointTrajectory action the arm was moved with and its joint states topic, which
    scheduler.yaml and shaper.yaml name; keys of :data:`WIRING`, the missing ones from it)."""
    unknown = sorted(set(wiring or {}) - set(WIRING))
    if unknown:
        raise PlanError(f"unknown wiring keys {unknown}; known: {sorted(WIRING)}")
    return {"config": config_to_dict(plan.config), "start": plan.start.tolist(),
            "analysis": {"method": settings.method, "max_modes": settings.max_modes,
                         "band_hz": list(settings.band_hz) if settings.band_hz else None,
                         "agreement": settings.agreement, "max_damping": settings.max_damping,
                         "family": family, "premise_threshold": premise_threshold},
            "wiring": {**WIRING, **(wiring or {})}}


def wiring_of(setup: Mapping[str, Any]) -> dict[str, str]:
    """The wiring of a recorded setup (:data:`WIRING` for what it does not name)."""
    got = setup.get("wiring") or {}
    return {k: str(got.get(k, v)) for k, v in WIRING.items()}


def plan_from_setup(setup: dict[str, Any]) -> tuple[Plan, IdentifySettings, str, float]:
    """Plan, identification settings, shaper family and premise threshold of a recorded setup."""
    try:
        plan = make_plan(config_from_dict(setup["config"]), setup["start"])
        a = setup["analysis"]
        band = (float(a["band_hz"][0]), float(a["band_hz"][1])) if a["band_hz"] else None
        settings = IdentifySettings(str(a["method"]), int(a["max_modes"]), band,
                                    float(a["agreement"]), float(a["max_damping"]))
        return plan, settings, str(a["family"]), float(a["premise_threshold"])
    except (KeyError, TypeError) as err:
        raise PlanError(f"the recorded setup is incomplete: {err!r}") from None


def decays_of(index: int, data: PoseData) -> list[Decay]:
    """The free decays of a pose: accelerometer samples after each MOTION_END up to its END,
    times from MOTION_END."""
    t = np.asarray(data.imu_t, dtype=float)
    y = np.asarray(data.imu, dtype=float).reshape(-1, 3)
    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    ends = {rep: s for kind, rep, s in data.events if kind == END}
    out = []
    for kind, rep, stamp in sorted(data.events, key=lambda e: (e[1], e[0])):
        if kind != MOTION_END or rep not in ends:
            continue
        sel = (t > stamp) & (t <= ends[rep])
        out.append(Decay(index, rep, t[sel] - stamp, y[sel]))
    return out


def pose_sensor_fault(data: PoseData, max_abs: float = MAX_ABS_ACCEL) -> str | None:
    """Why a pose's accelerometer cannot be trusted, or None: per excitation (START to END, the motion and its
    decay) no sample (silent), non-finite samples, every axis on one value (stuck or dead: a working sensor's
    reading moves with the motion and its noise), or samples at or beyond ``max_abs`` m/s^2 (saturated).
    The words are :func:`.core.learning.samples.sensor_fault`'s, the identifier's and learners' check."""
    t = np.asarray(data.imu_t, dtype=float)
    y = np.asarray(data.imu, dtype=float).reshape(-1, 3)
    starts = {rep: s for kind, rep, s in data.events if kind == START}
    for kind, rep, end in sorted(data.events, key=lambda e: (e[1], e[0])):
        if kind != END:
            continue
        begin = starts.get(rep, min((s for k, r, s in data.events if r == rep), default=end))
        window = y[(t >= begin) & (t <= end)]
        why = sensor_fault(window)
        over = out_of_range(window, max_abs) if why is None else None
        if over is not None:
            why = over.describe("accelerometer", "m/s^2", "saturated")
        if why is not None:
            return f"excitation {rep + 1}: {why}"
    return None


def compute(setup: dict[str, Any], poses: Sequence[PoseData], workers: int = 1) -> Calibration:
    """The pose map from the recorded samples, and the rule base, fallback and predictions it gives.

    A pose whose accelerometer failed (:func:`pose_sensor_fault`) is not identified: its result has no
    mode and the flag ``sensor_fault: ...`` (so it is not OK, and its place in the rule base takes its
    neighbour's modes, as for any pose without modes). ``workers`` > 1 identifies poses in that many
    processes (:func:`worker_pool`); the result does not depend on it."""
    plan, settings, family, threshold = plan_from_setup(setup)
    by_index = {p.index: p for p in poses}
    steps = [step for step in plan.steps if step.index in by_index]
    jobs = [(step, by_index[step.index], settings) for step in steps]
    if workers > 1 and len(jobs) > 1:
        with worker_pool(min(workers, len(jobs))) as pool:
            results = list(pool.map(identify_recorded, *zip(*jobs, strict=True)))
    else:
        results = [identify_recorded(*job) for job in jobs]
    return assemble(plan, settings, family, threshold, results, wiring_of(setup))


def identify_recorded(step: PoseStep, data: PoseData, settings: IdentifySettings) -> PoseResult:
    """One pose's result from its recorded samples: its modes (:func:`.core.calibration.identify_pose` on its
    free decays), or, when its accelerometer failed (:func:`pose_sensor_fault`), none and the flag
    ``sensor_fault: ...``."""
    fault = pose_sensor_fault(data)
    if fault is not None:
        return PoseResult(step.index, step.name, np.asarray(step.pose, float), step.grid_index, [], [],
                          [f"{SENSOR_FAULT}: {fault}"])
    return identify_pose(step.index, step.name, step.pose, step.grid_index, decays_of(step.index, data), settings)


def identify_folder(folder: pathlib.Path, setup: dict[str, Any]) -> tuple[dict[str, Any], PoseResult]:
    """One completed pose's bag read and identified (:func:`identify_recorded`) on the plan and settings of the
    setup it was recorded with (``setup`` if it holds none), as :func:`compute` does on the whole recording;
    returns that setup and the result (:class:`.calibration_pool.PosePipeline` runs it in a worker)."""
    recorded, data = read_pose(folder)
    setup = setup if recorded is None else recorded
    plan, settings, _, _ = plan_from_setup(setup)
    (step,) = [s for s in plan.steps if s.index == data.index]
    return setup, identify_recorded(step, data, settings)


def assemble(plan: Plan, settings: IdentifySettings, family: str, threshold: float, results: list[PoseResult],
             wiring: Mapping[str, str] | None = None) -> Calibration:
    """The calibration from the poses' identified modes: the rule base and the fallback (when every pose
    of the plan was measured), the notes, and the residuals predicted at every pose."""
    notes: list[str] = []
    spec = None
    shaper = None
    if len(results) == len(plan.steps):
        try:
            spec, notes = rule_base_spec(plan, results, family, threshold)
        except PlanError as err:
            notes.append(f"no rule base: {err}")
        try:
            shaper = fallback(results, family)[0]
        except PlanError as err:
            notes.append(f"no fallback shaper: {err}")
    residuals = _residuals(plan, results, spec, shaper, family)
    return Calibration(plan, settings, family, results, spec, notes, shaper, residuals,
                       {**WIRING, **(wiring or {})})


def _scheduler(spec: dict[str, Any], family: str) -> Scheduler:
    return Scheduler(rule_base_from_dict(spec), "modes", family)


def _residuals(plan: Plan, results: list[PoseResult], spec: dict[str, Any] | None, shaper: Shaper | None,
               family: str) -> list[dict[str, float]]:
    """Per pose: the residual vibration predicted for the fixed (home) shaper and the scheduled one,
    on the pose's identified modes (amplitude-weighted V), and each one's worst case over the modes'
    +-2 sigma (``fixed_worst_2sigma``, ``scheduled_worst_2sigma``: like is compared with like)."""
    out = []
    sched = _scheduler(spec, family) if spec is not None else None
    names = list(plan.config.joint_names)
    for r in results:
        row: dict[str, float] = {}
        if shaper is not None and r.modes:
            row["fixed"] = predicted_residual(shaper, r.modes)
            row["fixed_worst_2sigma"] = worst_residual(shaper, r.modes, 2.0)
        if sched is not None and r.modes:
            z = [float(r.positions[names.index(p)]) for p in sched.rule_base.premises]
            s = sched.shaper(sched.evaluate(z))
            row["scheduled"] = predicted_residual(s, r.modes)
            row["scheduled_worst_2sigma"] = worst_residual(s, r.modes, 2.0)
        out.append(row)
    return out


# --------------------------------------------------------------------------- reading a recording
def pose_folders(recording: pathlib.Path) -> list[pathlib.Path]:
    """The completed poses' bags of a recording folder, in order (``*.partial`` are not complete)."""
    return sorted(p for p in recording.glob("pose_[0-9][0-9][0-9]") if (p / "metadata.yaml").exists())


def read_recording(recording: str | pathlib.Path) -> tuple[dict[str, Any], list[PoseData]]:
    """The recorded setup and per-pose samples of a calibration recording folder (the accelerometer:
    its sensor_msgs/Imu topic).

    Raises
    ------
    PlanError
        No completed pose, no setup, or poses recorded under different setups.
    """
    path = pathlib.Path(recording)
    folders = pose_folders(path)
    if not folders:
        raise PlanError(f"{path} holds no completed pose (pose_NNN bags with metadata.yaml)")
    setup: dict[str, Any] | None = None
    poses = []
    for folder in folders:
        this, data = read_pose(folder)
        if this is not None:
            if setup is not None and this != setup:
                raise PlanError(f"{folder.name} was recorded with another setup than the poses before it")
            setup = this
        poses.append(data)
    if setup is None:
        raise PlanError(f"{path}: no {SETUP_TOPIC} message: not a calibration recording")
    return setup, poses


def read_pose(folder: pathlib.Path) -> tuple[dict[str, Any] | None, PoseData]:
    """One completed pose's bag (``pose_NNN``): the setup it was recorded with (None if it has none; the last
    if several) and its samples."""
    from shaper_nodes.recordings import Bag

    data = PoseData(int(folder.name.split("_")[1]))
    setup: dict[str, Any] | None = None
    with Bag(folder) as bag:
        imus = [t for t, i in bag.topics.items() if i.msgtype == "sensor_msgs/msg/Imu"]
        if len(imus) != 1:
            raise PlanError(f"{folder.name}: expected one sensor_msgs/Imu topic, found {imus}")
        imu_topic = imus[0]
        decode = {t: bag.deserializer(i.msgtype) for t, i in bag.topics.items()
                  if t in (SETUP_TOPIC, EVENTS_TOPIC, imu_topic)}
        for topic, _, _, raw in bag.messages([SETUP_TOPIC, EVENTS_TOPIC, imu_topic]):
            msg = decode[topic](raw)
            if topic == SETUP_TOPIC:
                this = json.loads(msg.data)
                if setup is not None and this != setup:
                    raise PlanError(f"{folder.name} was recorded with another setup than the poses before it")
                setup = this
            elif topic == EVENTS_TOPIC:
                data.events.append((int(msg.event), int(msg.cycle), stamp_to_sec(msg.header.stamp)))
            else:
                a = msg.linear_acceleration
                data.imu_t.append(stamp_to_sec(msg.header.stamp))
                data.imu.append((a.x, a.y, a.z))
    return setup, data


# --------------------------------------------------------------------------- outputs
def _r(x: float, digits: int = DIGITS) -> float:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else x


def _mode_dict(m: Any) -> dict[str, float]:
    return {"frequency_hz": _r(m.hz), "frequency_hz_std": _r(m.omega_std / (2 * math.pi), 3),
            "damping_ratio": _r(m.zeta), "damping_ratio_std": _r(m.zeta_std, 3), "amplitude": _r(m.amplitude, 4)}


def _sensor_fault(r: PoseResult) -> str | None:
    return next((f[len(SENSOR_FAULT) + 2:] for f in r.flags if f.startswith(SENSOR_FAULT + ": ")), None)


def sensor_faults(cal: Calibration | Sequence[PoseResult]) -> list[tuple[int, str, str]]:
    """The poses whose accelerometer failed: (index, name, why) each, in pose order (of a calibration or of
    its poses' results)."""
    results = cal.results if isinstance(cal, Calibration) else cal
    return [(r.index, r.name, why) for r in results if (why := _sensor_fault(r)) is not None]


def report_dict(cal: Calibration) -> dict[str, Any]:
    """report.json: plan, settings, per pose its positions, modes (one-sigma) and flags, the choices."""
    names = list(cal.plan.config.joint_names)
    poses = []
    for r, res in zip(cal.results, cal.residuals, strict=True):
        poses.append({"index": r.index, "name": r.name,
                      "grid_index": None if r.grid_index is None else list(r.grid_index),
                      "positions": {j: _r(float(v)) for j, v in zip(names, r.positions, strict=True)},
                      "modes": [_mode_dict(m) for m in r.modes],
                      "repeats": [[{"frequency_hz": _r(m.hz), "damping_ratio": _r(m.zeta)} for m in rep]
                                  for rep in r.repeats],
                      "flags": list(r.flags), "ok": r.ok and not _sensor_fault(r),
                      "sensor_fault": _sensor_fault(r),
                      "predicted_residual": {k: _r(v, 4) for k, v in res.items()}})
    s = cal.settings
    out: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "complete": len(cal.results) == len(cal.plan.steps),
        "plan": plan_to_dict(cal.plan),
        "identification": {"method": s.method, "max_modes": s.max_modes, "band_hz": s.band_hz,
                           "max_damping": s.max_damping, "agreement": s.agreement,
                           "uncertainty": "one sigma: the Jacobian covariance of each decay's fit with the spread"
                                          " over analysis variants added, and the spread between repeats"},
        "poses": poses,
        "flagged_poses": [r.name for r in cal.results if not r.ok or r.flags],
        "notes": list(cal.notes),
    }
    if cal.rule_base is not None:
        out["scheduler"] = {"premises": cal.rule_base["premises"], "rules": len(cal.rule_base["rules"]),
                            "family": cal.family, "interpolation": "modes"}
    if cal.fallback is not None:
        out["fallback"] = {"family": cal.fallback.family, "pose": "home",
                           "frequencies_hz": [_r(m.omega / (2 * math.pi)) for m in cal.fallback.modes],
                           "damping_ratios": [_r(m.zeta) for m in cal.fallback.modes],
                           "duration_s": _r(cal.fallback.duration)}
    return out


def _floats(values: Sequence[float]) -> str:
    """A YAML flow list of floats that every YAML reader takes as floats (1e-05 alone reads as a string)."""
    def one(x: float) -> str:
        text = repr(_r(float(x)))
        mantissa, _, exponent = text.partition("e")
        return f"{mantissa}.0e{exponent}" if exponent and "." not in mantissa else text
    return "[" + ", ".join(one(x) for x in values) + "]"


def _controller_ns(action: str) -> str | None:
    """The controller's namespace of a FollowJointTrajectory action named ``<ns>/follow_joint_trajectory``
    (``/joint_trajectory_controller``), else None."""
    head, _, tail = action.rpartition("/")
    return head if tail == "follow_joint_trajectory" and head.startswith("/") else None


def scheduler_yaml(cal: Calibration, node: str = "/**") -> str:
    """The scheduler node's parameter file for the calibrated rule base (keyed ``/**`` by default: it
    applies whatever the scheduler node is named): the rule base, the joint states topic the calibration
    read and the shaper node the shapers go to."""
    assert cal.rule_base is not None
    spec = cal.rule_base
    w = cal.wiring
    lines = [f"# Scheduler rule base from a calibration ({len(cal.results)} poses): ros2 run shaper_nodes scheduler",
             "# --ros-args --params-file scheduler.yaml. Premises: joint positions, rad; frequency_hz in Hz,",
             "# one per mode (sorted by frequency); damping_ratio dimensionless.",
             f"{node}:", "  ros__parameters:",
             f"    joint_states: {json.dumps(w['joint_states'])}   # the topic the calibration read the pose from",
             f"    shaper: {json.dumps(w['shaper_node'])}   # the shaper node (its set_shaper)",
             f"    premises: {json.dumps(spec['premises'])}",
             f"    range: {_floats(spec['range'])}",
             "    interpolation: modes",
             f"    family: {cal.family}",
             f"    rule_names: {json.dumps(list(spec['rules']))}",
             "    rules:"]
    for name, rule in spec["rules"].items():
        lines += [f"      {name}:",
                  f"        membership: {json.dumps(rule['membership'])}",
                  f"        membership_params: {_floats(rule['membership_params'])}",
                  f"        frequency_hz: {_floats([w / (2 * math.pi) for w in rule['natural_frequency']])}",
                  f"        damping_ratio: {_floats(rule['damping_ratio'])}"]
    return "\n".join(lines) + "\n"


def shaper_yaml(cal: Calibration, node: str = "/**") -> str:
    """The shaper node's parameters (keyed ``/**`` by default: they apply whatever the shaper node is
    named): the calibrated joints; the controller the calibration moved the arm with (its
    FollowJointTrajectory action and, in its namespace, its trajectory topic); with a rule base,
    ``action.scheduler`` (each goal shaped for the modes at its final pose); and the fixed fallback,
    the family's shaper on the home pose's modes, active for streamed commands and for goals when the
    scheduler does not answer."""
    assert cal.fallback is not None
    modes = cal.fallback.modes
    w = cal.wiring
    ns = _controller_ns(w["action"])
    how = (["# shaper.yaml. Each goal to <node>/follow_joint_trajectory is shaped for the modes at its final pose",
            "# (the scheduler's, started with scheduler.yaml; when it does not answer, with the fixed shaper below:",
            "# the home pose's modes) and forwarded to the controller."] if cal.rule_base is not None
           else ["# shaper.yaml. Each goal to <node>/follow_joint_trajectory is shaped with the fixed shaper below",
                 "# (the home pose's modes) and forwarded to the controller."])
    lines = ["# The shaper node from a calibration: ros2 run shaper_nodes shaper_node --ros-args --params-file",
             *how, "# Frequencies Hz, damping ratios dimensionless.",
             f"{node}:", "  ros__parameters:",
             f"    joint_names: {json.dumps(list(cal.plan.config.joint_names))}",
             "    action:",
             f"      controller: {json.dumps(w['action'])}   # the action the calibration moved the arm with"]
    if cal.rule_base is not None:
        lines.append(f"      scheduler: {json.dumps(w['scheduler_node'])}")
    if ns is not None:
        lines += ["    topics:   # the controller's trajectory topic, for trajectories and streams sent to the shaper",
                  f"      trajectory_out: {json.dumps(ns + '/joint_trajectory')}",
                  f"      stream_out: {json.dumps(ns + '/joint_trajectory')}"]
    lines += ["    shaper:",
              f"      family: {cal.fallback.family}",
              f"      frequencies_hz: {_floats([m.omega / (2 * math.pi) for m in modes])}",
              f"      damping_ratios: {_floats([m.zeta for m in modes])}"]
    return "\n".join(lines) + "\n"
