"""The sim plant node's parameters: the class :class:`SimPlantParams` (names, defaults, ranges, units,
descriptions, the plant's own check of a value; one group a concept), from which the node declares them
and reads them typed, its table :data:`PARAMETERS`, and the names of the ones that rebuild the plant.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rclpy.parameter import Parameter

from shaper_nodes.core.learning.mrilc import PAPER_CONTROLLER
from shaper_nodes.ros.parameters import Spec, param, table, topic

from ..arm.description import MAX_PAYLOAD_MASS, MAX_PAYLOAD_OFFSET, PAYLOAD_MASS, PAYLOAD_OFFSET
from ..models.loops import LOOP_MODELS, LOOP_PARAMS, check_loop_value
from ..models.plants import (
    LIST_FORCE_LIMIT,
    LIST_GAIN,
    LIST_STIFFNESS_CUBIC,
    PLANT_MODELS,
    check_rate,
    check_task,
    plant_values,
)
from ..models.two_mass import StaircaseTask

__all__ = ["MODELS", "PARAMETERS", "PLANT_KEYS", "PLANT_PARAMS", "WAITING", "SimPlantParams", "check_model"]

# per-joint plant values, in make_plant's order; with plant.model, what rebuilds the plant
PLANT_PARAMS = ("plant.mass", "plant.damping", "plant.stiffness", "plant.stiffness_cubic", "plant.gain",
                "plant.force_limit")
PLANT_KEYS = ("plant.model", "controller.numerator", "controller.denominator", *PLANT_PARAMS, *LOOP_PARAMS)
MODELS = (*PLANT_MODELS, "mck_pid", *LOOP_MODELS, "two_mass", "arm")
#: how ~/start_task's refusal begins while task.subscribers are not matched yet (a driver may retry)
WAITING = "waiting for subscribers"


def check_model(model: str) -> str:
    """The node's check of ``plant.model``: one of :data:`MODELS`."""
    if model not in MODELS:
        raise ValueError(f"plant.model must be one of {', '.join(MODELS)}; got {model!r}")
    return model


def _task_check(setting: str) -> Callable[[Any], None]:
    """:func:`check_task` on a value of one of its settings."""
    return lambda value: check_task(**{setting: value})


def _levels_check(levels: Any) -> None:
    """:class:`StaircaseTask`'s check of ``task.levels`` (for one joint)."""
    StaircaseTask([0.0], levels, 1.0, 1.0)



def _loop(name: str) -> Any:
    """The field of loop parameter ``name`` (default and description from :data:`LOOP_PARAMS`, checked by
    :func:`check_loop_value`)."""
    default, text = LOOP_PARAMS[name]
    return param(default, text, check=functools.partial(check_loop_value, name))


def _per_joint(key: str, default: float, text: str) -> Any:
    """The field of plant value ``plant.<key>`` (one per joint, or one for all; checked by :func:`plant_values`)."""
    return param([default], text, check=functools.partial(plant_values, key))


@dataclass(frozen=True)
class LockstepParams:
    """``lockstep.*``: the exchange with the shaper in lockstep."""

    block: int = param(1, "Lockstep, a task running: steps per exchange with the shaper. 1: one raw setpoint"
                       " per message, as forward_command_controller takes; N > 1: the raw setpoints of the next N"
                       " steps go out as one Float64MultiArray with layout [samples, joints], and the plant steps"
                       " through the shaped block that comes back (the same setpoints, N times fewer round trips)."
                       " Only for a feedforward command path: what the plant does within a block cannot change the"
                       " block's setpoints, and a shaper change takes effect at a block's boundary.", (1, 1000),
                       read_only=True)
    readers: tuple[str, ...] = param(None, "Lockstep: the nodes (fully qualified names, e.g. /recorder) whose"
                                     " processing the plant waits for: each acknowledges the simulated time it has"
                                     " processed on <node>/lockstep_ack (shaper_nodes.ros.lockstep_reader), and the"
                                     " plant never steps more than lockstep.lead beyond the slowest. Empty: it waits"
                                     " for none.", type=Parameter.Type.STRING_ARRAY, read_only=True)
    lead: float = param(0.25, "Lockstep with readers: how far the plant may run beyond the slowest reader's"
                        " acknowledgement, s of simulated time (the readers' reliable queues hold 10 s).",
                        (0.001, 5.0), read_only=True)
    reader_timeout: float = param(30.0, "Lockstep with readers: wall time the plant waits for a reader that holds"
                                  " it before it steps on without it (one line names it), s. A reader whose"
                                  " acknowledgements go away (the process ended) is dropped at once.",
                                  (0.1, 3600.0), read_only=True)


