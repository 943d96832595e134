"""The shaper node: a causal real-time FIR per joint between a motion source and a controller.

Inputs and outputs (topic names are parameters, see config/shaper.yaml)
-----------------------------------------------------------------------
topics.array_in -> topics.array_out
    std_msgs/Float64MultiArray, one setpoint per joint in ``joint_names`` order (the input of
    forward_command_controller), one sample per message at ``command_rate``. A message whose layout
    has two dimensions, [samples, joints], carries a block of consecutive samples (the sim plant's
    lockstep exchange, ``lockstep.block``): shaped as those samples one by one would be, and sent on
    as one message with the same layout.
topics.stream_in -> topics.stream_out
    trajectory_msgs/JointTrajectory streamed with one or a few points per message (as MoveIt
    Servo does); every point is one sample at ``command_rate``; positions are shaped, and
    velocities and accelerations too when given.
topics.trajectory_in -> topics.trajectory_out, and service ~/shape_trajectory
    A whole trajectory for joint_trajectory_controller, resampled at ``command_rate`` and shaped.
action.server_name (~/follow_joint_trajectory) -> action.controller
    control_msgs/action/FollowJointTrajectory: each goal's trajectory shaped as above and
    forwarded to the controller's action, feedback, result and cancel relayed; a new goal
    preempts the running one (see trajectory_action.py). With ``action.scheduler`` set, each goal
    is shaped with the shaper that scheduler gives for the goal's final point (see
    ros/pose_shaper.py); the active shaper is not changed by it.
~/active_shaper (latched), ~/set_shaper, ~/get_shaper
    The active shaper, and changing or reading it. Changes (service or parameters) are
    validated first; a refused change leaves the active shaper as it was. Accepted changes are
    applied between two samples, bumplessly.
/diagnostics
    diagnostic_msgs/DiagnosticArray: every refused input (its class, throttled per class) and a
    periodic summary, with each streamed input's rate, gaps, bursts, drops and queueing lag
    (core/rate.py; WARN when a window saw gaps or drops); and the graph around the command path
    (another node of this name, other publishers, wrong types, incompatible QoS: ros/graph_watch.py).

What leaves the node
--------------------
Every output is checked where it is made, on every path, and a violation refuses the input with
the reason (``/diagnostics``, the log, the service's or goal's answer) and publishes nothing; a
streamed sample that is refused leaves the filters as they were. Outputs are finite; positions
are within the joint limits (``limits.position_*`` and the URDF's, the tighter), and whole
trajectories' velocities and accelerations within ``limits.velocity`` / ``limits.acceleration``
(core/shaping/limits.py); times are strictly increasing and representable. Inputs beyond
``limits.max_abs_value`` never reach a filter's state. Requests are bounded before any work
(points, span, joints, shaper size: core/shaping/trajectory.py, types.py).

Threads
-------
The streamed inputs (array, stream) are taken by a lean second node, ``<name>_stream``, spun on a
thread of its own (``stream_executor`` 'thread', the default): it has nothing but those two
subscriptions, so its executor's wake-up, which rclpy rebuilds over every entity of its nodes, costs
what a bare node's does (docs/benchmarks.md). Their topic names are resolved by this node, so
``~/commands`` is ``/<name>/commands`` as before. Shaper changes and parameters run in this node's
executor; :attr:`ShaperNode.stream_lock` keeps them between two streamed samples. With
``stream_executor`` 'node' the streamed inputs run in this node's executor as well. Whole
trajectories (topic, ``~/shape_trajectory``, the FollowJointTrajectory proxy) are served, under the
same names, by a side node ``<name>_trajectories`` on a thread of its own
(ros/side_node.py), so that the stream never waits for a long trajectory. Shaping a whole
trajectory only reads the active filter, never the streaming filters' state. The interpreter's
thread switch interval is shortened (:data:`SWITCH_INTERVAL`) so that a thread doing Python work
on a long trajectory yields within a fraction of a command period.

The stream follows the fields that arrive: a field that appears (velocities, say) starts its
filter at its first value (there was no output of it to be continuous with); a field that goes
away stops being output, and its filter starts afresh if it comes back.

Update policy (:mod:`shaper_nodes.core.shaping.policy`): every change names its source;
``allowed_sources`` lists the sources that may change the shaper (parameters count as source
"parameters"); the last accepted change wins. Changes from the sources in ``retime_sources``
(e.g. the scheduler) re-time the motion already commanded instead of switching bumplessly
(time-varying shaping, see core/shaping/fir.py).

Parameters: :data:`PARAMETERS` (names, defaults, ranges and descriptions; config/shaper.yaml).
"""

from __future__ import annotations

import array
import gc
import pathlib
import sys
import threading
import time
from collections import Counter, deque
from operator import le
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper, ShapeTrajectory
from shaper_nodes.core.checks import InputError, finite_array
from shaper_nodes.core.rate import RateWatch
from shaper_nodes.core.shaping import (
    DEFAULT_MAX_GAIN,
    FAMILIES,
    MAX_DESIGN_MODES,
    MAX_GAIN,
    Mode,
    PolicyError,
    RetimingShaper,
    Shaper,
    ShaperError,
    SparseFir,
    StreamingShaper,
    UpdatePolicy,
    design,
    discretize,
    modes_from_hz,
    none_shaper,
)
from shaper_nodes.core.shaping.limits import JointLimits, urdf_limits
from shaper_nodes.core.shaping.policy import PARAMETERS_SOURCE
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_SAMPLES
from shaper_nodes.ros.conversions import (
    TRAJ_FIELDS,
    shaper_from_msg,
    shaper_to_msg,
    trajectory_arrays,
    trajectory_msg,
)
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from shaper_nodes.ros.graph_watch import GraphWatch
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import Spec, declare_all, topics, values
from shaper_nodes.ros.pose_shaper import PoseShaperClient
from shaper_nodes.ros.qos import LATCHED
from shaper_nodes.ros.side_node import SideNode
from shaper_nodes.ros.whole_trajectory import TrajectoryWorker, WholeShaping

