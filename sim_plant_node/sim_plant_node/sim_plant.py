"""Simulated plant node: flexible joints with a tip accelerometer, running a repeated task.

Stands in for a robot and its ros2_control forward position controller in tests and the demo.
Its parameters (names, defaults, ranges, units) are the table :data:`PARAMETERS`.

Each step the task runner publishes the raw setpoint (``topics.command_out``, to the shaper),
the plant takes the shaped setpoint (``topics.command_in``, std_msgs/Float64MultiArray as
forward_command_controller does), integrates one period, and publishes ``/joint_states``
(joint = base position and velocity, which for every model is the applied setpoint and its
slope), ``~/tip_state`` (tip position and velocity), the tip accelerometer (sensor_msgs/Imu,
m/s^2, configurable noise and bias), cycle events and a per-cycle report.

Plant models (parameter ``plant.model``, see sim_plant_node.plants and docs/list_plants.md)
------------------------------------------------------------------------------------------
mck
    Base-driven m-c-k flexible joint (spring and damper between base and tip), exact.
list_linear, list_time_varying, list_hardening, list_saturation
    The four plants of the LIST simulations (seed 003): damper to ground; mass that doubles
    over the first second of every cycle; cubic hardening spring ``plant.stiffness_cubic``;
    P loop ``plant.gain`` with actuator force limit ``plant.force_limit``. The time-varying
    mass follows the time since the current cycle's START event.
mck_pid
    The mck plant inside the loop of a continuous feedback controller C(s)
    (``controller.numerator``/``denominator``, default seed 000's PID), with a feedforward
    effort u2 (seed 000, MRILC): /joint_states carries the output y and the total effort u,
    ``~/reference`` the applied (shaped) reference. See sim_plant_node.pid_loop.
arm
    The six-axis elastic-joint arm (UR5e figures, Pinocchio; docs/arm.md), chosen at start-up,
    behind an emulation of joint_trajectory_controller: FollowJointTrajectory on
    ``topics.jtc_action``, JointTrajectory on ``topics.jtc_topic`` (sim_plant_node.jtc_server),
    and the forward command topic while a task runs. /joint_states carries the motor-side
    positions, velocities and torques, ``~/tip_state`` the link angles, the IMU the flange's
    specific force (gravity included) and angular rate at every physics step (rate x
    ``arm.substeps``). In lockstep the arm steps while the controller executes a trajectory;
    at rest it publishes its last joint state again every 0.1 s of wall time (simulated time
    stands still), as a robot's joint_state_broadcaster keeps publishing. The payload at the
    flange (``arm.payload_mass``, ``arm.payload_offset``) changes live (``ros2 param set``): the
    inertia, gravity and modes follow at the next step.

Feedforward (``~/set_feedforward``, shaper_msgs/SetFeedforward)
--------------------------------------------------------------
A profile indexed by the sample within the cycle, installed at the next START: "command"
profiles are added to the shaped setpoint (every model), "effort" profiles to the controller
output (mck_pid only).

Modes (parameter ``mode``)
--------------------------
lockstep
    Simulated time: publishes /clock and steps only when the shaped setpoint for the previous
    raw setpoint has arrived, so runs go as fast as the nodes answer and give the same result
    on a loaded machine. Idle (no task running) the plant does not step. If no answer comes
    within ``lockstep_timeout`` seconds of wall time, the plant holds the last setpoint, warns,
    and goes on. So that the first setpoint of a run is not lost on DDS (and the run stalled
    for ``lockstep_timeout``), ``~/start_task`` refuses with 'waiting for subscribers' (a driver
    asks again) until the raw setpoints have a matched subscription and the shaped setpoints a
    matched publisher. With ``lockstep.block`` N > 1 the raw setpoints of N steps go to the shaper in one
    message (layout [samples, joints]) and the plant steps through the shaped block: the same run with N
    times fewer round trips, for a command path that is feedforward (each step's events, joint states, IMU
    and /clock go out as before, step by step). Each ask is numbered in its layout's first label
    ("joints, ask K", or "samples, ask K" for a block), which the shaper passes on with the shaped data: an
    answer labelled with another ask (one that comes after ``lockstep_timeout`` went by) is ignored and
    counted (``late_answers``), with a warning, so that it is never applied to a later step. An answer with no
    layout, or a layout of its own (a peer that does not pass the plant's on), is taken as the answer to the
    pending ask.
realtime
    Wall-clock rate; the latest shaped setpoint received is applied each period.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock as RclpyClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetFeedforward
from shaper_nodes.core.checks import InputError, finite_array
from shaper_nodes.core.cycles import CycleMonitor
from shaper_nodes.core.learning.mrilc import PAPER_CONTROLLER
from shaper_nodes.recordings.cdr import JointStateCdr, clock_cdr, stamp_parts
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import Spec, declare_all, topics, values
from shaper_nodes.ros.qos import LATCHED

from .arm.description import JOINT_NAMES as ARM_JOINTS
from .arm.description import MAX_PAYLOAD_MASS, MAX_PAYLOAD_OFFSET, PAYLOAD_MASS, PAYLOAD_OFFSET, ArmSpec, check_payload
from .arm.dynamics import ArmModel
from .arm.jtc import JointTrajectoryController
from .arm.plant import ArmPlant
from .jtc_server import ControllerServer, tolerances_from
from .loops import LOOP_MODELS, LOOP_PARAMS, LoopPlant, check_loop_value, make_loop_plant
from .pid_loop import PidLoopPlant
from .plants import (
    LIST_FORCE_LIMIT,
    LIST_GAIN,
    LIST_STIFFNESS_CUBIC,
    PLANT_MODELS,
    CycleTask,
    ListPlant,
    MckPlant,
    check_rate,
    check_task,
    make_plant,
    plant_values,
)
from .two_mass import StaircaseTask, TwoMassPlant

#: the plant models the node runs
Plant = MckPlant | ListPlant | PidLoopPlant | LoopPlant | TwoMassPlant | ArmPlant
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
#: lockstep: how the first layout label of an ask begins (then the ask's number)
ASK_LABELS = ("joints, ask ", "samples, ask ")
#: the lockstep IMU writer: reliable, 10 s of samples at 1 kHz kept for a reader that lags (the plant stepping in
#: blocks may run seconds ahead of a loaded reader's intake)
LOCKSTEP_IMU_QOS = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
#: s of wall time between joint states of the lockstep arm at rest (joint_states.idle_period's default)
IDLE_STATE_PERIOD = 0.1


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


class SimPlantNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("sim_plant", *args, **kwargs)
        declare_all(self, PARAMETERS)

        self.joint_names = list(self.get_parameter("joint_names").value)
        self.arm = self.get_parameter("plant.model").value == "arm"
        if self.arm and self.joint_names == ["joint_1"]:
            self.joint_names = list(ARM_JOINTS)
        if self.arm and len(self.joint_names) != len(ARM_JOINTS):
            raise ValueError(f"plant.model arm has {len(ARM_JOINTS)} joints; joint_names has {len(self.joint_names)}")
        self.n = len(self.joint_names)
        self.rate = float(self.get_parameter("rate").value)
        self.mode = str(self.get_parameter("mode").value)
        if self.mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode must be 'lockstep' or 'realtime', got {self.mode!r}")
        self.plant = self._make_plant({})
        axes = [int(a) for a in self.get_parameter("imu.axes").value][:3]
        self._axes = [a if 0 <= a < self.n else -1 for a in axes] + [-1] * (3 - len(axes))
        self._rng = np.random.default_rng(int(self.get_parameter("imu.seed").value))
        self._sensor = {name: self.get_parameter(name).value for name in SENSOR_PARAMS}
        self._sensor_changed()
        # /joint_states and /clock are published as serialized bytes, their numbers rewritten in place
        # (shaper_nodes.ros.cdr): the same messages, without building message objects. The IMU stays a message
        # object: published as bytes (shaper_nodes.ros.cdr.ImuCdr, the same bytes on the wire) it failed
        # tests/test_calibrate.py's killed-and-resumed run twice (no IMU sample past a point within 30 s), not
        # yet understood (docs/benchmarks.md)
        self._imu_msg = Imu()  # reused: publish() serialises it at once
        self._imu_msg.orientation_covariance[0] = -1.0
        self._imu_msg.header.frame_id = self._imu_frame  # (imu.frame_id is read-only)
        self._imu_gyro_sigma: float | None = None  # the gyro covariance written in it
        self._js_cdr: JointStateCdr | None = None  # made for the array lengths the plant reports
        self._monitor = CycleMonitor(float(self.get_parameter("settle_tolerance").value), remove_mean=self.arm)
        self._active_shaper = ShaperMsg()

        tp = values(self, PARAMETERS, "topics.")
        self._cmd_pub = self.create_publisher(Float64MultiArray, tp["command_out"], 10)
        self._js_pub = self.create_publisher(JointState, tp["joint_states"], 10)
        self._tip_pub = self.create_publisher(JointState, tp["tip_state"], 10)
        self._loop_pub = self.create_publisher(JointState, "~/loop_state", 10)  # loop models only
        # in lockstep every sample counts (simulated time runs faster than a reader may take them): a reliable
        # writer keeps 10000 for a reliable reader, and still matches best-effort readers as a sensor driver does
        self._imu_pub = self.create_publisher(Imu, tp["imu"], LOCKSTEP_IMU_QOS if self.mode == "lockstep"
                                              else qos_profile_sensor_data)
        self._event_pub = self.create_publisher(CycleEvent, tp["cycle_events"], 10)
        self._report_pub = self.create_publisher(CycleReport, tp["cycle_reports"], 10)
        self._clock_pub = self.create_publisher(Clock, "/clock", 10) if self.mode == "lockstep" else None
        self._ref_pub = self.create_publisher(JointState, tp["reference"], 10)
        self.create_service(SetFeedforward, "~/set_feedforward", self._on_set_feedforward)
        self._ff_pending: tuple[str, np.ndarray] | None = None
        self._ff: tuple[str, np.ndarray] | None = None  # (injection, samples x joints) of this cycle
        self._cmd_sub = self.create_subscription(Float64MultiArray, tp["command_in"], self._on_command, 10)
        self.create_subscription(ShaperMsg, tp["active_shaper"], self._on_shaper, LATCHED)
        self.create_service(Trigger, "~/start_task", self._on_start)
        self.create_service(Trigger, "~/stop_task", self._on_stop)
        self.add_on_set_parameters_callback(self._validate_params)

        self.step_index = 0
        self.sim_time = 0.0
        self._cycle_start_step: int | None = None  # step_index at the current cycle's START
        self.task: CycleTask | StaircaseTask | None = None
        self._preroll_left = 0
        self._raw = np.zeros(self.n)
        self._applied = np.zeros(self.n)
        self._latest_shaped: np.ndarray | None = None
        self._waiting_since: float | None = None
        #: lockstep: the steps asked of the shaper and not yet answered: (cycle events, preroll ends) each
        self._asked: list[tuple[list, bool]] = []
        self._block = int(self.get_parameter("lockstep.block").value)
        self.timeouts = 0
        self.refused = 0
        self.late_answers = 0  # lockstep: answers to an earlier ask, ignored
        self._ask_label = ""  # lockstep: the label of the pending ask (_publish_next)
        self._asks = 0
        self.plant.reset(self._pose("task.start", {}))
        self._applied = self._pose("task.start", {}) if self.arm else self.plant.base_position
        self._raw = self._applied.copy()
        self.jtc: ControllerServer | None = None
        if self.arm:
            g = lambda n: self.get_parameter(n).value  # noqa: E731
            defaults = tolerances_from(tuple(self.joint_names), list(g("jtc.trajectory_tolerance")),
                                       list(g("jtc.goal_tolerance")), float(g("jtc.goal_time")))
            controller = JointTrajectoryController(tuple(self.joint_names), 1.0 / self.rate, defaults, self._applied)
            self.jtc = ControllerServer(self, controller, self._now, self._measured, self._jtc_busy, tp["jtc_action"],
                                        tp["jtc_topic"])
            if self.mode == "lockstep":
                self.create_timer(0.002, self._free_run)
        idle = float(self.get_parameter("joint_states.idle_period").value)
        idle = (IDLE_STATE_PERIOD if self.arm else 0.0) if idle < 0 else idle
        if self.mode == "lockstep" and idle > 0:
            # a robot's joint_state_broadcaster publishes at rest too: the last state again (time stands still)
            self._last_js: JointState | bytes = JointState(name=self.joint_names, position=self._reported(
                self.plant.base_position).tolist(), velocity=self.plant.base_velocity.tolist(),
                effort=getattr(self.plant, "effort", np.zeros(0)).tolist())
            self._last_js.header.stamp = sec_to_time(self._now())
            self.create_timer(idle, self._idle_joint_states, clock=RclpyClock(clock_type=ClockType.STEADY_TIME))
        if self.mode == "lockstep":
            self.create_timer(0.05, self._watchdog)
            self._publish_clock()
        else:
            self.create_timer(1.0 / self.rate, self._realtime_tick)
        if self.get_parameter("task.autostart").value:
            self._start_task()
        self.get_logger().info(
            f"{self.n} joints, plant {self.get_parameter('plant.model').value}, modes " + ", ".join(
                f"{w / (2 * math.pi):.4g} Hz zeta {z:.3g}" for w, z in zip(self.plant.natural_frequency,
                                                                          self.plant.damping_ratio, strict=True))
            + f", {self.mode} at {self.rate:g} Hz")

    # ----------------------------------------------------------------- configuration
    def _vector(self, name: str, overrides: dict, allow_inf: bool = False) -> np.ndarray:
        v = np.asarray(overrides.get(name, self.get_parameter(name).value), dtype=float).ravel()
        if v.size == 1:
            v = np.full(self.n, v[0])
        finite = np.isfinite(v) | (allow_inf & np.isinf(v))
        if v.size != self.n or not np.all(finite):
            kind = "" if allow_inf else "finite "
            raise ValueError(f"{name} needs 1 or {self.n} {kind}values, got {v.tolist()}")
        return v

    def _pose(self, name: str, overrides: dict) -> np.ndarray:
        return self._vector(name, overrides)

    def _make_plant(self, overrides: dict) -> Plant:
        model = check_model(str(overrides.get("plant.model", self.get_parameter("plant.model").value)))
        if model == "two_mass":  # seed 004's two-mass system, m1 = 10 x0 + 1 (two_mass.py)
            return TwoMassPlant(self.n, self.rate)
        if model == "arm":
            spec = ArmSpec(payload_mass=float(self.get_parameter("arm.payload_mass").value),
                           payload_offset=float(self.get_parameter("arm.payload_offset").value))
            return ArmPlant(self.rate, int(self.get_parameter("arm.substeps").value), ArmModel(spec))
        m, c, k, k3, kp, f_max = (self._vector(p, overrides, p == "plant.force_limit") for p in PLANT_PARAMS)
        if model in LOOP_MODELS:
            loop = values(self, LOOP_PARAMS)
            return make_loop_plant(model, m, c, k, self.rate, {p: overrides.get(p, loop[p]) for p in LOOP_PARAMS})
        try:
            plant = make_plant("mck" if model == "mck_pid" else model, m, c, k, self.rate, stiffness_cubic=k3,
                               gain=kp, force_limit=f_max)
        except ValueError as err:
            raise ValueError(f"plant.{err}") from None  # the plant names its argument first
        if model != "mck_pid":
            return plant
        g = lambda n: overrides.get(n, self.get_parameter(n).value)  # noqa: E731
        return PidLoopPlant(m, c, k, self.rate, list(g("controller.numerator")), list(g("controller.denominator")))

    def _cycle_time(self) -> float | None:
        """Time since the current cycle's START at the present step, s (None before any)."""
        if self._cycle_start_step is None:
            return None
        return (self.step_index - self._cycle_start_step) / self.rate

    def _validate_params(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        if self.arm and any(p in changes for p in PLANT_KEYS):
            return SetParametersResult(successful=False, reason="the arm (plant.model arm) is chosen at start-up; "
                                       "its model and plant.* do not change live")
        if changes.get("plant.model") == "arm":
            return SetParametersResult(successful=False, reason="plant.model arm is chosen at start-up only")
        try:
            new = self._make_plant(changes) if any(p in changes for p in PLANT_KEYS) else None
            for pose in ("task.start", "task.goal"):
                if pose in changes:
                    self._pose(pose, changes)
            payload = self._payload(changes)
        except ValueError as err:
            return SetParametersResult(successful=False, reason=str(err))
        self._sensor.update({k: v for k, v in changes.items() if k in SENSOR_PARAMS})
        self._sensor_changed()
        if payload is not None:  # checked above: takes effect at the next step
            assert isinstance(self.plant, ArmPlant)
            self.plant.set_payload(*payload)
            self.get_logger().info(
                f"payload {payload[0]:g} kg at {payload[1]:g} m: modes at the present pose now " + ", ".join(
                    f"{w / (2 * math.pi):.4g} Hz zeta {z:.3g}" for w, z in zip(
                        self.plant.natural_frequency[:3], self.plant.damping_ratio[:3], strict=True)))
        if new is not None:  # all checks passed: takes effect at the next step
            assert not isinstance(self.plant, ArmPlant) and not isinstance(new, ArmPlant)  # refused above
            try:
                new.state = self.plant.state.copy()
            except ValueError:  # another state layout: start the new model at rest where the output is
                new.reset(self.plant.base_position)
            new.cycle_time = self.plant.cycle_time
            self.plant = new
        return SetParametersResult(successful=True)

    def _payload(self, changes: dict) -> tuple[float, float] | None:
        """The arm's new payload (mass kg, offset m) if ``changes`` sets one, checked; None otherwise (and for
        the other plant models, which keep the values unused)."""
        if not self.arm or not ({"arm.payload_mass", "arm.payload_offset"} & changes.keys()):
            return None
        g = lambda n: float(changes.get(n, self.get_parameter(n).value))  # noqa: E731
        mass, offset = g("arm.payload_mass"), g("arm.payload_offset")
        check_payload(mass, offset)
        return mass, offset

    # ----------------------------------------------------------------- task
    def _make_task(self) -> CycleTask | StaircaseTask:
        """The task the parameters describe: a staircase (seed 004) when task.levels is set, else moves."""
        g = lambda n: self.get_parameter(n).value  # noqa: E731
        task = CycleTask(self._pose("task.start", {}), self._pose("task.goal", {}), float(g("task.max_velocity")),
                         float(g("task.max_acceleration")), float(g("task.dwell")), self.rate, int(g("task.cycles")),
                         str(g("task.profile")), bool(g("task.round_trip")))
        if len(g("task.levels")):  # empty (the default): not set
            return StaircaseTask(self._pose("task.start", {}), g("task.levels"), float(g("task.dwell")), self.rate)
        return task

    def _start_task(self, matched: bool = False) -> tuple[bool, str]:
        """Start a run; with ``matched`` (the ~/start_task service), in lockstep only once the loop through the
        shaper is matched on DDS (:meth:`_lockstep_unmatched`)."""
        if self.task is not None:
            return False, "a task is already running"
        if self.jtc is not None and self.jtc.running:
            return False, "joint_trajectory_controller is executing a trajectory"
        need = int(self.get_parameter("task.subscribers").value)
        have = self._event_pub.get_subscription_count()  # matched, not only discovered
        if have < need:
            return False, f"{WAITING}: the cycle events have {have} matched subscriptions, task.subscribers is {need}"
        unmatched = self._lockstep_unmatched() if matched and self.mode == "lockstep" else ""
        if unmatched:
            return False, f"{WAITING}: {unmatched}"
        try:
            task = self.task = self._make_task()
        except ValueError as err:
            return False, str(err)
        g = lambda n: self.get_parameter(n).value  # noqa: E731
        self._preroll_left = int(round(float(g("task.preroll")) * self.rate))
        self._cycle_start_step = None  # the preroll belongs to no cycle
        self._preroll_total = self._preroll_left
        if self.mode == "lockstep" and self._waiting_since is None:
            self._publish_next()
        return True, (f"{task.cycles} cycles of {task.samples_per_cycle / self.rate:.3f} s"
                      f" (move {task.move_duration:.3f} s) after {self._preroll_left / self.rate:.3f} s preroll")

    def _lockstep_unmatched(self) -> str:
        """What the lockstep loop still lacks on DDS ('' if nothing): a step waits for the shaped answer to its
        raw setpoint, so a run started before the raw setpoints reach a subscription, or before a publisher's
        shaped setpoints reach the plant, loses its first setpoint and stalls for ``lockstep_timeout``. (Matched,
        not only discovered: a driver that sees the shaper in the graph may see it before the plant matches it.)"""
        missing = []
        if self._cmd_pub.get_subscription_count() == 0:
            missing.append(f"the raw setpoints on {self._cmd_pub.topic_name} have no matched subscription")
        if self._cmd_sub.get_publisher_count() == 0:
            missing.append(f"the shaped setpoints on {self._cmd_sub.topic_name} have no matched publisher")
        return "; ".join(missing)

    def _on_start(self, req, resp):
        resp.success, resp.message = self._start_task(matched=True)
        return resp

    def _on_stop(self, req, resp):
        resp.success, resp.message = self.task is not None, "stopped" if self.task else "no task running"
        self.task = None
        return resp

    def _next_raw(self) -> tuple[list, bool]:
        """The raw setpoint of the next step (into ``_raw``), its cycle events, and whether the preroll ends
        with it (:meth:`_begin_step` carries them out when the step is integrated)."""
        if self.task is None:
            return [], False
        if self._preroll_left > 0:
            self._raw = self.task.start.copy()
            self._preroll_left -= 1
            return [], self._preroll_left == 0
        self._raw, events = self.task.step()
        return events, False

    def _begin_step(self, events: list, preroll_end: bool) -> None:
        """What comes before a step is integrated: at the end of the preroll the plant rests exactly at the
        applied setpoint (whatever came before the run), and the step's cycle events go out."""
        if preroll_end:
            self.plant.reset(self._applied)
        t = self._now()
        for ev in events:
            self._emit_event(ev, t)

    # ----------------------------------------------------------------- stepping
    def _publish_clock(self) -> None:
        if self._clock_pub is not None:
            self._clock_pub.publish(clock_cdr(*stamp_parts(self.sim_time)))

    def _now(self) -> float:
        if self.mode == "lockstep":
            return self.sim_time
        return self.get_clock().now().nanoseconds * 1e-9

    def _publish_next(self) -> None:
        """Ask the shaper for the next step's setpoint: publish its raw setpoint, or with ``lockstep.block``
        above 1 the raw setpoints of the next steps up to that many (up to the task's end) as one block
        (layout [samples, joints]). Their events go out as each step is integrated (:meth:`_on_command`)."""
        asked = self._asked
        raws: list[np.ndarray] = []
        while len(raws) < self._block and self.task is not None and (self._preroll_left > 0 or not self.task.done):
            asked.append(self._next_raw())
            raws.append(self._raw)
        if not raws:
            return
        self._asks += 1
        if self._block == 1:
            self._ask_label = f"{ASK_LABELS[0]}{self._asks}"
            msg = Float64MultiArray(data=self._raw.tolist())
            msg.layout.dim = [MultiArrayDimension(label=self._ask_label, size=self.n, stride=self.n)]
        else:
            self._ask_label = f"{ASK_LABELS[1]}{self._asks}"
            msg = Float64MultiArray(data=np.concatenate(raws).tolist())
            msg.layout.dim = [MultiArrayDimension(label=self._ask_label, size=len(raws), stride=len(raws) * self.n),
                              MultiArrayDimension(label="joints", size=self.n, stride=self.n)]
        self._cmd_pub.publish(msg)
        self._waiting_since = time.monotonic()

    def _step_asked(self, shaped: np.ndarray | None) -> None:
        """Integrate the steps asked for, each with its shaped setpoint (a row of ``shaped``; None: each holds
        the last applied setpoint), publishing /clock after each; then ask for the next ones."""
        asked, self._asked = self._asked, []
        self._waiting_since = None
        for i, (events, preroll_end) in enumerate(asked):
            self._begin_step(events, preroll_end)
            self._integrate(self._applied if shaped is None else shaped[i])
            self._publish_clock()
        if self.task is not None:
            self._publish_next()

    def _emit_event(self, ev, t: float) -> None:
        msg = CycleEvent(event=ev.kind, cycle=ev.cycle, task=str(self.get_parameter("task.name").value),
                         joint_names=self.joint_names, start_positions=ev.start.tolist(),
                         goal_positions=ev.goal.tolist())
        msg.header.stamp = sec_to_time(t)
        self._event_pub.publish(msg)
        if ev.kind == CycleEvent.START:
            self._cycle_start_step = self.step_index  # the next period is the cycle's first
            if self._ff_pending is not None:
                self._ff, self._ff_pending = (None if self._ff_pending[1].size == 0 else self._ff_pending), None
        result = self._monitor.event(ev.kind, ev.cycle, t)
        if result is not None:
            self._report(result)
        if ev.kind == CycleEvent.END and self.task is not None and self.task.done:
            self.get_logger().info(f"task run finished after {self.task.cycles} cycles")
            self.task = None

    def _report(self, result) -> None:
        r = result.residual
        msg = CycleReport(source="sim_plant", cycle=result.cycle, window_start=r.window_start, window_end=r.window_end,
                          residual_rms=r.rms, residual_peak=r.peak, shaper_used=self._active_shaper,
                          shaper_next=self._active_shaper)
        msg.header.stamp = sec_to_time(self._now())
        self._report_pub.publish(msg)

    def _feedforward(self) -> tuple[str, np.ndarray] | None:
        """The installed profile's sample for the present period (None outside it)."""
        if self._ff is None or self._cycle_start_step is None:
            return None
        k = self.step_index - self._cycle_start_step
        return (self._ff[0], self._ff[1][k]) if 0 <= k < self._ff[1].shape[0] else None

    def _integrate(self, command: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """One period: apply ``command`` (and, from the trajectory controller, its ``velocity``), publish the state."""
        if self.jtc is not None and velocity is None and not self.jtc.running:
            self.jtc.controller.hold(command)  # the forward command's setpoint is held when it stops
        t_start = self._now()
        self._applied = command
        if self._ref_pub.get_subscription_count() > 0:  # (a learner's input; costly at every step)
            ref = JointState(name=self.joint_names, position=command.tolist())
            ref.header.stamp = sec_to_time(self._now())  # the start of the period the setpoint applies to
            self._ref_pub.publish(ref)
        ff = self._feedforward()
        if ff is not None and ff[0] == "command":
            command = command + ff[1]
        if isinstance(self.plant, PidLoopPlant):
            self.plant.feedforward = ff[1] if ff is not None and ff[0] == "effort" else np.zeros(self.n)
        if isinstance(self.plant, ArmPlant):
            self.plant.step(command, velocity=velocity)
        else:
            self.plant.step(command, cycle_time=self._cycle_time())
        self.step_index += 1
        self.sim_time = self.step_index / self.rate
        t = self._now()
        self._last_js = self._joint_state(t)  # (also the idle republisher's)
        self._js_pub.publish(self._last_js)
        if self._tip_pub.get_subscription_count() > 0:
            tip = JointState(name=self.joint_names, position=self.plant.tip_position.tolist(),
                             velocity=self.plant.tip_velocity.tolist())
            tip.header.stamp = sec_to_time(t)
            self._tip_pub.publish(tip)
        if isinstance(self.plant, LoopPlant):  # per joint: output y (with d_o), measured y + n, control u, reference r
            p = self.plant
            loop = JointState(name=[f"{j}/{s}" for s in p.SIGNALS for j in self.joint_names],
                              position=np.concatenate([p.output, p.measured, p.control, p.reference]).tolist())
            loop.header.stamp = sec_to_time(t)
            self._loop_pub.publish(loop)
        if isinstance(self.plant, ArmPlant):  # the flange IMU at every physics step
            for t_sub, force, rate in self.plant.imu_samples:
                self._publish_imu(t_start + t_sub - self.plant.imu_samples[-1][0] + 1.0 / self.rate, force, rate)
        else:
            acc_joint = self.plant.tip_acceleration
            self._publish_imu(t, np.array([acc_joint[a] if a >= 0 else 0.0 for a in self._axes]), None)
        self._monitor.add_positions(t, self._applied)

    def _joint_state(self, t: float) -> bytes:
        """The serialized /joint_states message at ``t`` s: reported positions, velocities, efforts (if any)."""
        position = self._reported(self.plant.base_position)
        velocity = self.plant.base_velocity
        effort = getattr(self.plant, "effort", None)
        sizes = (position.size, velocity.size, 0 if effort is None else effort.size)
        js = self._js_cdr
        if js is None or js.sizes != sizes:  # (a plant model changed live may report efforts or not)
            js = self._js_cdr = JointStateCdr(self.joint_names, *sizes)
        js.position[:] = position
        js.velocity[:] = velocity
        if effort is not None:
            js.effort[:] = effort
        js.set_stamp(*stamp_parts(t))
        return js.data()

    def _reported(self, position: np.ndarray) -> np.ndarray:
        """Joint positions as the encoders report them: noise and quantisation as the parameters say."""
        sigma = float(self._sensor["joint_states.noise_stddev"])
        quantum = float(self._sensor["joint_states.resolution"])
        if sigma > 0:
            position = position + self._rng.normal(0.0, sigma, position.size)
        if quantum > 0:
            position = np.round(position / quantum) * quantum
        return position

    def _sensor_changed(self) -> None:
        """The sensor settings as every sample uses them (after start and each parameter change)."""
        sensor = self._sensor
        self._imu_bias = np.asarray(sensor["imu.bias"], dtype=float)[:3]
        self._gyro_bias = np.asarray(sensor["imu.gyro_bias"], dtype=float)[:3]
        self._imu_sigma = float(sensor["imu.noise_stddev"])
        self._gyro_sigma = float(sensor["imu.gyro_noise_stddev"])
        self._imu_frame = str(sensor["imu.frame_id"])

    def _publish_imu(self, t: float, acc: np.ndarray, rate: np.ndarray | None) -> None:
        """One Imu message at ``t``: specific force ``acc`` (m/s^2), angular rate ``rate`` (rad/s; None: none)."""
        acc = acc + self._imu_bias
        sigma = self._imu_sigma
        if sigma > 0:
            acc += self._rng.normal(0.0, sigma, 3)
        imu = self._imu_msg
        imu.header.stamp.sec, imu.header.stamp.nanosec = stamp_parts(t)
        if rate is None:
            imu.angular_velocity_covariance[0] = -1.0
        else:
            gyro_sigma = self._gyro_sigma
            rate = rate + self._gyro_bias
            if gyro_sigma > 0:
                rate = rate + self._rng.normal(0.0, gyro_sigma, 3)
            imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z = rate.tolist()
            if gyro_sigma != self._imu_gyro_sigma:
                imu.angular_velocity_covariance = [gyro_sigma**2, 0.0, 0.0, 0.0, gyro_sigma**2, 0.0, 0.0, 0.0,
                                                   gyro_sigma**2]
                self._imu_gyro_sigma = gyro_sigma
        imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = acc.tolist()
        imu.linear_acceleration_covariance[0] = imu.linear_acceleration_covariance[4] = \
            imu.linear_acceleration_covariance[8] = sigma**2
        self._imu_pub.publish(imu)
        self._monitor.add_accel(t, acc)

    # ----------------------------------------------------------------- the trajectory controller (arm)
    def _measured(self) -> tuple[np.ndarray, np.ndarray]:
        """What the controller's state interfaces read: motor-side positions and velocities."""
        return self.plant.base_position, self.plant.base_velocity

    def _jtc_busy(self) -> str | None:
        if self.task is not None:
            return "a task is running: forward_position_controller drives the joints (~/stop_task first)"
        return None

    def _jtc_step(self) -> None:
        """One controller period and one plant period (arm, no task)."""
        assert self.jtc is not None
        self.jtc.update(self._now())
        c = self.jtc.controller
        self._integrate(c.command, c.command_velocity)

    def _idle_joint_states(self) -> None:
        """Lockstep at rest (no trajectory, no task): publish the last joint state again."""
        if (self.jtc is None or not self.jtc.running) and self.task is None and self._waiting_since is None:
            self._js_pub.publish(self._last_js)

    def _free_run(self) -> None:
        """Lockstep: step while the controller executes a trajectory (no task runs), ~20 ms of wall time a call."""
        if self.jtc is None or self.task is not None or self._waiting_since is not None:
            return
        deadline = time.monotonic() + 0.02
        while self.jtc.running and time.monotonic() < deadline:
            self._jtc_step()
            self._publish_clock()  # the commanded positions (what "at rest" means)

    def _on_command(self, msg: Float64MultiArray) -> None:
        if self.mode == "lockstep" and msg.layout.dim and msg.layout.dim[0].label != self._ask_label \
                and msg.layout.dim[0].label.startswith(ASK_LABELS):  # the answer to an earlier ask
            self.late_answers += 1
            self.get_logger().warning(f"ignored a late answer to '{msg.layout.dim[0].label}' (it came after"
                                      f" lockstep_timeout; pending: '{self._ask_label}')", throttle_duration_sec=5.0)
            return
        try:  # in lockstep, the answer to the steps asked for (lockstep.block)
            rows = len(self._asked) if self.mode == "lockstep" and self._waiting_since is not None else 1
            command = finite_array("shaped command", msg.data, size=self.n * rows)
        except InputError as err:
            self.refused += 1
            self.get_logger().error(f"refused setpoint: {err}; holding the last one", throttle_duration_sec=1.0)
            command = None
        if self.mode == "realtime":
            if self.jtc is not None and self.task is None:  # the arm, no task: the forward controller holds it
                if command is not None and not self.jtc.running:
                    self.jtc.controller.hold(command)
                return
            if command is not None:
                self._latest_shaped = command
            return
        if self._waiting_since is None:
            return  # not waiting (idle, or a late answer after a timeout): ignore
        self._step_asked(None if command is None else command.reshape(-1, self.n))

    def _watchdog(self) -> None:
        if self._waiting_since is None or time.monotonic() - self._waiting_since < float(
                self.get_parameter("lockstep_timeout").value):
            return
        self.timeouts += 1
        self.get_logger().warning("no shaped setpoint within lockstep_timeout; holding the last setpoint",
                                  throttle_duration_sec=5.0)
        self._step_asked(None)

    def _realtime_tick(self) -> None:
        if self.jtc is not None and self.task is None:
            self._jtc_step()
            return
        self._begin_step(*self._next_raw())
        self._cmd_pub.publish(Float64MultiArray(data=self._raw.tolist()))
        command = self._latest_shaped if self._latest_shaped is not None else self._applied
        self._integrate(command)

    def _on_shaper(self, msg: ShaperMsg) -> None:
        self._active_shaper = msg

    def _on_set_feedforward(self, req, resp):
        resp.success, resp.message = True, ""
        try:
            self._ff_pending = self._check_profile(req.profile)
        except ValueError as err:
            resp.success, resp.message = False, str(err)
            self.get_logger().error(f"refused feedforward profile: {err}")
            return resp
        if self._cycle_start_step is None or self.task is None:  # no cycle runs: at once
            self._ff, self._ff_pending = (None if self._ff_pending[1].size == 0 else self._ff_pending), None
        samples = self._ff_pending[1].shape[0] if self._ff_pending else (self._ff[1].shape[0] if self._ff else 0)
        resp.message = (f"{req.profile.injection} profile of {samples} samples (iteration {req.profile.iteration})"
                        + (" from the next START" if self._ff_pending else " installed"))
        return resp

    def _check_profile(self, msg) -> tuple[str, np.ndarray]:
        if msg.injection not in ("effort", "command"):
            raise ValueError(f"injection must be 'effort' or 'command', got {msg.injection!r}")
        if msg.injection == "effort" and not isinstance(self.plant, PidLoopPlant):
            raise ValueError("an effort profile needs plant.model 'mck_pid' (no controller output to add it to)")
        if list(msg.joint_names) != self.joint_names:
            raise ValueError(f"joint names {list(msg.joint_names)} do not match the plant's {self.joint_names}")
        if not (math.isfinite(msg.sample_period) and abs(msg.sample_period * self.rate - 1.0) < 1e-6):
            raise ValueError(f"sample period {msg.sample_period!r} s does not match the plant's {1.0 / self.rate:g} s")
        data = np.asarray(msg.data, dtype=float)
        if data.size % self.n:
            raise ValueError(f"{data.size} values are not a whole number of samples of {self.n} joints")
        if not np.all(np.isfinite(data)):
            raise ValueError(f"non-finite value at index {int(np.argmax(~np.isfinite(data)))}")
        return msg.injection, data.reshape(-1, self.n)


def main(args: list[str] | None = None) -> int:
    return run_node(SimPlantNode, "sim_plant", args, examples=(
        with_config("sim_plant_node", "sim_plant", "sim_plant.yaml"),
        "ros2 run sim_plant_node sim_plant --ros-args -p plant.model:=arm -p mode:=realtime",))


if __name__ == "__main__":
    raise SystemExit(main())
