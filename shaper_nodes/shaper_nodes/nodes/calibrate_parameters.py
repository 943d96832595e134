"""The calibrate node's parameters (config/calibrate.yaml), and the plan and identification settings they give.

Split from :mod:`shaper_nodes.nodes.calibrate` (which imports them from here, as before) to keep the node
module short; the typed table is :data:`PARAMETERS`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rclpy.parameter import Parameter

from shaper_nodes.core.calibration import IdentifySettings, PlanConfig, PlanError
from shaper_nodes.core.calibration.plan import MAX_AMPLITUDE, make_limits
from shaper_nodes.recordings import COMPRESSIONS
from shaper_nodes.ros.parameters import Spec, param, table, unflat

__all__ = ["PARAMETERS", "CalibrateParams", "config_from_values", "settings_from_values"]

_SA, _DA = Parameter.Type.STRING_ARRAY, Parameter.Type.DOUBLE_ARRAY

@dataclass(frozen=True)
class TopicsParams:
    """The parameters topics.*."""

    joint_states: str = param("/joint_states", "Joint states (positions, rad): where the arm is.",
                              read_only=True)
    imu: str = param("/tip_imu", "Accelerometer (sensor_msgs/Imu, linear_acceleration m/s^2) on the tool.",
                     read_only=True)
    imu_reliable: bool = param(False, "Subscribe to the accelerometer RELIABLE (lossless from a reliable"
         " publisher such as the simulator in lockstep; a best-effort sensor driver does not match it)."
         " Default best effort, deep queue.", read_only=True)


@dataclass(frozen=True)
class LimitsParams:
    """The parameters limits.*."""

    lower: tuple[float, ...] = param([-2 * math.pi], "Lowest joint positions, rad (one per joint, or one for all).",
                                     read_only=True)
    upper: tuple[float, ...] = param([2 * math.pi], "Highest joint positions, rad.", read_only=True)
    max_velocity: tuple[float, ...] = param([math.pi], "Largest joint speeds, rad/s.", read_only=True)
    max_acceleration: tuple[float, ...] = param([15.0], "Largest joint accelerations, rad/s^2.", read_only=True)


@dataclass(frozen=True)
class GridParams:
    """The parameters grid.*."""

    joints: tuple[str, ...] = param(None, "Joints whose positions change the dynamics: the grid's axes (and the"
                                    " scheduler's premises).", read_only=True, type=_SA)
    lower: tuple[float, ...] = param(None, "Lowest grid value per grid joint, rad.", read_only=True, type=_DA)
    upper: tuple[float, ...] = param(None, "Highest grid value per grid joint, rad.", read_only=True, type=_DA)
    counts: tuple[int, ...] = param(None, "Grid values per grid joint (evenly spaced; the home pose's value is added).",
                                    read_only=True, type=Parameter.Type.INTEGER_ARRAY)


@dataclass(frozen=True)
class FollowParams:
    """The parameters follow.*."""

    joints: tuple[str, ...] = param(None, "Joints that move with the grid to keep the tool's orientation.",
                                    read_only=True, type=_SA)
    gains: tuple[float, ...] = param(None, "Per follow joint, one gain per grid joint: q_f = base_f + sum_j g_j (q_j -"
                                     " base_j).", read_only=True, type=_DA)


@dataclass(frozen=True)
class ExcitationParams:
    """The parameters excitation.*."""

    joints: tuple[str, ...] = param(None, "Joints moved by the excitation.", read_only=True, type=_SA)
    amplitude: tuple[float, ...] = param(
        None, f"Excursion per excitation joint, rad (signed, at most {MAX_AMPLITUDE:g}).",
        read_only=True, type=_DA)
    max_velocity: float = param(0.5, "Largest speed of the excitation, rad/s.", (1e-3, 10.0), read_only=True)
    max_acceleration: float = param(10.0, "Largest acceleration of the excitation, rad/s^2.", (1e-3, 100.0),
                                    read_only=True)
    repeats: int = param(3, "Excitations per pose.", (1, 10), read_only=True)
    decay: float = param(2.0, "Free vibration recorded after each excitation, s.", (0.2, 10.0),
                         read_only=True)


@dataclass(frozen=True)
class ApproachParams:
    """The parameters approach.*."""

    max_velocity: float = param(0.5, "Largest speed between poses, rad/s.", (1e-3, 10.0), read_only=True)
    max_acceleration: float = param(2.0, "Largest acceleration between poses, rad/s^2.", (1e-3, 100.0),
                                    read_only=True)
    settle: float = param(1.0, "Rest at a pose before its first excitation, s.", (0.0, 60.0), read_only=True)


@dataclass(frozen=True)
class IdentificationParams:
    """The parameters identification.*."""

    method: str = param("fit", "Identification method (fit, spectral, matrix_pencil).",
                        choices=("fit", "spectral", "matrix_pencil"), read_only=True)
    max_modes: int = param(4, "Most modes mapped per pose (one more is fitted beside them).", (1, 6),
                           read_only=True)
    band_hz: tuple[float, ...] = param([2.0, 45.0], "Band searched for modes [low, high], Hz.", read_only=True)
    max_damping: float = param(0.15, "Modes damped more than this are not mapped (they do not ring).",
                               (0.01, 0.9), read_only=True)
    agreement: float = param(0.02, "Largest relative spread of a mode's frequency over the repeats"
                             " before the pose is flagged.", (1e-4, 0.5), read_only=True)


@dataclass(frozen=True)
class SchedulerParams:
    """The parameters scheduler.*."""

    family: str = param("zv", "Shaper family of the rule base and the fallback.", read_only=True)
    premise_threshold: float = param(0.02, "A grid joint along which the modes change less than this"
                                     " (relative) is not a premise.", (0.0, 1.0), read_only=True)


@dataclass(frozen=True)
class TimeoutsParams:
    """The parameters timeouts.*."""

    server: float = param(30.0, "Wait for the action server, and for each goal's answer (at most timeouts.peer), s"
                          " (wall).", (0.1, 3600.0),
                          read_only=True)
    data: float = param(30.0, "Wait for joint states and accelerometer data, s (wall).", (0.1, 3600.0),
                        read_only=True)
    result: float = param(600.0, "Wait for a goal's result, s (wall).", (1.0, 36000.0), read_only=True)
    peer: float = param(10.0, "While a goal is sent or runs, the controller's silence that ends the run, s (wall):"
                        " no answer or feedback for this long, or its action server gone from the graph (at once), is"
                        " a dead or stalled controller (the DDS lease alone takes 20 s to notice a killed process).",
                        (0.5, 3600.0), read_only=True)


@dataclass(frozen=True)
class CalibrateParams:
    """The calibrate node's parameters (see config/calibrate.yaml)."""

    joint_names: tuple[str, ...] = param(None, "The controller's joints, in the order of every per-joint list below.",
                                         read_only=True, type=_SA)
    action: str = param("/joint_trajectory_controller/follow_joint_trajectory", "FollowJointTrajectory action to"
         " send the moves to (the controller's, or the shaper node's proxy with its shaper set to none).",
         read_only=True)
    topics: TopicsParams = field(default_factory=TopicsParams)
    limits: LimitsParams = field(default_factory=LimitsParams)
    base_pose: tuple[float, ...] = param(None, "Pose of the joints not on the grid, rad; empty: where the arm is now.",
                                         read_only=True, type=_DA)
    home_pose: tuple[float, ...] = param(
        None, "Home pose, rad (calibrated first; its modes give the fallback shaper; on the grid"
        " when inside its ranges); empty: base_pose.", read_only=True, type=_DA)
    grid: GridParams = field(default_factory=GridParams)
    poses: tuple[float, ...] = param(
        None, "Instead of a grid: explicit poses, rad, one after the other (len(joint_names) values"
        " each).", read_only=True, type=_DA)
    follow: FollowParams = field(default_factory=FollowParams)
    excitation: ExcitationParams = field(default_factory=ExcitationParams)
    approach: ApproachParams = field(default_factory=ApproachParams)
    identification: IdentificationParams = field(default_factory=IdentificationParams)
    scheduler: SchedulerParams = field(default_factory=SchedulerParams)
    compression: str = param("none", "MCAP chunk compression of the recording: 'zstd' compresses each chunk (as the"
         " recorder's compression), 'none' writes them as they are.", choices=COMPRESSIONS, read_only=True)
    timeouts: TimeoutsParams = field(default_factory=TimeoutsParams)