from .trajectory_action import TrajectoryActionProxy

DESIGN_PARAMS = ("shaper.family", "shaper.frequency_hz", "shaper.damping_ratio",
                 "shaper.frequencies_hz", "shaper.damping_ratios",
                 "shaper.derivative_order", "shaper.vibration_tolerance", "shaper.insensitivity",
                 "discretization")
DISCRETIZATIONS = ("split", "round", "exact")
TOPICS = {
    "array_in": "~/commands", "array_out": "/forward_position_controller/commands",
    "stream_in": "~/joint_trajectory_stream", "stream_out": "/joint_trajectory_controller/joint_trajectory",
    "trajectory_in": "~/joint_trajectory", "trajectory_out": "/joint_trajectory_controller/joint_trajectory",
}
_PROBE = Mode.from_hz(10.0, 0.05)  # a mode to hold one design parameter against the core
#: s, the interpreter's thread switch interval in this node (Python's default is 5 ms, ten command
#: periods at 2 kHz): a thread shaping a long trajectory gives the streaming thread the interpreter
#: within this time
SWITCH_INTERVAL = 2e-4
#: s, how long the side thread sleeps after each 100 points of a whole trajectory's message it builds
#: (about 1 ms of work): whole trajectories are background work, the stream comes first
BACKGROUND_PAUSE = 1e-3
#: the collector's thresholds in this node (Python's default is (700, 10, 10)); see _tune_interpreter
GC_THRESHOLDS = (700, 10, 1000)
#: s, the longest a whole trajectory may take in the worker process (300,000 samples take about 10 s)
WORKER_TIMEOUT = 120.0
#: default of limits.max_trajectory_samples (see there)
DEFAULT_MAX_SAMPLES = 5_000
#: the streamed inputs (array_in, stream_in)
STREAMS = ("array", "stream")
#: how often the streams' kept arrivals go through the rate watch (s, steady clock, main thread)
WATCH_PERIOD = 0.25
#: choices of the stream_executor parameter
STREAM_EXECUTORS = ("thread", "node")

