"""The sim plant node's parameters: the table :data:`PARAMETERS` (names, defaults, ranges, units,
descriptions, the plant's own check of a value), from which the node declares them, and the groups
of them the node reads together.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from rclpy.parameter import Parameter

from shaper_nodes.core.learning.mrilc import PAPER_CONTROLLER
from shaper_nodes.ros.parameters import Spec, topics

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

__all__ = ["MODELS", "PARAMETERS", "PLANT_KEYS", "PLANT_PARAMS", "SENSOR_PARAMS", "WAITING", "check_model"]

# per-joint plant values, in make_plant's order; with plant.model, what rebuilds the plant
PLANT_PARAMS = ("plant.mass", "plant.damping", "plant.stiffness", "plant.stiffness_cubic", "plant.gain",
                "plant.force_limit")
PLANT_KEYS = ("plant.model", "controller.numerator", "controller.denominator", *PLANT_PARAMS, *LOOP_PARAMS)
MODELS = (*PLANT_MODELS, "mck_pid", *LOOP_MODELS, "two_mass", "arm")
#: sensor settings read at every sample: cached, and refreshed when they are set
SENSOR_PARAMS = ("imu.bias", "imu.noise_stddev", "imu.gyro_noise_stddev", "imu.gyro_bias", "imu.frame_id",
                 "joint_states.noise_stddev", "joint_states.resolution")
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


#: every parameter of the node, declared from here (``check``: the plant's own check of one value)
PARAMETERS: tuple[Spec, ...] = (
    Spec("joint_names", ["joint_1"], "Joint names, one m-c-k plant each.", read_only=True),
    Spec("rate", 500.0, "Integration and command rate, Hz.", (1.0, 10000.0), read_only=True, check=check_rate),
    Spec("mode", "lockstep", "'lockstep' (simulated time, /clock) or 'realtime' (wall clock).", read_only=True),
    Spec("lockstep_timeout", 2.0, "Lockstep: wall time to wait for the shaped setpoint, s.", (0.01, 600.0)),
    Spec("lockstep.block", 1, "Lockstep, a task running: steps per exchange with the shaper. 1: one raw setpoint"
         " per message, as forward_command_controller takes; N > 1: the raw setpoints of the next N steps go out as"
         " one Float64MultiArray with layout [samples, joints], and the plant steps through the shaped block that"
         " comes back (the same setpoints, N times fewer round trips). Only for a feedforward command path: what"
         " the plant does within a block cannot change the block's setpoints, and a shaper change takes effect"
         " at a block's boundary.", (1, 1000), read_only=True),
    Spec("plant.model", "mck",
         "Plant model: 'mck' (base-driven flexible joint), or the LIST cases (seed 003) 'list_linear',"
         " 'list_time_varying', 'list_hardening', 'list_saturation', or 'mck_pid' (mck in a feedback loop,"
         " seed 000), or the closed loops of seeds 001, 002 (see loop.*) 'delay_loop', 'qft_open', 'qft_fb',"
         " 'qft_ffb', or seed 004's two-mass system 'two_mass' (m1 = 10 x0 + 1), or the six-axis elastic-joint arm"
         " 'arm' (docs/arm.md; chosen at start-up only, with joint_names its six joints or left at the default)."
         " Changes live, keeping the state when the models share it.", check=check_model),
    Spec("arm.substeps", 2, "plant.model arm: physics steps per period; the flange IMU publishes at each,"
         " rate x arm.substeps Hz (1 kHz by default).", (1, 100), read_only=True),
    Spec("arm.payload_mass", PAYLOAD_MASS, "plant.model arm: payload at the flange (gripper and part), kg; changes"
         " live (a part picked up, a tool changed): the inertia, gravity and modes follow at the next step, the arm"
         " swings under the new load (docs/arm.md).", (0.0, MAX_PAYLOAD_MASS)),
    Spec("arm.payload_offset", PAYLOAD_OFFSET, "plant.model arm: the payload's centre of mass along the flange's"
         " z, m; changes live with arm.payload_mass.", (0.0, MAX_PAYLOAD_OFFSET)),
    Spec("jtc.trajectory_tolerance", [0.0],
         "plant.model arm, the joint_trajectory_controller emulation: path position tolerance per joint (or one"
         " for all), rad, 0 unchecked (constraints.<joint>.trajectory).", read_only=True),
    Spec("jtc.goal_tolerance", [0.0], "Goal position tolerance per joint, rad, 0 unchecked (constraints.<joint>.goal).",
         read_only=True),
    Spec("jtc.goal_time", 0.0, "Time after the trajectory's end to reach the goal tolerance, s, 0: wait indefinitely"
         " (constraints.goal_time).", (0.0, 3600.0), read_only=True),
    Spec("joint_states.noise_stddev", 0.0, "White noise on the reported joint positions, rad or m (one sigma).",
         (0.0, 1.0)),
    Spec("joint_states.resolution", 0.0, "Encoder quantum of the reported joint positions, rad or m (0: none).",
         (0.0, 1.0)),
    Spec("joint_states.idle_period", -1.0, "Lockstep, at rest (no task, no trajectory): the last joint state is"
         " published again every this many s of wall time, as a joint_state_broadcaster keeps publishing (simulated"
         " time stands still, so the stamp repeats); 0: never; negative: 0.1 for the arm, never for other plants.",
         (-1.0, 60.0), read_only=True),
    *(Spec(name, default, text, check=functools.partial(check_loop_value, name))
      for name, (default, text) in LOOP_PARAMS.items()),
    Spec("controller.numerator", list(PAPER_CONTROLLER[0]),
         "mck_pid: feedback controller C(s) numerator, highest power first (default seed 000 eq. 13)."),
    Spec("controller.denominator", list(PAPER_CONTROLLER[1]), "mck_pid: C(s) denominator."),
    Spec("plant.mass", [1.0],
         "Tip mass per joint (one value for all), kg (or kg m^2), > 0; list_time_varying: the mass at a"
         " cycle's START, m(t) = mass (1 + t) for t < 1 s, 2 mass after.",
         check=functools.partial(plant_values, "mass")),
    Spec("plant.damping", [0.6283185307179586],
         "Damping per joint, N s/m (or N m s/rad), >= 0: between base and tip for mck, to ground for list_*.",
         check=functools.partial(plant_values, "damping")),
    Spec("plant.stiffness", [986.96044010893586],
         "Linear stiffness per joint, N/m (or N m/rad), > 0 (unused by list_saturation).",
         check=functools.partial(plant_values, "stiffness")),
    Spec("plant.stiffness_cubic", [LIST_STIFFNESS_CUBIC],
         "list_hardening: cubic stiffness k3 per joint, spring force k d + k3 d^3 (d = u - x),"
         " N/m^3 (or N m/rad^3), >= 0.",
         check=functools.partial(plant_values, "stiffness_cubic")),
    Spec("plant.gain", [LIST_GAIN],
         "list_saturation: P gain Kp per joint, force Kp (u - x) before the limit, N/m (or N m/rad), > 0.",
         check=functools.partial(plant_values, "gain")),
    Spec("plant.force_limit", [LIST_FORCE_LIMIT],
         "list_saturation: actuator force limit f_max per joint, N (or N m), > 0 (.inf: none).",
         check=functools.partial(plant_values, "force_limit")),
    Spec("imu.axes", [0, 1, 2], "Joint index whose tip acceleration each IMU axis x, y, z measures (-1: none);"
         " plant.model arm: the flange's specific force (gravity included) in the flange frame."),
    Spec("imu.noise_stddev", 0.0, "Accelerometer white noise, m/s^2 (one sigma).", (0.0, 1000.0)),
    Spec("imu.bias", [0.0, 0.0, 0.0], "Accelerometer constant offset per axis, m/s^2."),
    Spec("imu.gyro_noise_stddev", 0.0, "plant.model arm: gyro white noise, rad/s (one sigma).", (0.0, 100.0)),
    Spec("imu.gyro_bias", [0.0, 0.0, 0.0], "plant.model arm: gyro constant offset per axis, rad/s."),
    Spec("imu.frame_id", "tool0", "frame_id of the Imu messages.", read_only=True),
    Spec("imu.seed", 1, "Seed of the noise generator.", read_only=True),
    Spec("task.name", "point_to_point", "Task name in cycle events."),
    Spec("task.start", [0.0], "Start pose, one value per joint (or one for all), rad or m."),
    Spec("task.goal", [0.5], "Goal pose, rad or m."),
    Spec("task.max_velocity", 1.0, "Largest joint velocity of a move, rad/s or m/s.", (1e-6, 1e6),
         check=_task_check("max_velocity")),
    Spec("task.max_acceleration", 10.0, "Largest joint acceleration of a move, rad/s^2 or m/s^2.", (1e-6, 1e9),
         check=_task_check("max_acceleration")),
    Spec("task.dwell", 2.0, "Dwell after each move (the residual-vibration window), s.", (0.0, 3600.0),
         check=_task_check("dwell")),
    Spec("task.levels", None,
         "If set, a staircase instead of moves: the command steps to each level in turn (one cycle per step,"
         " task.dwell each; steps x joints values), e.g. seed 004's velocity steps (plant.model two_mass).",
         type=Parameter.Type.DOUBLE_ARRAY, check=_levels_check),
    Spec("task.profile", "trapezoid",
         "Move profile: 'trapezoid' (within max_velocity and max_acceleration), 'step' (jump to the target)"
         " or 'ramp' (constant max_velocity).", check=_task_check("profile")),
    Spec("task.round_trip", False,
         "Every cycle goes start -> goal -> start (each with a dwell), so all cycles are the same;"
         " otherwise cycles alternate between the poses."),
    Spec("task.cycles", 4, "Cycles per run (started by ~/start_task).", check=_task_check("cycles")),
    Spec("task.preroll", 1.0, "Rest at the start pose before the first cycle, s.", (0.0, 3600.0)),
    Spec("task.autostart", False, "Start a run as soon as the node is up.", read_only=True),
    Spec("task.subscribers", 0,
         "Start a run only once the cycle events reach at least this many matched subscriptions (0: at once);"
         " until then ~/start_task refuses with 'waiting for subscribers'. A test driver sets it so that a learner"
         " started just before cannot miss the first START.", (0, 64)),
    Spec("settle_tolerance", 1e-6, "Joint positions within this of their final value count as at rest, rad or m.",
         (0.0, 1.0)),
    *topics({"command_out": "/shaper/commands", "command_in": "/forward_position_controller/commands",
             "joint_states": "/joint_states", "tip_state": "~/tip_state", "imu": "/tip_imu",
             "cycle_events": "/cycle_events", "cycle_reports": "/cycle_reports",
             "active_shaper": "/shaper/active_shaper", "reference": "~/reference",
             "jtc_action": "/joint_trajectory_controller/follow_joint_trajectory",
             "jtc_topic": "/joint_trajectory_controller/joint_trajectory"}),
)
