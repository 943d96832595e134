"""The shaper node: a causal real-time FIR per joint between a motion source and a controller.

Inputs and outputs (topic names are parameters, see config/shaper.yaml)
-----------------------------------------------------------------------
topics.array_in -> topics.array_out
    std_msgs/Float64MultiArray, one setpoint per joint in ``joint_names`` order (the input of
    forward_command_controller), one sample per message at ``command_rate``.
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
    periodic summary.

Update policy (:mod:`shaper_nodes.core.shaping.policy`): every change names its source;
``allowed_sources`` lists the sources that may change the shaper (parameters count as source
"parameters"); the last accepted change wins. Changes from the sources in ``retime_sources``
(e.g. the scheduler) re-time the motion already commanded instead of switching bumplessly
(time-varying shaping, see core/shaping/fir.py).

Parameters: :data:`PARAMETERS` (names, defaults, ranges and descriptions; config/shaper.yaml).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

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
    shape_trajectory,
)
from shaper_nodes.core.shaping.policy import PARAMETERS_SOURCE
from shaper_nodes.ros.conversions import TRAJ_FIELDS, shaper_from_msg, shaper_to_msg, trajectory_arrays, trajectory_msg
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import Spec, declare_all, topics, values
from shaper_nodes.ros.pose_shaper import PoseShaperClient
from shaper_nodes.ros.qos import LATCHED

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
    Spec("allowed_sources", ["parameters", "service", "learner", "scheduler", "identification", "user"],
         "Sources allowed to change the active shaper (update policy).", read_only=True),
    Spec("retime_sources", None, "Sources whose changes re-time the motion already commanded (time-varying"
         " shaping: pending impulses follow the new shaper, e.g. 'scheduler' for pose-dependent modes) instead of"
         " the bumpless switch that leaves it to the old shaper. Default none.", read_only=True,
         type=Parameter.Type.STRING_ARRAY),
    Spec("error_throttle", 1.0, "Least time between two error logs or diagnostics of the same class of bad input,"
         " s.", (0.0, 3600.0)),
    Spec("diagnostics_period", 1.0, "Period of the diagnostics summary, s.", (0.05, 3600.0), read_only=True),
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
        self._stream_fields: tuple[str, ...] | None = None
        self._pending_params: tuple[Shaper, str] | None = None
        self._max_abs = float(p("limits.max_abs_value").value)

        self.rejections: Counter[str] = Counter()
        self.forwarded: Counter[str] = Counter()
        self._window_rejections = 0
        self.diagnostics = Diagnostics(self, lambda: float(p("error_throttle").value))

        tp = {k: p(f"topics.{k}").value for k in TOPICS}
        pubs: dict[str, Any] = {}

        def pub(name: str, typ: Any) -> Any:
            if name not in pubs:
                pubs[name] = self.create_publisher(typ, name, 10)
            return pubs[name]

        self._array_pub = pub(tp["array_out"], Float64MultiArray)
        self._stream_pub = pub(tp["stream_out"], JointTrajectory)
        self._traj_pub = pub(tp["trajectory_out"], JointTrajectory)
        self._active_pub = self.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)
        subs = {
            "array_in": self.create_subscription(Float64MultiArray, tp["array_in"], self._on_array, 10),
            "stream_in": self.create_subscription(JointTrajectory, tp["stream_in"], self._on_stream, 10),
            "trajectory_in": self.create_subscription(JointTrajectory, tp["trajectory_in"], self._on_trajectory, 10),
        }
        self._in_topics = {k: sub.topic_name for k, sub in subs.items()}  # fully qualified, for messages
        self.create_service(SetShaper, "~/set_shaper", self._on_set_shaper)
        self.create_service(GetShaper, "~/get_shaper", self._on_get_shaper)
        self.create_service(ShapeTrajectory, "~/shape_trajectory", self._on_shape_trajectory)
        self._action: TrajectoryActionProxy | None = None
        self.pose_shaper: PoseShaperClient | None = None
        server_name = str(p("action.server_name").value)
        action_topic = self.resolve_topic_name(server_name) if server_name else ""
        if server_name:
            scheduler = str(p("action.scheduler").value).strip()
            if scheduler:
                self.pose_shaper = PoseShaperClient(
                    self, scheduler, float(p("action.server_timeout").value), self.shape_whole, self.diagnostics,
                    max_gain=lambda: float(p("shaper.max_gain").value), rate=self.rate)
            self._action = TrajectoryActionProxy(
                self, server_name, str(p("action.controller").value), self.shape_whole,
                on_refused=lambda err: self._reject(action_topic, err),
                on_forwarded=lambda: self.forwarded.update(["action"]),
                timeout=float(p("action.server_timeout").value), reshape=self.pose_shaper)
        self.add_on_set_parameters_callback(self._validate_params)
        self.add_post_set_parameters_callback(self._apply_params)
        self.create_timer(float(p("diagnostics_period").value), self._publish_summary,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._publish_active()
        self.get_logger().info(
            f"shaping {n} joints at {self.rate:g} Hz with {self._describe()};"
            f" {self._in_topics['array_in']} -> {self._array_pub.topic_name}"
            + (f"; FollowJointTrajectory {action_topic} -> {self._action.controller_name}" if self._action else "")
            + (f", each goal shaped for its final pose by {self.pose_shaper.srv_name}" if self.pose_shaper else ""))

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
        self._pending_params = (shaper, method)
        return SetParametersResult(successful=True)

    def _apply_params(self, params: list[Parameter]) -> None:
        for param in params:
            if param.name == "limits.max_abs_value":
                self._max_abs = float(param.value)
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
        self.rejections[err.kind] += 1
        self._window_rejections += 1
        self.diagnostics.report(err.kind, ERROR, f"refused {err.kind} on {topic}: {err} (not forwarded)",
                                name="input", values=[("topic", topic), ("count", str(self.rejections[err.kind]))])

    def _publish_summary(self) -> None:
        level = WARN if self._window_rejections else OK
        msg = (f"{self._window_rejections} messages refused in the last period" if self._window_rejections
               else f"shaping with {self._describe()}")
        self._window_rejections = 0
        values = [("revision", str(self._revision)), ("source", self._source), ("family", self._shaper.family)]
        values += [(f"forwarded.{k}", str(v)) for k, v in sorted(self.forwarded.items())]
        if self.pose_shaper is not None:
            values += [("action.scheduler.shaped", str(self.pose_shaper.shaped)),
                       ("action.scheduler.fallbacks", str(self.pose_shaper.fallbacks))]
        values += [(f"refused.{k}", str(v)) for k, v in sorted(self.rejections.items())]
        self.diagnostics.publish("shaper", level, msg, values)

    # ----------------------------------------------------------------- data paths
    def _limit(self) -> float:
        """limits.max_abs_value (cached: read on every sample)."""
        return self._max_abs

    def _on_array(self, msg: Float64MultiArray) -> None:
        try:
            x = finite_array("data", msg.data, size=len(self.joint_names), limit=self._limit())
        except InputError as err:
            self._reject(self._in_topics["array_in"], err)
            return
        out = Float64MultiArray(layout=msg.layout)
        out.data = self._array_filter.process(x).tolist()
        self._array_pub.publish(out)
        self.forwarded["array"] += 1

    def _on_stream(self, msg: JointTrajectory) -> None:
        topic = self._in_topics["stream_in"]
        try:
            _, fields = trajectory_arrays(msg, self.joint_names, require_times=False, limit=self._limit())
            names = tuple(fields)
            if self._stream_fields is not None and names != self._stream_fields:
                raise InputError("inconsistent_fields",
                                 f"fields {list(names)} differ from the stream's {list(self._stream_fields)}")
        except InputError as err:
            self._reject(topic, err)
            return
        self._stream_fields = names
        shaped = {f: self._stream_filters[f].process(v) for f, v in fields.items()}
        self._stream_pub.publish(trajectory_msg(msg.header, self.joint_names,
                                                [p.time_from_start for p in msg.points], shaped))
        self.forwarded["stream"] += 1

    def shape_whole(self, msg: JointTrajectory, shaper: Shaper | None = None) -> JointTrajectory:
        """Shape a whole trajectory with the active shaper, or with ``shaper`` (discretised as the
        active one is; the active shaper is not changed). Raises InputError on bad input, and
        ShaperError or ValueError if ``shaper`` cannot be discretised."""
        fir = self._fir if shaper is None else discretize(shaper, self.rate, self._method)
        times, fields = trajectory_arrays(msg, self.joint_names, require_times=True, limit=self._limit())
        result = shape_trajectory(times, fields["positions"], fir, self.rate, fields.get("velocities"))
        return trajectory_msg(msg.header, self.joint_names, result.times,
                              {"positions": result.positions, "velocities": result.velocities,
                               "accelerations": result.accelerations})

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        topic = self._in_topics["trajectory_in"]
        try:
            out = self.shape_whole(msg)
        except InputError as err:
            self._reject(topic, err)
            return
        self._traj_pub.publish(out)
        self.forwarded["trajectory"] += 1

    def destroy_node(self) -> None:
        if self._action is not None:  # action servers and clients are not destroyed with the node
            self._action.destroy()
            self._action = None
        if self.pose_shaper is not None:
            self.pose_shaper.destroy()
            self.pose_shaper = None
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


def main(args: list[str] | None = None) -> int:
    return run_node(ShaperNode, "shaper_node", args)


if __name__ == "__main__":
    raise SystemExit(main())
