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
(the scheduler node's parameters) and shaper.yaml (the shaper node's fallback parameters; the JSON and YAML
texts are :mod:`.calibration_outputs`'),
each written to a temporary name and renamed, so a folder never holds half a file.
"""

from __future__ import annotations

import json
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
from shaper_nodes.core.calibration.plan import PlanError, config_from_dict, config_to_dict
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL, out_of_range, sensor_fault
from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict
from shaper_nodes.core.shaping import Shaper
from shaper_nodes.core.stamps import stamp_to_sec

from .worker_pool import worker_pool

SETUP_TOPIC = "/calibrate/setup"
EVENTS_TOPIC = "/calibrate/events"
#: event kinds (shaper_msgs/CycleEvent)
START, MOTION_END, END = 0, 1, 2
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


def _no_pose(path: pathlib.Path) -> str:
    """Why ``path`` is not a calibration recording, naming what it is where that is plain (the owner's
    mistakes: a wrong path, the output folder instead of its recording/, one recording of another kind)."""
    wanted = "a calibration's recording folder (the recording/ that calibrate --execute writes)"
    if not path.exists():
        return f"{path}: no such folder; --from-bag takes {wanted}"
    if path.is_file() or (path / "metadata.yaml").exists():
        return (f"{path} is a single recording, not {wanted}, whose poses are pose_NNN recordings;"
                " analyze_bag analyses a single recording")
    if pose_folders(path / "recording"):
        return f"{path} holds no completed pose; its recording/ does: --from-bag {path / 'recording'}"
    return f"{path} holds no completed pose (pose_NNN bags with metadata.yaml)"


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
        raise PlanError(_no_pose(path))
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
    from shaper_nodes.recordings.cdr import imu_fast, little_endian

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
            if topic == imu_topic and little_endian(raw):  # most of a pose's messages: the fields read in place
                t, a = imu_fast(raw)
                data.imu_t.append(t)
                data.imu.append(a)
                continue
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