@dataclass(frozen=True)
class PlantParams:
    """``plant.*``: the model and its per-joint values (:data:`PLANT_PARAMS`)."""

    model: str = param("mck",
                       "Plant model: 'mck' (base-driven flexible joint), or the LIST cases (seed 003) 'list_linear',"
                       " 'list_time_varying', 'list_hardening', 'list_saturation', or 'mck_pid' (mck in a feedback"
                       " loop, seed 000), or the closed loops of seeds 001, 002 (see loop.*) 'delay_loop', 'qft_open',"
                       " 'qft_fb', 'qft_ffb', or seed 004's two-mass system 'two_mass' (m1 = 10 x0 + 1), or the"
                       " six-axis elastic-joint arm 'arm' (docs/arm.md; chosen at start-up only, with joint_names its"
                       " six joints or left at the default). Changes live, keeping the state when the models share"
                       " it.", check=check_model)
    mass: tuple[float, ...] = _per_joint(
        "mass", 1.0, "Tip mass per joint (one value for all), kg (or kg m^2), > 0; list_time_varying: the mass at a"
        " cycle's START, m(t) = mass (1 + t) for t < 1 s, 2 mass after.")
    damping: tuple[float, ...] = _per_joint(
        "damping", 0.6283185307179586,
        "Damping per joint, N s/m (or N m s/rad), >= 0: between base and tip for mck, to ground for list_*.")
    stiffness: tuple[float, ...] = _per_joint(
        "stiffness", 986.96044010893586, "Linear stiffness per joint, N/m (or N m/rad), > 0 (unused by"
        " list_saturation).")
    stiffness_cubic: tuple[float, ...] = _per_joint(
        "stiffness_cubic", LIST_STIFFNESS_CUBIC, "list_hardening: cubic stiffness k3 per joint, spring force"
        " k d + k3 d^3 (d = u - x), N/m^3 (or N m/rad^3), >= 0.")
    gain: tuple[float, ...] = _per_joint(
        "gain", LIST_GAIN, "list_saturation: P gain Kp per joint, force Kp (u - x) before the limit, N/m (or N m/rad),"
        " > 0.")
    force_limit: tuple[float, ...] = _per_joint(
        "force_limit", LIST_FORCE_LIMIT, "list_saturation: actuator force limit f_max per joint, N (or N m), > 0"
        " (.inf: none).")


@dataclass(frozen=True)
class ArmParams:
    """``arm.*``: the six-axis arm (plant.model arm)."""

    substeps: int = param(2, "plant.model arm: physics steps per period; the flange IMU publishes at each,"
                          " rate x arm.substeps Hz (1 kHz by default).", (1, 100), read_only=True)
    payload_mass: float = param(PAYLOAD_MASS, "plant.model arm: payload at the flange (gripper and part), kg;"
                                " changes live (a part picked up, a tool changed): the inertia, gravity and modes"
                                " follow at the next step, the arm swings under the new load (docs/arm.md).",
                                (0.0, MAX_PAYLOAD_MASS))
    payload_offset: float = param(PAYLOAD_OFFSET, "plant.model arm: the payload's centre of mass along the"
                                  " flange's z, m; changes live with arm.payload_mass.", (0.0, MAX_PAYLOAD_OFFSET))