#: the shaper node's parameters (see config/shaper.yaml)
PARAMETERS: tuple[Spec, ...] = (
    Spec("joint_names", None, "Joints to shape, in the order of Float64MultiArray data and of the outputs.",
         read_only=True, type=Parameter.Type.STRING_ARRAY),
    Spec("command_rate", 500.0, "Rate of the streamed setpoints and of whole-trajectory resampling, Hz.",
         (1.0, 10000.0), read_only=True, check=lambda v: discretize(none_shaper(), v)),
    Spec("shaper.family", "none", "Shaper family: " + ", ".join(f"{k} ({v})" for k, v in FAMILIES.items()
                                                               if k != "custom"),
         check=lambda v: design(v, [_PROBE])),
    Spec("shaper.frequency_hz", 10.0, "Natural frequency of the mode to shape for, Hz (undamped).", (0.01, 1000.0),
         check=lambda v: design("zv", [Mode.from_hz(v, 0.05)])),
    Spec("shaper.damping_ratio", 0.05, "Damping ratio of the mode to shape for, dimensionless.", (0.0, 0.95),
         check=lambda v: design("zv", [Mode.from_hz(10.0, v)])),
    Spec("shaper.frequencies_hz", None, "Several modes: their natural frequencies, Hz (undamped), one per entry"
         " of shaper.damping_ratios. When set (non-empty), the family is designed on all these modes (the"
         " single-mode designs convolved; si designs them jointly) and shaper.frequency_hz and"
         f" shaper.damping_ratio are not used. At most {MAX_DESIGN_MODES} modes, each below command_rate / 4."
         " A change of the number of modes sets both lists at once (ros2 param load, or one atomic set).",
         type=Parameter.Type.DOUBLE_ARRAY, check=lambda v: modes_from_hz(v, [0.05] * len(v))),
    Spec("shaper.damping_ratios", None, "Several modes: their damping ratios, dimensionless, in [0, 0.95], one per"
         " entry of shaper.frequencies_hz (see there).", type=Parameter.Type.DOUBLE_ARRAY,
         check=lambda v: modes_from_hz([10.0] * len(v), v)),
    Spec("shaper.derivative_order", 2, "n of the ZV-D^n family (family zvdn): 0 = ZV, 1 = ZVD, 2 = ZVDD.", (0, 10),
         check=lambda v: design("zvdn", [_PROBE], derivative_order=v)),
    Spec("shaper.vibration_tolerance", 0.05, "EI, multi-hump EI and SI families: tolerated percentage vibration,"
         " fraction (0.05 = 5 %).", (0.001, 0.3), check=lambda v: design("ei", [_PROBE], vibration_tolerance=v)),
    Spec("shaper.insensitivity", 0.4, "SI family: width of the band where V <= vibration_tolerance, fraction of"
         " the design frequency (0.4 = +-20 %).", (0.01, 1.5),
         check=lambda v: design("si", [_PROBE], insensitivity=v)),
    Spec("discretization", "split", "Impulse times between samples: 'split' linearly between the two samples"
         " (default), 'round', or 'exact' (the split corrected so the FIR meets the shaper's conditions at its"
         " modes exactly).", choices=DISCRETIZATIONS,
         check=lambda v: discretize(design("zv", [_PROBE]), 500.0, v)),
    Spec("shaper.max_gain", DEFAULT_MAX_GAIN, "Largest gain sum |A| of a custom shaper sent to ~/set_shaper:"
         " 1 (default) admits non-negative impulses only; larger allows negative impulses, whose output may"
         f" overshoot the input by up to this factor. In [1, {MAX_GAIN:g}].", (1.0, MAX_GAIN),
         check=lambda v: design("custom", amplitudes=[1.0], times=[0.0], max_gain=v)),
    Spec("limits.max_abs_value", 1e6, "Largest magnitude of any input value (position rad or m, velocity,"
         " acceleration in their SI units): a larger, finite value is implausible and refused before it reaches"
         " the filters, so their state keeps its precision and no sum overflows.", (1e-3, 1e12)),
    Spec("limits.max_trajectory_samples", DEFAULT_MAX_SAMPLES, "Most samples of a shaped whole trajectory (its span"
         " plus the shaper's duration, times command_rate); a longer one is refused before any work. Sending a"
         " trajectory's message holds the Python interpreter in rclpy's conversion for a time that grows with it,"
         " and the stream waits that long: about 0.4 ms per 1000 samples on a 2-core machine (docs/shaping.md)."
         f" The default, {DEFAULT_MAX_SAMPLES} (10 s at 500 Hz, 5 s at 1 kHz), keeps that wait under two periods"
         " at 1 kHz; raise it for longer trajectories if the stream can wait longer while one is shaped."
         f" At most {MAX_TRAJECTORY_SAMPLES}.", (100, MAX_TRAJECTORY_SAMPLES)),
    Spec("limits.position_lower", None, "Lowest position of each joint (rad or m), one per joint_names entry, in"
         " that order; empty (default): none (or the URDF's). No output passes below it.",
         read_only=True, type=Parameter.Type.DOUBLE_ARRAY),
    Spec("limits.position_upper", None, "Highest position of each joint (rad or m), one per joint_names entry;"
         " empty (default): none (or the URDF's). No output passes above it.",
         read_only=True, type=Parameter.Type.DOUBLE_ARRAY),
    Spec("limits.velocity", None, "Largest |velocity| of each joint (rad/s or m/s), one per joint_names entry;"
         " .inf for none on a joint; empty (default): none (or the URDF's). Whole trajectories whose shaped"
         " velocities pass it, and streamed points whose shaped velocities pass it, are refused.",
         read_only=True, type=Parameter.Type.DOUBLE_ARRAY),
    Spec("limits.acceleration", None, "Largest |acceleration| of each joint (rad/s^2 or m/s^2), one per"
         " joint_names entry; .inf for none on a joint; empty (default): none (URDF has none). As limits.velocity.",
         read_only=True, type=Parameter.Type.DOUBLE_ARRAY),
    Spec("limits.urdf_file", "", "A URDF file whose <limit> elements (position, velocity) hold for the joints"
         " too; where a parameter above also sets a limit, the tighter one holds. Every joint of joint_names must"
         " be a revolute, prismatic or continuous joint of it. Empty (default): no URDF.", read_only=True),
    Spec("stream_executor", "thread", "Who takes the streamed inputs (array_in, stream_in): 'thread' (default), a"
         " lean second node of this process, '<name>_stream', with nothing but those two subscriptions, spun on a"
         " thread of its own (the topics stay this node's: ~/commands is /<name>/commands); 'node': this node's"
         " executor, with its services, parameters and timers (one thread; every wake-up of the executor then"
         " waits on all of them, which costs the stream CPU and latency: docs/benchmarks.md).",
         choices=STREAM_EXECUTORS, read_only=True),
    Spec("queue_depth", 100, "Depth of the streamed inputs' subscription queues (array_in, stream_in), messages:"
         " how long a burst or a stall of the node may last without a sample being dropped (100 = 0.1 s at"
         " 1 kHz); a dropped sample is counted on /diagnostics.", (1, 100000), read_only=True),
    Spec("allowed_sources", ["parameters", "service", "learner", "scheduler", "identification", "user"],
         "Sources allowed to change the active shaper (update policy).", read_only=True),
    Spec("retime_sources", None, "Sources whose changes re-time the motion already commanded (time-varying"
         " shaping: pending impulses follow the new shaper, e.g. 'scheduler' for pose-dependent modes) instead of"
         " the bumpless switch that leaves it to the old shaper. Default none.", read_only=True,
         type=Parameter.Type.STRING_ARRAY),
    Spec("error_throttle", 1.0, "Least time between two error logs or diagnostics of the same class of bad input,"
         " s.", (0.0, 3600.0)),
    Spec("diagnostics_period", 1.0, "Period of the diagnostics summary, s.", (0.05, 3600.0), read_only=True),
    Spec("graph_watch.period", 1.0, "Period of the look at the ROS graph around the command path, s of wall"
         " time: another node of this node's name, several publishers on an input, another publisher on an"
         " output, a wrong message type or incompatible QoS on either, reported on /diagnostics (status"
         " '<node>: graph') and logged once each (ros/graph_watch.py). 0 disables it.", (0.0, 3600.0),
         read_only=True),
    *topics(TOPICS),
    Spec("action.server_name", "~/follow_joint_trajectory", "FollowJointTrajectory action served by this node;"
         " empty: no action server.", read_only=True),
    Spec("action.controller", "/joint_trajectory_controller/follow_joint_trajectory", "The controller's"
         " FollowJointTrajectory action that shaped goals are forwarded to.", read_only=True),
    Spec("action.server_timeout", 2.0, "How long a goal waits for the controller's action server and for its"
         " answer to the goal request, and (with action.scheduler) for the scheduler's answer, s.", (0.01, 3600.0),
         read_only=True),
    Spec("action.scheduler", "", "Fully qualified name of a scheduler node (e.g. '/scheduler'): each goal is then"
         " shaped with the shaper <scheduler>/shaper_at gives for the goal trajectory's final point (the modes"
         " where the move ends), not with the active shaper, which stays as it is. If the scheduler is absent,"
         " does not answer within action.server_timeout, refuses the pose, or its shaper fails this node's checks,"
         " the goal is shaped with the active shaper and a warning says why. Empty (default): the active shaper.",
         read_only=True),
)