#: the calibrate node's parameters (derived from CalibrateParams; see config/calibrate.yaml)
PARAMETERS: tuple[Spec, ...] = table(CalibrateParams)


def config_from_values(v: CalibrateParams | Mapping[str, Any], here: np.ndarray | None) -> PlanConfig:
    """The plan's configuration from the node's parameters (or a mapping of them keyed by name, as a
    params file gives them; ``here``: the arm's pose now)."""
    p = v if isinstance(v, CalibrateParams) else unflat(CalibrateParams, v)
    names = p.joint_names
    if not names:
        raise PlanError("joint_names is empty: the controller's joints are needed")
    n = len(names)
    base = np.asarray(p.base_pose or (here if here is not None else []), dtype=float)
    if base.size == 0:
        raise PlanError("base_pose is empty and no joint states came to take the present pose")
    home = np.asarray(p.home_pose or base, dtype=float)
    grid = p.grid.joints
    follow_joints = list(p.follow.joints)
    gains = np.asarray(p.follow.gains, dtype=float)
    if follow_joints and gains.size != len(follow_joints) * len(grid):
        raise PlanError(f"follow.gains needs {len(grid)} gains per follow joint ({len(follow_joints) * len(grid)}"
                        f" values), got {gains.size}")
    follow = {j: tuple(gains[i * len(grid):(i + 1) * len(grid)]) for i, j in enumerate(follow_joints)}
    flat = np.asarray(p.poses, dtype=float)
    if flat.size % n:
        raise PlanError(f"poses needs {n} values per pose, got {flat.size} values")
    lim, exc, app = p.limits, p.excitation, p.approach
    return PlanConfig(
        names, make_limits(n, list(lim.lower), list(lim.upper), list(lim.max_velocity), list(lim.max_acceleration)),
        base, home, grid, p.grid.lower, p.grid.upper, tuple(int(c) for c in p.grid.counts),
        tuple(tuple(q) for q in flat.reshape(-1, n)), follow, exc.joints, exc.amplitude,
        float(exc.max_velocity), float(exc.max_acceleration), int(exc.repeats),
        float(exc.decay), float(app.max_velocity), float(app.max_acceleration), float(app.settle))


def settings_from_values(v: CalibrateParams | Mapping[str, Any]) -> IdentifySettings:
    """The identification settings from the node's parameters (or a mapping of them keyed by name)."""
    ident = (v if isinstance(v, CalibrateParams) else unflat(CalibrateParams, v)).identification
    band = [float(x) for x in ident.band_hz]
    if len(band) != 2 or not 0 <= band[0] < band[1]:
        raise PlanError(f"identification.band_hz must be [low, high] with 0 <= low < high, got {band}")
    return IdentifySettings(str(ident.method), int(ident.max_modes), (band[0], band[1]), float(ident.agreement),
                            float(ident.max_damping))