@dataclass(frozen=True)
class JtcParams:
    """``jtc.*``: the joint_trajectory_controller emulation's default tolerances (plant.model arm)."""

    trajectory_tolerance: tuple[float, ...] = param(
        [0.0], "plant.model arm, the joint_trajectory_controller emulation: path position tolerance per joint (or"
        " one for all), rad, 0 unchecked (constraints.<joint>.trajectory).", read_only=True)
    goal_tolerance: tuple[float, ...] = param(
        [0.0], "Goal position tolerance per joint, rad, 0 unchecked (constraints.<joint>.goal).", read_only=True)
    goal_time: float = param(0.0, "Time after the trajectory's end to reach the goal tolerance, s, 0: wait"
                             " indefinitely (constraints.goal_time).", (0.0, 3600.0), read_only=True)


@dataclass(frozen=True)
class JointStatesParams:
    """``joint_states.*``: the encoders (:class:`~.sensors.Sensors`) and the republishing at rest."""

    noise_stddev: float = param(0.0, "White noise on the reported joint positions, rad or m (one sigma).",
                                (0.0, 1.0))
    resolution: float = param(0.0, "Encoder quantum of the reported joint positions, rad or m (0: none).",
                              (0.0, 1.0))
    idle_period: float = param(-1.0, "Lockstep, at rest (no task, no trajectory): the last joint state is"
                               " published again every this many s of wall time, as a joint_state_broadcaster keeps"
                               " publishing (simulated time stands still, so the stamp repeats); 0: never; negative:"
                               " 0.1 for the arm, never for other plants.", (-1.0, 60.0), read_only=True)


@dataclass(frozen=True)
class LoopParams:
    """``loop.*``: the closed-loop models (:data:`LOOP_PARAMS` holds their defaults and descriptions)."""

    substeps: int = _loop("loop.substeps")
    assumed_frequency: float = _loop("loop.assumed_frequency")
    delay: float = _loop("loop.delay")
    gain: float = _loop("loop.gain")
    nominal: tuple[float, ...] = _loop("loop.nominal")
    disturbance_step: float = _loop("loop.disturbance_step")
    disturbance_time: float = _loop("loop.disturbance_time")
    noise_step: float = _loop("loop.noise_step")
    noise_time: float = _loop("loop.noise_time")
    noise_stddev: float = _loop("loop.noise_stddev")
    seed: int = _loop("loop.seed")


@dataclass(frozen=True)
class ControllerParams:
    """``controller.*``: mck_pid's feedback controller C(s)."""

    numerator: tuple[float, ...] = param(list(PAPER_CONTROLLER[0]), "mck_pid: feedback controller C(s) numerator,"
                                         " highest power first (default seed 000 eq. 13).")
    denominator: tuple[float, ...] = param(list(PAPER_CONTROLLER[1]), "mck_pid: C(s) denominator.")


@dataclass(frozen=True)
class ImuParams:
    """``imu.*``: the accelerometer (and the arm's gyro; :class:`~.sensors.Sensors`)."""

    axes: tuple[int, ...] = param([0, 1, 2], "Joint index whose tip acceleration each IMU axis x, y, z measures"
                                  " (-1: none); plant.model arm: the flange's specific force (gravity included) in"
                                  " the flange frame.")
    noise_stddev: float = param(0.0, "Accelerometer white noise, m/s^2 (one sigma).", (0.0, 1000.0))
    bias: tuple[float, ...] = param([0.0, 0.0, 0.0], "Accelerometer constant offset per axis, m/s^2.")
    gyro_noise_stddev: float = param(0.0, "plant.model arm: gyro white noise, rad/s (one sigma).", (0.0, 100.0))
    gyro_bias: tuple[float, ...] = param([0.0, 0.0, 0.0], "plant.model arm: gyro constant offset per axis, rad/s.")
    frame_id: str = param("tool0", "frame_id of the Imu messages.", read_only=True)
    seed: int = param(1, "Seed of the noise generator.", read_only=True)