class ShaperNode(Node):
    """Input-shaping node; see the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("shaper", *args, **kwargs)
        declare_all(self, PARAMETERS)
        p = self.get_parameter
        v = values(self, PARAMETERS)
        self.joint_names = list(v["joint_names"] or [])
        if not self.joint_names or len(set(self.joint_names)) != len(self.joint_names):
            raise ValueError("parameter joint_names must be a non-empty list of distinct names")
        self.rate = float(p("command_rate").value)
        self.policy = UpdatePolicy.of(v["allowed_sources"], v["retime_sources"] or ())
        n = len(self.joint_names)
        filt = RetimingShaper if self.policy.retime_sources else StreamingShaper

        shaper, method = self._design_from_params({})
        self._method = method
        self._shaper = shaper
        self._fir: SparseFir = discretize(shaper, self.rate, method)
        self._source = PARAMETERS_SOURCE
        self._revision = 1
        self._array_filter = filt(self._fir, n)
        self._stream_filters = {f: filt(self._fir, n) for f in TRAJ_FIELDS}
        self._stream_fields: tuple[str, ...] = ()
        # the last command passed on per filter (see _shape_checked)
        self._last_sent: dict[str, np.ndarray | list[float]] = {}
        self._pending_params: tuple[Shaper, str] | None = None
        self._max_abs = float(p("limits.max_abs_value").value)
        self._max_samples = int(p("limits.max_trajectory_samples").value)
        self.limits = self._limits_from_params(v)
        self._bounds_for = -1.0  # the limits.max_abs_value of _bounds (see _input_bounds)
        self._bounds: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())

        self._lock = threading.Lock()  # the counters and rate watches, shared by the threads
        #: held while a streamed sample is shaped and while the shaper changes (they run on different threads
        #: with stream_executor 'thread'); a holder stalls the streamed inputs
        self.stream_lock = threading.Lock()
        self._n = n
        self.rejections: Counter[str] = Counter()
        self.forwarded: Counter[str] = Counter()
        self._window_rejections = 0
        self.diagnostics = Diagnostics(self, lambda: float(p("error_throttle").value))
        self.rate_watch = {k: RateWatch(self.rate) for k in STREAMS}
        self._publisher_counts = dict.fromkeys(STREAMS, 1)
        # the streams' message infos wait here (a deque's append and popleft are atomic) and go through the
        # rate watch off the streaming path, on the main thread every WATCH_PERIOD s (_watch_arrivals); the
        # bound is 10 s of arrivals at the command rate: reaching it means a stalled main thread, and is reported
        self._arrivals_max = max(4096, int(10 * self.rate))
        self._arrivals: dict[str, deque] = {k: deque(maxlen=self._arrivals_max)
                                                        for k in STREAMS}
        self._arrivals_in = dict.fromkeys(STREAMS, 0)  # appended, by the one thread of each stream
        self._arrivals_seen = dict.fromkeys(STREAMS, 0)  # through the rate watch
        # whole trajectories: served by a side node on a thread of its own, never in the streaming thread
        self._side = SideNode(self, "trajectories")
        self._worker = TrajectoryWorker()  # the trajectory topic's shaping, in a process of its own
        side = self._side.node
        # the command path's endpoints are made through the graph watch, which looks from the side thread
        self.graph = GraphWatch(self, self.diagnostics, float(p("graph_watch.period").value), looker=side)

        tp = {k: p(f"topics.{k}").value for k in TOPICS}
        pubs: dict[str, Any] = {}

        def pub(name: str, typ: Any) -> Any:
            if name not in pubs:
                pubs[name] = self.graph.publisher(typ, name, 10)
            return pubs[name]

        self._array_pub = pub(tp["array_out"], Float64MultiArray)
        self._stream_pub = pub(tp["stream_out"], JointTrajectory)
        self._traj_pub = pub(tp["trajectory_out"], JointTrajectory)
        self._active_pub = self.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)
        depth = int(p("queue_depth").value)
        # the streamed inputs: on a lean node of their own, spun on a thread of its own (the names resolved by
        # this node), or on this node
        self._stream_side: SideNode | None = None
        stream_node: Node = self
        if str(p("stream_executor").value) == "thread":
            self._stream_side = SideNode(self, "stream", lean=True)
            stream_node = self._stream_side.node
            tp["array_in"], tp["stream_in"] = (self.resolve_topic_name(tp[k]) for k in ("array_in", "stream_in"))
        # two-argument callbacks: rclpy passes each message's info (stamps, sequence number) for the rate watch
        subs = {
            "array_in": self.graph.subscription(Float64MultiArray, tp["array_in"], self._on_array, depth,
                                                on=stream_node),
            "stream_in": self.graph.subscription(JointTrajectory, tp["stream_in"], self._on_stream, depth,
                                                 on=stream_node),
            # raw: the bytes go to the trajectory worker process undecoded (ros/whole_trajectory.py)
            "trajectory_in": self.graph.subscription(JointTrajectory, self.resolve_topic_name(tp["trajectory_in"]),
                                                     self._on_trajectory, 10, on=side, raw=True),
        }
        self._subs = subs
        self._in_topics = {k: sub.topic_name for k, sub in subs.items()}  # fully qualified, for messages
        self.create_service(SetShaper, "~/set_shaper", self._on_set_shaper)
        self.create_service(GetShaper, "~/get_shaper", self._on_get_shaper)
        side.create_service(ShapeTrajectory, self.resolve_service_name("~/shape_trajectory"),
                            self._on_shape_trajectory)
        self._action: TrajectoryActionProxy | None = None
        self.pose_shaper: PoseShaperClient | None = None
        server_name = str(p("action.server_name").value)
        action_topic = self.resolve_topic_name(server_name) if server_name else ""
        if server_name:
            scheduler = str(p("action.scheduler").value).strip()
            if scheduler:
                self.pose_shaper = PoseShaperClient(
                    side, scheduler, float(p("action.server_timeout").value), self.shape_whole, self.diagnostics,
                    max_gain=lambda: float(p("shaper.max_gain").value), rate=self.rate)
            self._action = TrajectoryActionProxy(
                side, action_topic, str(p("action.controller").value), self.shape_whole,
                on_refused=lambda err: self._reject(action_topic, err),
                on_forwarded=lambda: self._count_forwarded("action"),
                timeout=float(p("action.server_timeout").value), reshape=self.pose_shaper)
        self.add_on_set_parameters_callback(self._validate_params)
        self.add_post_set_parameters_callback(self._apply_params)
        self.create_timer(float(p("diagnostics_period").value), self._publish_summary,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_timer(WATCH_PERIOD, self._on_watch_timer, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._publish_active()
        self.graph.start()
        self._side.start()
        if self._stream_side is not None:
            self._stream_side.start()
        self.get_logger().info(
            f"shaping {n} joints at {self.rate:g} Hz with {self._describe()};"
            f" {self._in_topics['array_in']} -> {self._array_pub.topic_name}"
            + (f"; FollowJointTrajectory {action_topic} -> {self._action.controller_name}" if self._action else "")
            + (f", each goal shaped for its final pose by {self.pose_shaper.srv_name}" if self.pose_shaper else "")
            + f"; {self.limits.describe()}")

    def _limits_from_params(self, v: dict[str, Any]) -> JointLimits:
        """The joint limits: the parameters', and the URDF's when limits.urdf_file is set (the tighter)."""
        limits = JointLimits.from_lists(self.joint_names, v["limits.position_lower"] or (),
                                        v["limits.position_upper"] or (), v["limits.velocity"] or (),
                                        v["limits.acceleration"] or ())
        urdf_file = str(v["limits.urdf_file"]).strip()
        if urdf_file:
            try:
                text = pathlib.Path(urdf_file).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as err:
                raise ValueError(f"limits.urdf_file: cannot read {urdf_file}: {err}") from None
            try:
                limits = limits.tighter(urdf_limits(text, self.joint_names))
            except ValueError as err:
                raise ValueError(f"limits.urdf_file {urdf_file}: {err}") from None
        return limits

    # ----------------------------------------------------------------- shaper changes
    def _describe(self) -> str:
        s = self._shaper
        modes = ", ".join(f"{m.hz:.4g} Hz zeta {m.zeta:.3g}" for m in s.modes)
        return f"{s.family} ({len(s)} impulses, {s.duration * 1e3:.1f} ms{', ' + modes if modes else ''})"

    def _design_from_params(self, overrides: dict[str, Any]) -> tuple[Shaper, str]:
        def val(name: str) -> Any:
            if name in overrides:
                return overrides[name]
            try:
                return self.get_parameter(name).value
            except ParameterUninitializedException:  # a list without a default, not set: empty
                return None

        method = str(val("discretization"))
        if method not in DISCRETIZATIONS:
            raise ShaperError(f"discretization must be 'split', 'round' or 'exact', got {method!r}")
        family = str(val("shaper.family")).strip().lower()
        if family == "custom":
            raise ShaperError("family 'custom' is set through the ~/set_shaper service, not parameters")
        modes, name = self._modes_from_params(val)
        high = [m.hz for m in modes if m.hz >= self.rate / 4.0]
        if family != "none" and high:
            raise ShaperError(
                f"{name} {high[0]:.6g} Hz is too high for command_rate {self.rate:g} Hz"
                f" (must be below rate / 4 = {self.rate / 4:g} Hz)")
        shaper = design(family, modes,
                        derivative_order=int(val("shaper.derivative_order")),
                        vibration_tolerance=float(val("shaper.vibration_tolerance")),
                        insensitivity=float(val("shaper.insensitivity")))
        return shaper, method

    @staticmethod
    def _modes_from_params(val: Any) -> tuple[tuple[Mode, ...], str]:
        """The design modes: shaper.frequencies_hz with shaper.damping_ratios when set, else
        shaper.frequency_hz with shaper.damping_ratio; and the name of the parameter they came from."""
        freqs, zetas = list(val("shaper.frequencies_hz") or []), list(val("shaper.damping_ratios") or [])
        if not freqs and not zetas:
            return (Mode.from_hz(float(val("shaper.frequency_hz")), float(val("shaper.damping_ratio"))),), \
                "shaper.frequency_hz"
        try:
            return modes_from_hz(freqs, zetas), "shaper.frequencies_hz"
        except ShaperError as err:
            raise ShaperError(f"shaper.frequencies_hz / shaper.damping_ratios: {err}") from None

    def _stages(self) -> list[int]:
        with self.stream_lock:
            return [f.stages for f in (self._array_filter, *self._stream_filters.values())]

    def _validate_params(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in DESIGN_PARAMS}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            self.policy.allow(PARAMETERS_SOURCE)
            shaper, method = self._design_from_params(changes)
            self.policy.settled(self._stages())
            discretize(shaper, self.rate, method)  # may refuse; nothing has changed yet
        except (ShaperError, PolicyError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        except Exception as err:  # whatever the values, the node refuses them and keeps running
            return SetParametersResult(successful=False, reason=f"the design failed ({type(err).__name__}: {err})")
        self._pending_params = (shaper, method)
        return SetParametersResult(successful=True)

    def _apply_params(self, params: list[Parameter]) -> None:
        for param in params:
            if param.name == "limits.max_abs_value":
                self._max_abs = float(param.value)
            elif param.name == "limits.max_trajectory_samples":
                self._max_samples = int(param.value)
        pending, self._pending_params = self._pending_params, None
        if pending is not None:
            self._commit(pending[0], PARAMETERS_SOURCE, pending[1])

    def request(self, shaper: Shaper, source: str) -> tuple[bool, str]:
        """Validate and make ``shaper`` active on behalf of ``source``; returns (accepted, why)."""
        try:
            self.policy.decide(source, shaper, self.rate, self._stages())
            self._commit(shaper, source, self._method)
        except (PolicyError, RuntimeError, ValueError) as err:
            return False, str(err)
        return True, f"active: {self._describe()}, revision {self._revision}"

    def _commit(self, shaper: Shaper, source: str, method: str) -> None:
        fir = discretize(shaper, self.rate, method)  # may raise; nothing changed yet
        retime = self.policy.how(source) == "retime"
        with self.stream_lock:  # between two streamed samples
            for f in [self._array_filter, *self._stream_filters.values()]:
                if retime:
                    f.retime(fir)  # type: ignore[union-attr]  # retime sources make every filter a RetimingShaper
                else:
                    f.switch(fir)
        self._shaper, self._fir, self._source, self._method = shaper, fir, source, method
        self._revision += 1
        self._publish_active()
        self.get_logger().info(f"shaper changed by {source}: {self._describe()}, revision {self._revision}")

    def active_msg(self) -> ShaperMsg:
        return shaper_to_msg(self._shaper, self._source, self._revision, self.get_clock().now().to_msg())

    def _publish_active(self) -> None:
        self._active_pub.publish(self.active_msg())

    def _on_set_shaper(self, req: SetShaper.Request, resp: SetShaper.Response) -> SetShaper.Response:
        source = UpdatePolicy.source_of(req.shaper.source)
        try:
            shaper = shaper_from_msg(req.shaper, float(self.get_parameter("shaper.max_gain").value))
            resp.success, resp.message = self.request(shaper, source)
        except ShaperError as err:
            resp.success, resp.message = False, f"invalid shaper: {err}"
        except Exception as err:  # whatever a request holds, the node answers and keeps running
            resp.success, resp.message = False, f"invalid shaper: the design failed ({type(err).__name__}: {err})"
        if not resp.success:
            self.get_logger().warning(f"set_shaper from {source} refused: {resp.message}")
        resp.active = self.active_msg()
        return resp

    def _on_get_shaper(self, req: GetShaper.Request, resp: GetShaper.Response) -> GetShaper.Response:
        resp.active = self.active_msg()
        resp.command_rate = self.rate
        resp.fir_taps = self._fir.dense().tolist()
        return resp

    # ----------------------------------------------------------------- bad input
    def _reject(self, topic: str, err: InputError) -> None:
        with self._lock:
            self.rejections[err.kind] += 1
            self._window_rejections += 1
            count = self.rejections[err.kind]
            self.diagnostics.report(err.kind, ERROR, f"refused {err.kind} on {topic}: {err} (not forwarded)",
                                    name="input", values=[("topic", topic), ("count", str(count))])

    def _count_forwarded(self, path: str) -> None:
        # no lock: each path's count has one writer (array and stream: the streaming thread; trajectory and
        # action: the side node's thread), and a dict item's update is atomic to the readers under the GIL
        self.forwarded[path] += 1

    def _arrived(self, stream: str, info: dict[str, Any] | None) -> None:
        """Keep a streamed message's info (the middleware's stamps) and when it was taken, for the rate
        watch; only an append on the streaming path."""
        self._arrivals[stream].append((info, time.time_ns()))
        self._arrivals_in[stream] += 1

    def _on_watch_timer(self) -> None:
        with self._lock:
            self._watch_arrivals()

    def _watch_arrivals(self) -> None:
        """Pass the kept arrivals through the rate watches (call with ``_lock`` held)."""
        for k, queue in self._arrivals.items():
            watch, publishers = self.rate_watch[k], self._publisher_counts[k]
            # bounded: what is there now (the stream thread may go on appending)
            for _ in range(len(queue)):
                info, handled = queue.popleft()
                info = info or {}
                watch.arrival(info.get("source_timestamp"), info.get("received_timestamp"), handled,
                              info.get("publication_sequence_number"), publishers)
                self._arrivals_seen[k] += 1

    def watched(self, stream: str) -> RateWatch:
        """The rate watch of ``stream`` ('array' or 'stream') with every arrival so far taken in."""
        with self._lock:
            self._watch_arrivals()
            return self.rate_watch[stream]

    def _publish_summary(self) -> None:
        with self._lock:
            refused, self._window_rejections = self._window_rejections, 0
            forwarded, rejections = dict(self.forwarded), dict(self.rejections)
            self._watch_arrivals()
            windows = {k: w.window() for k, w in self.rate_watch.items()}
            total_drops = {k: w.total_drops for k, w in self.rate_watch.items()}
            # arrivals pushed out of a full queue before the rate watch saw them (a stalled main thread)
            unwatched = {k: self._arrivals_in[k] - self._arrivals_seen[k] - len(self._arrivals[k]) for k in STREAMS}
        # sequence numbers are per publisher: drops are counted while one publisher is seen
        self._publisher_counts = {k: self._subs[f"{k}_in"].get_publisher_count() for k in STREAMS}
        troubled = [k for k, w in windows.items() if w.trouble]
        level = WARN if refused or troubled else OK
        parts = [f"{refused} messages refused in the last period"] if refused else []
        parts += [f"{k} input: {w.gaps} gaps (largest {1e3 * w.largest_gap_s:.1f} ms), {w.drops} dropped"
                  for k, w in windows.items() if w.trouble]
        parts += [f"{k} input: {n} arrivals not watched (the node's main thread fell behind)"
                  for k, n in unwatched.items() if n > 0]
        if any(n > 0 for n in unwatched.values()):
            level = WARN
        msg = "; ".join(parts) if parts else f"shaping with {self._describe()}"
        values = [("revision", str(self._revision)), ("source", self._source), ("family", self._shaper.family),
                  ("command_rate_hz", f"{self.rate:g}")]
        values += [(f"forwarded.{k}", str(v)) for k, v in sorted(forwarded.items())]
        for k, w in windows.items():
            if w.messages:
                values += w.values(f"input.{k}")
            values.append((f"input.{k}.total_drops", str(total_drops[k])))
            if unwatched[k] > 0:
                values.append((f"input.{k}.unwatched", str(unwatched[k])))
        if self.pose_shaper is not None:
            values += [("action.scheduler.shaped", str(self.pose_shaper.shaped)),
                       ("action.scheduler.fallbacks", str(self.pose_shaper.fallbacks))]
        values += [(f"refused.{k}", str(v)) for k, v in sorted(rejections.items())]
        self.diagnostics.publish("shaper", level, msg, values)

    # ----------------------------------------------------------------- data paths
    def _limit(self) -> float:
        """limits.max_abs_value (cached: read on every sample)."""
        return self._max_abs

    def _on_array(self, msg: Float64MultiArray, info: dict[str, Any] | None) -> None:
        self._arrived("array", info)
        try:
            if msg.layout.dim:  # a layout: one sample, or a block of samples (:meth:`_block_rows`)
                rows = self._block_rows(msg)
                if rows > 1:
                    with self.stream_lock:
                        msg.data = self._shape_block(msg.data, rows)
                    self._array_pub.publish(msg)
                    self._count_forwarded("array")
                    return
            with self.stream_lock:
                y = self._shape_array(msg.data)
        except InputError as err:
            self._reject(self._in_topics["array_in"], err)
            return
        msg.data = y  # the input message goes on, its layout unchanged, with the shaped data
        self._array_pub.publish(msg)
        self._count_forwarded("array")

    def _shape_array(self, data: Any) -> list[float]:
        """One Float64MultiArray sample shaped by the array filter, with the checks and refusals of
        :meth:`_shape_checked`, made cheaply for a few values: the input is finite, within
        limits.max_abs_value and within the position limits exactly when ``lo <= v <= hi`` holds for each
        value with the bounds of :meth:`JointLimits.input_bounds` (a NaN fails any comparison), and the
        output is finite and within the position limits exactly when it holds with
        :attr:`JointLimits.sample_bounds`. Only a sample that fails is checked again by the general checks,
        which raise the InputError naming the reason. The sample stays a list of Python floats through the
        filter (:meth:`StreamingShaper.process_values`): on 7 values numpy's calls cost more than the
        arithmetic. Returns the shaped values."""
        values = data.tolist() if isinstance(data, array.array) else list(data)
        lo, hi = self._input_bounds
        # all(map(le, ...)) stops at the first pair out of order, in C; a NaN compares False
        if not (len(values) == self._n and all(map(le, lo, values)) and all(map(le, values, hi))):
            # the reason, as the general checks give it
            x = finite_array("data", data, size=self._n, limit=self._limit())
            self.limits.check("positions", "the command", x)
            values = x.tolist()
        out = self._array_filter.process_values(values)
        lo, hi = self.limits.sample_bounds
        if not (all(map(le, lo, out)) and all(map(le, out, hi))):
            self._check_shaped({"array": (self._array_filter, np.array(values), "positions")}, {"array": np.array(out)})
        self._last_sent["array"] = out
        return out

    def _block_rows(self, msg: Float64MultiArray) -> int:
        """The samples a Float64MultiArray carries: one without a layout or with a layout of one dimension
        (forward_command_controller's input), and ``dim[0].size`` for a layout of two, [samples, joints] (the
        sim plant's lockstep exchange, ``lockstep.block``), whose rows are shaped in order as consecutive
        samples. A layout that does not describe the data, or a block of more than
        ``limits.max_trajectory_samples`` samples, is refused with the reason (InputError)."""
        dims = msg.layout.dim
        if len(dims) == 1:
            return 1
        shape = [int(d.size) for d in dims]
        if len(dims) != 2 or shape[1] != self._n or shape[0] * self._n != len(msg.data) or shape[0] < 1:
            raise InputError("wrong_size", f"layout {shape} does not describe samples x {self._n} joints in"
                             f" {len(msg.data)} values")
        if shape[0] > self._max_samples:
            raise InputError("too_large", f"a block of {shape[0]} samples is more than"
                             f" limits.max_trajectory_samples ({self._max_samples})")
        return shape[0]

    def _shape_block(self, data: Any, rows: int) -> list[float]:
        """A block of ``rows`` consecutive samples (row-major, samples x joints) shaped by the array filter in
        one call of its block path, with the checks and refusals of :meth:`_shape_checked`: a block with any
        sample refused is refused whole, and nothing of it stays in the filter. Returns the shaped values."""
        x = finite_array("data", data, size=rows * self._n, limit=self._limit()).reshape(rows, self._n)
        out = self._shape_checked({"array": (self._array_filter, x, "positions")})
        values: list[float] = out["array"].ravel().tolist()
        return values

    @property
    def _input_bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Per joint, the (lowest, highest) value a streamed position may take (limits.max_abs_value and the
        position limits; see :meth:`_shape_array`), recomputed when limits.max_abs_value changes."""
        max_abs = self._max_abs
        if self._bounds_for != max_abs:
            self._bounds = self.limits.input_bounds(max_abs)
            self._bounds_for = max_abs
        return self._bounds

    def _shape_checked(self, work: dict[str, tuple[Any, np.ndarray, str]]) -> dict[str, np.ndarray]:
        """Shape streamed samples with the output invariants held; ``work`` maps a key to (filter,
        samples, field: "positions", "velocities" or "accelerations").

        Inputs beyond the joint limits are refused before any filter (a sample inside them whose first
        impulse stays inside would otherwise pull every later output out, and the stream with it).
        Then each filter runs and its output is checked (:meth:`_check_shaped`). Raises the InputError."""
        for _, (_, x, field) in work.items():
            self.limits.check(field, "the command", x)
        out = {k: f.process(x) for k, (f, x, _) in work.items()}
        self._check_shaped(work, out)
        for k, y in out.items():
            self._last_sent[k] = np.atleast_2d(y)[-1].copy()
        return out

    def _check_shaped(self, work: dict[str, tuple[Any, np.ndarray, str]], out: dict[str, np.ndarray]) -> None:
        """Check the filters' outputs ``out`` (finite, within the limits); an output can leave them although
        its inputs did not (a switch between shapers, a custom shaper with negative impulses). Then nothing
        is passed on, and the filters of ``work`` restart at rest at the last command they passed on
        (refusing the sample while keeping their state would refuse every later one too: the state would
        not move on); the next sample is shaped from there. Their reset replaces all the state a sample
        changes, so nothing of the refused sample stays. Raises the InputError."""
        try:
            for k, y in out.items():
                if not np.all(np.isfinite(y)):
                    raise InputError("non_finite", f"the shaped {work[k][2]} would not be finite")
                self.limits.check(work[k][2], "the shaped command", y)
        except InputError as err:
            for k, (f, _, _) in work.items():
                f.reset(self._last_sent.get(k))
            raise InputError(err.kind, f"{err}; the filters restart from the last command passed on") from None

    def _on_stream(self, msg: JointTrajectory, info: dict[str, Any] | None) -> None:
        self._arrived("stream", info)
        topic = self._in_topics["stream_in"]
        try:
            _, fields = trajectory_arrays(msg, self.joint_names, require_times=False, limit=self._limit())
            with self.stream_lock:
                for f in fields:
                    if f not in self._stream_fields:  # a field that (re)appears starts at its first value
                        self._stream_filters[f].reset()
                        self._last_sent.pop(f"stream.{f}", None)
                shaped = self._shape_checked({f"stream.{f}": (self._stream_filters[f], v, f)
                                              for f, v in fields.items()})
                names = tuple(fields)
                for f in self._stream_fields:
                    if f not in names:  # gone: if it comes back it starts afresh
                        self._stream_filters[f].reset()
                        self._last_sent.pop(f"stream.{f}", None)
                self._stream_fields = names
        except InputError as err:
            self._reject(topic, err)
            return
        self._stream_pub.publish(trajectory_msg(msg.header, self.joint_names, [p.time_from_start for p in msg.points],
                                                {f: shaped[f"stream.{f}"] for f in names}))
        self._count_forwarded("stream")

    def whole_shaping(self, shaper: Shaper | None = None) -> WholeShaping:
        """What a whole trajectory is shaped with now: the active FIR, or ``shaper`` discretised as the
        active one is (ShaperError or ValueError if it cannot be), the limits in force."""
        fir = self._fir if shaper is None else discretize(shaper, self.rate, self._method)
        return WholeShaping(tuple(self.joint_names), self.rate, fir, self.limits, self._limit(), self._max_samples)

    def shape_whole(self, msg: JointTrajectory, shaper: Shaper | None = None) -> JointTrajectory:
        """Shape a whole trajectory with the active shaper, or with ``shaper`` (discretised as the
        active one is; the active shaper is not changed), and check it against the output invariants.
        Raises InputError on bad input or output, and ShaperError or ValueError if ``shaper`` cannot
        be discretised."""
        return self.whole_shaping(shaper).shape(msg, pause=_background_pause)

    def _on_trajectory(self, data: bytes) -> None:
        """The trajectory topic: the serialized message shaped in the worker process, published as bytes."""
        topic = self._in_topics["trajectory_in"]
        answer = self._worker.shape(self.whole_shaping(), data, WORKER_TIMEOUT)
        if answer[0] != "shaped":
            self._reject(topic, InputError(str(answer[1]), str(answer[2])))
            return
        self._traj_pub.publish(answer[1])
        self._count_forwarded("trajectory")

    def destroy_node(self) -> None:
        if self._stream_side is not None:  # the streamed inputs stop first
            self._stream_side.close()
            self._stream_side = None
        if self._action is not None:  # action servers and clients are not destroyed with the node
            self._action.destroy()
            self._action = None
        if self.pose_shaper is not None:
            self.pose_shaper.destroy()
            self.pose_shaper = None
        self._side.close()
        self._worker.close()
        super().destroy_node()

    def _on_shape_trajectory(self, req: ShapeTrajectory.Request,
                             resp: ShapeTrajectory.Response) -> ShapeTrajectory.Response:
        try:
            resp.shaped = self.shape_whole(req.trajectory)
            resp.success, resp.message = True, f"{len(resp.shaped.points)} points at {self.rate:g} Hz"
        except InputError as err:
            self._reject("~/shape_trajectory", err)
            resp.success, resp.message = False, str(err)
        return resp


def _background_pause() -> None:
    """Whole-trajectory work yields the interpreter to the stream for a while (see BACKGROUND_PAUSE)."""
    time.sleep(BACKGROUND_PAUSE)


def _tune_interpreter() -> None:
    """Thread switches within :data:`SWITCH_INTERVAL`; no full garbage collection while a long
    trajectory's messages are alive (each would scan them all, holding the interpreter for tens of ms):
    the objects made at start-up are frozen out of the collector and the oldest generation is
    collected only after :data:`GC_THRESHOLDS` [2] collections of the middle one. Messages hold no
    reference cycles, so they are freed by reference counting as before."""
    sys.setswitchinterval(SWITCH_INTERVAL)
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLDS)


def main(args: list[str] | None = None) -> int:
    _tune_interpreter()
    return run_node(ShaperNode, "shaper_node", args, examples=(
        with_config("shaper_nodes", "shaper_node", "shaper.yaml"),
        with_config("shaper_nodes", "shaper_node", "shaper.yaml",
                    "-r __node:=left_arm_shaper -p shaper.family:=zvd -p shaper.frequency_hz:=8")))


if __name__ == "__main__":
    raise SystemExit(main())