@dataclass(frozen=True)
class TaskParams:
    """``task.*``: the repeated task (:func:`~.models.make_task`) and when a run starts."""

    name: str = param("point_to_point", "Task name in cycle events.")
    start: tuple[float, ...] = param([0.0], "Start pose, one value per joint (or one for all), rad or m.")
    goal: tuple[float, ...] = param([0.5], "Goal pose, rad or m.")
    max_velocity: float = param(1.0, "Largest joint velocity of a move, rad/s or m/s.", (1e-6, 1e6),
                                check=_task_check("max_velocity"))
    max_acceleration: float = param(10.0, "Largest joint acceleration of a move, rad/s^2 or m/s^2.", (1e-6, 1e9),
                                    check=_task_check("max_acceleration"))
    dwell: float = param(2.0, "Dwell after each move (the residual-vibration window), s.", (0.0, 3600.0),
                         check=_task_check("dwell"))
    levels: tuple[float, ...] = param(
        None, "If set, a staircase instead of moves: the command steps to each level in turn (one cycle per step,"
        " task.dwell each; steps x joints values), e.g. seed 004's velocity steps (plant.model two_mass).",
        type=Parameter.Type.DOUBLE_ARRAY, check=_levels_check)
    profile: str = param("trapezoid", "Move profile: 'trapezoid' (within max_velocity and max_acceleration), 'step'"
                         " (jump to the target) or 'ramp' (constant max_velocity).", check=_task_check("profile"))
    round_trip: bool = param(False, "Every cycle goes start -> goal -> start (each with a dwell), so all cycles are"
                             " the same; otherwise cycles alternate between the poses.")
    cycles: int = param(4, "Cycles per run (started by ~/start_task).", check=_task_check("cycles"))
    preroll: float = param(1.0, "Rest at the start pose before the first cycle, s.", (0.0, 3600.0))
    autostart: bool = param(False, "Start a run as soon as the node is up.", read_only=True)
    subscribers: int = param(0, "Start a run only once the cycle events reach at least this many matched"
                             " subscriptions (0: at once); until then ~/start_task refuses with 'waiting for"
                             " subscribers'. A test driver sets it so that a learner started just before cannot miss"
                             " the first START.", (0, 64))


@dataclass(frozen=True)
class TopicsParams:
    """``topics.*``: the node's topic names (read-only)."""

    command_out: str = topic("/shaper/commands", "command_out")
    command_in: str = topic("/forward_position_controller/commands", "command_in")
    joint_states: str = topic("/joint_states", "joint_states")
    tip_state: str = topic("~/tip_state", "tip_state")
    imu: str = topic("/tip_imu", "imu")
    cycle_events: str = topic("/cycle_events", "cycle_events")
    cycle_reports: str = topic("/cycle_reports", "cycle_reports")
    active_shaper: str = topic("/shaper/active_shaper", "active_shaper")
    reference: str = topic("~/reference", "reference")
    jtc_action: str = topic("/joint_trajectory_controller/follow_joint_trajectory", "jtc_action")
    jtc_topic: str = topic("/joint_trajectory_controller/joint_trajectory", "jtc_topic")


@dataclass(frozen=True)
class SimPlantParams:
    """Every parameter of the sim plant node (``check``: the plant's own check of one value)."""

    joint_names: tuple[str, ...] = param(["joint_1"], "Joint names, one m-c-k plant each.", read_only=True)
    rate: float = param(500.0, "Integration and command rate, Hz.", (1.0, 10000.0), read_only=True, check=check_rate)
    mode: str = param("lockstep", "'lockstep' (simulated time, /clock) or 'realtime' (wall clock).", read_only=True)
    lockstep_timeout: float = param(2.0, "Lockstep: wall time to wait for the shaped setpoint, s.", (0.01, 600.0))
    lockstep: LockstepParams = field(default_factory=LockstepParams)
    plant: PlantParams = field(default_factory=PlantParams)
    arm: ArmParams = field(default_factory=ArmParams)
    jtc: JtcParams = field(default_factory=JtcParams)
    joint_states: JointStatesParams = field(default_factory=JointStatesParams)
    loop: LoopParams = field(default_factory=LoopParams)
    controller: ControllerParams = field(default_factory=ControllerParams)
    imu: ImuParams = field(default_factory=ImuParams)
    task: TaskParams = field(default_factory=TaskParams)
    settle_tolerance: float = param(1e-6, "Joint positions within this of their final value count as at rest, rad"
                                    " or m.", (0.0, 1.0))
    topics: TopicsParams = field(default_factory=TopicsParams)


#: every parameter of the node, declared from :class:`SimPlantParams`
PARAMETERS: tuple[Spec, ...] = table(SimPlantParams)
