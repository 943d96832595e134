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
    preempts the running one (see trajectory_action.py).
~/active_shaper (latched), ~/set_shaper, ~/get_shaper
    The active shaper, and changing or reading it. Changes (service or parameters) are
    validated first; a refused change leaves the active shaper as it was. Accepted changes are
    applied between two samples, bumplessly.
/diagnostics
    diagnostic_msgs/DiagnosticArray: every refused input (its class, throttled per class) and a
    periodic summary.

Update policy: every change names its source; ``allowed_sources`` lists the sources that may
change the shaper (parameters count as source "parameters"); the last accepted change wins.
Changes from the sources in ``retime_sources`` (e.g. the scheduler) re-time the motion already
commanded instead of switching bumplessly (time-varying shaping, see core/fir.py).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper, ShapeTrajectory
from shaper_nodes.core.checks import InputError, finite_array, joint_permutation, strictly_increasing
from shaper_nodes.core.shaping import (
    FAMILIES,
    MAX_STAGES,
    Mode,
    RetimingShaper,
    Shaper,
    ShaperError,
    StreamingShaper,
    design,
    discretize,
    shape_trajectory,
)
from shaper_nodes.ros.conversions import duration_to_sec, sec_to_duration, shaper_from_msg, shaper_to_msg
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import describe as _desc

from .trajectory_action import TrajectoryActionProxy

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
DESIGN_PARAMS = ("shaper.family", "shaper.frequency_hz", "shaper.damping_ratio",
                 "shaper.derivative_order", "shaper.vibration_tolerance", "shaper.insensitivity",
                 "discretization")
TRAJ_FIELDS = ("positions", "velocities", "accelerations")


class ShaperNode(Node):
    """Input-shaping node; see the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("shaper", *args, **kwargs)
        self.declare_parameter("joint_names", Parameter.Type.STRING_ARRAY, _desc(
            "Joints to shape, in the order of Float64MultiArray data and of the outputs.", read_only=True))
        self.declare_parameter("command_rate", 500.0, _desc(
            "Rate of the streamed setpoints and of whole-trajectory resampling, Hz.", 1.0, 10000.0, read_only=True))
        self.declare_parameter("shaper.family", "none", _desc(
            "Shaper family: " + ", ".join(f"{k} ({v})" for k, v in FAMILIES.items() if k != "custom")))
        self.declare_parameter("shaper.frequency_hz", 10.0, _desc(
            "Natural frequency of the mode to shape for, Hz (undamped).", 0.01, 1000.0))
        self.declare_parameter("shaper.damping_ratio", 0.05, _desc(
            "Damping ratio of the mode to shape for, dimensionless.", 0.0, 0.95))
        self.declare_parameter("shaper.derivative_order", 2, _desc(
            "n of the ZV-D^n family (family zvdn): 0 = ZV, 1 = ZVD, 2 = ZVDD.", 0, 10, integer=True))
        self.declare_parameter("shaper.vibration_tolerance", 0.05, _desc(
            "EI, multi-hump EI and SI families: tolerated percentage vibration, fraction (0.05 = 5 %).", 0.001, 0.3))
        self.declare_parameter("shaper.insensitivity", 0.4, _desc(
            "SI family: width of the band where V <= vibration_tolerance, fraction of the design frequency"
            " (0.4 = +-20 %).", 0.01, 1.5))
        self.declare_parameter("discretization", "split", _desc(
            "Impulse times between samples: 'split' linearly between the two samples (default), 'round', or"
            " 'exact' (the split corrected so the FIR meets the shaper's conditions at its modes exactly)."))
        self.declare_parameter("allowed_sources", ["parameters", "service", "learner", "scheduler", "identification", "user"], _desc(
            "Sources allowed to change the active shaper (update policy).", read_only=True))
        self.declare_parameter("retime_sources", Parameter.Type.STRING_ARRAY, _desc(
            "Sources whose changes re-time the motion already commanded (time-varying shaping: pending"
            " impulses follow the new shaper, e.g. 'scheduler' for pose-dependent modes) instead of the"
            " bumpless switch that leaves it to the old shaper. Default none.", read_only=True))
        self.declare_parameter("error_throttle", 1.0, _desc(
            "Least time between two error logs or diagnostics of the same class of bad input, s.", 0.0, 3600.0))
        self.declare_parameter("diagnostics_period", 1.0, _desc(
            "Period of the diagnostics summary, s.", 0.05, 3600.0, read_only=True))
        topics = {
            "array_in": "~/commands", "array_out": "/forward_position_controller/commands",
            "stream_in": "~/joint_trajectory_stream", "stream_out": "/joint_trajectory_controller/joint_trajectory",
            "trajectory_in": "~/joint_trajectory", "trajectory_out": "/joint_trajectory_controller/joint_trajectory",
        }
        for key, default in topics.items():
            self.declare_parameter(f"topics.{key}", default, _desc(f"Topic name ({key}).", read_only=True))
        self.declare_parameter("action.server_name", "~/follow_joint_trajectory", _desc(
            "FollowJointTrajectory action served by this node; empty: no action server.", read_only=True))
        self.declare_parameter("action.controller", "/joint_trajectory_controller/follow_joint_trajectory", _desc(
            "The controller's FollowJointTrajectory action that shaped goals are forwarded to.", read_only=True))
        self.declare_parameter("action.server_timeout", 2.0, _desc(
            "How long a goal waits for the controller's action server and for its answer to the goal"
            " request, s.", 0.01, 3600.0, read_only=True))

        self.joint_names = list(self.get_parameter("joint_names").value or [])
        if not self.joint_names or len(set(self.joint_names)) != len(self.joint_names):
            raise ValueError("parameter joint_names must be a non-empty list of distinct names")
        self.rate = float(self.get_parameter("command_rate").value)
        self.allowed_sources = set(self.get_parameter("allowed_sources").value)
        try:
            self.retime_sources = set(self.get_parameter("retime_sources").value)
        except ParameterUninitializedException:  # not set: none
            self.retime_sources = set()
        n = len(self.joint_names)
        filt = RetimingShaper if self.retime_sources else StreamingShaper

        shaper, method = self._design_from_params({})
        self._method = method
        self._shaper = shaper
        self._fir = discretize(shaper, self.rate, method)
        self._source = "parameters"
        self._revision = 1
        self._array_filter = filt(self._fir, n)
        self._stream_filters = {f: filt(self._fir, n) for f in TRAJ_FIELDS}
        self._stream_fields: tuple[str, ...] | None = None
        self._pending_params: tuple[Shaper, str] | None = None

        self.rejections: Counter[str] = Counter()
        self.forwarded = Counter()
        self._last_report: dict[str, float] = {}
        self._window_rejections = 0

        tp = {k: self.get_parameter(f"topics.{k}").value for k in topics}
        pubs: dict[str, object] = {}

        def pub(name: str, typ):
            if name not in pubs:
                pubs[name] = self.create_publisher(typ, name, 10)
            return pubs[name]

        self._array_pub = pub(tp["array_out"], Float64MultiArray)
        self._stream_pub = pub(tp["stream_out"], JointTrajectory)
        self._traj_pub = pub(tp["trajectory_out"], JointTrajectory)
        self._active_pub = self.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
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
        server_name = str(self.get_parameter("action.server_name").value)
        action_topic = self.resolve_topic_name(server_name) if server_name else ""
        if server_name:
            self._action = TrajectoryActionProxy(
                self, server_name, str(self.get_parameter("action.controller").value), self.shape_whole,
                on_refused=lambda err: self._reject(action_topic, err),
                on_forwarded=lambda: self.forwarded.update(["action"]),
                timeout=float(self.get_parameter("action.server_timeout").value))
        self.add_on_set_parameters_callback(self._validate_params)
        self.add_post_set_parameters_callback(self._apply_params)
        self.create_timer(float(self.get_parameter("diagnostics_period").value), self._publish_summary,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._publish_active()
        self.get_logger().info(
            f"shaping {n} joints at {self.rate:g} Hz with {self._describe()};"
            f" {self._in_topics['array_in']} -> {self._array_pub.topic_name}"
            + (f"; FollowJointTrajectory {action_topic} -> {self._action.controller_name}" if self._action else ""))

    # ----------------------------------------------------------------- shaper changes
    def _describe(self) -> str:
        s = self._shaper
        modes = ", ".join(f"{m.hz:.4g} Hz zeta {m.zeta:.3g}" for m in s.modes)
        return f"{s.family} ({len(s)} impulses, {s.duration * 1e3:.1f} ms{', ' + modes if modes else ''})"

    def _design_from_params(self, overrides: dict[str, object]) -> tuple[Shaper, str]:
        def val(name: str):
            return overrides[name] if name in overrides else self.get_parameter(name).value

        method = str(val("discretization"))
        if method not in ("split", "round", "exact"):
            raise ShaperError(f"discretization must be 'split', 'round' or 'exact', got {method!r}")
        family = str(val("shaper.family")).strip().lower()
        if family == "custom":
            raise ShaperError("family 'custom' is set through the ~/set_shaper service, not parameters")
        freq = float(val("shaper.frequency_hz"))
        if family != "none" and freq >= self.rate / 4.0:
            raise ShaperError(
                f"shaper.frequency_hz {freq:g} Hz is too high for command_rate {self.rate:g} Hz"
                f" (must be below rate / 4 = {self.rate / 4:g} Hz)")
        shaper = design(family, [Mode.from_hz(freq, float(val("shaper.damping_ratio")))],
                        derivative_order=int(val("shaper.derivative_order")),
                        vibration_tolerance=float(val("shaper.vibration_tolerance")),
                        insensitivity=float(val("shaper.insensitivity")))
        return shaper, method

    def _validate_params(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in DESIGN_PARAMS}
        if not changes:
            return SetParametersResult(successful=True)
        if "parameters" not in self.allowed_sources:
            return SetParametersResult(successful=False, reason="update policy: source 'parameters' not allowed")
        try:
            shaper, method = self._design_from_params(changes)
            self._check_switchable()
        except (ShaperError, RuntimeError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        self._pending_params = (shaper, method)
        return SetParametersResult(successful=True)

    def _apply_params(self, params: list[Parameter]) -> None:
        pending, self._pending_params = self._pending_params, None
        if pending is not None:
            self._commit(pending[0], "parameters", pending[1])

    def _check_switchable(self) -> None:
        for f in [self._array_filter, *self._stream_filters.values()]:
            if f.stages >= MAX_STAGES:
                raise RuntimeError(f"{f.stages} shaper changes are still settling; try again shortly")

    def request(self, shaper: Shaper, source: str) -> tuple[bool, str]:
        """Validate and make ``shaper`` active on behalf of ``source``; returns (accepted, why)."""
        if source not in self.allowed_sources:
            return False, f"update policy: source {source!r} is not in allowed_sources {sorted(self.allowed_sources)}"
        if shaper.family != "none" and shaper.duration > 0 and shaper.duration * self.rate < 1.0:
            return False, (f"shaper duration {shaper.duration * 1e3:.3g} ms is shorter than one"
                           f" command period ({1e3 / self.rate:.3g} ms)")
        try:
            if source not in self.retime_sources:
                self._check_switchable()
            self._commit(shaper, source, self._method)
        except (RuntimeError, ValueError) as err:
            return False, str(err)
        return True, f"active: {self._describe()}, revision {self._revision}"

    def _commit(self, shaper: Shaper, source: str, method: str) -> None:
        fir = discretize(shaper, self.rate, method)  # may raise; nothing changed yet
        for f in [self._array_filter, *self._stream_filters.values()]:
            f.retime(fir) if source in self.retime_sources else f.switch(fir)
        self._shaper, self._fir, self._source, self._method = shaper, fir, source, method
        self._revision += 1
        self._publish_active()
        self.get_logger().info(f"shaper changed by {source}: {self._describe()}, revision {self._revision}")

    def active_msg(self) -> ShaperMsg:
        return shaper_to_msg(self._shaper, self._source, self._revision, self.get_clock().now().to_msg())

    def _publish_active(self) -> None:
        self._active_pub.publish(self.active_msg())

    def _on_set_shaper(self, req: SetShaper.Request, resp: SetShaper.Response) -> SetShaper.Response:
        source = req.shaper.source.strip() or "service"
        try:
            shaper = shaper_from_msg(req.shaper)
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
        throttle = float(self.get_parameter("error_throttle").value)
        now = time.monotonic()
        if now - self._last_report.get(err.kind, -1e18) < throttle:
            return
        self._last_report[err.kind] = now
        self.get_logger().error(f"refused message on {topic}: {err} (not forwarded)")
        status = DiagnosticStatus(
            level=DiagnosticStatus.ERROR, name=f"{self.get_name()}: input", hardware_id=self.get_fully_qualified_name(),
            message=f"refused {err.kind} on {topic}: {err}",
            values=[KeyValue(key="kind", value=err.kind), KeyValue(key="topic", value=topic),
                    KeyValue(key="count", value=str(self.rejections[err.kind]))])
        self._diag_pub.publish(DiagnosticArray(header=self._header_now(), status=[status]))

    def _header_now(self):
        from std_msgs.msg import Header

        return Header(stamp=self.get_clock().now().to_msg())

    def _publish_summary(self) -> None:
        level = DiagnosticStatus.WARN if self._window_rejections else DiagnosticStatus.OK
        msg = (f"{self._window_rejections} messages refused in the last period" if self._window_rejections
               else f"shaping with {self._describe()}")
        self._window_rejections = 0
        values = [KeyValue(key="revision", value=str(self._revision)), KeyValue(key="source", value=self._source),
                  KeyValue(key="family", value=self._shaper.family)]
        values += [KeyValue(key=f"forwarded.{k}", value=str(v)) for k, v in sorted(self.forwarded.items())]
        values += [KeyValue(key=f"refused.{k}", value=str(v)) for k, v in sorted(self.rejections.items())]
        status = DiagnosticStatus(level=level, name=f"{self.get_name()}: shaper",
                                  hardware_id=self.get_fully_qualified_name(), message=msg, values=values)
        self._diag_pub.publish(DiagnosticArray(header=self._header_now(), status=[status]))

    # ----------------------------------------------------------------- data paths
    def _on_array(self, msg: Float64MultiArray) -> None:
        try:
            x = finite_array("data", msg.data, size=len(self.joint_names))
        except InputError as err:
            self._reject(self._in_topics["array_in"], err)
            return
        out = Float64MultiArray(layout=msg.layout)
        out.data = self._array_filter.process(x).tolist()
        self._array_pub.publish(out)
        self.forwarded["array"] += 1

    def _trajectory_arrays(self, msg: JointTrajectory, require_times: bool) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        perm = joint_permutation(self.joint_names, msg.joint_names)
        if not msg.points:
            raise InputError("empty", "trajectory has no points")
        n = len(self.joint_names)
        times = np.array([duration_to_sec(p.time_from_start) for p in msg.points])
        if require_times or len(times) > 1:
            strictly_increasing("time_from_start", times)
        fields: dict[str, np.ndarray] = {}
        for f in TRAJ_FIELDS:
            present = [len(getattr(p, f)) > 0 for p in msg.points]
            if f == "positions" and not all(present):
                raise InputError("empty", "every point needs positions")
            if any(present) and not all(present):
                raise InputError("inconsistent_fields", f"{f} given for some points but not all")
            if all(present):
                rows = [finite_array(f"point {i} {f}", getattr(p, f), size=n) for i, p in enumerate(msg.points)]
                fields[f] = np.vstack(rows)[:, perm]
        return times, fields

    def _on_stream(self, msg: JointTrajectory) -> None:
        topic = self._in_topics["stream_in"]
        try:
            times, fields = self._trajectory_arrays(msg, require_times=False)
            names = tuple(fields)
            if self._stream_fields is not None and names != self._stream_fields:
                raise InputError("inconsistent_fields",
                                 f"fields {list(names)} differ from the stream's {list(self._stream_fields)}")
        except InputError as err:
            self._reject(topic, err)
            return
        self._stream_fields = names
        shaped = {f: self._stream_filters[f].process(v) for f, v in fields.items()}
        out = JointTrajectory(header=msg.header, joint_names=list(self.joint_names))
        for i, p in enumerate(msg.points):
            pt = JointTrajectoryPoint(time_from_start=p.time_from_start)
            for f, v in shaped.items():
                setattr(pt, f, v[i].tolist())
            out.points.append(pt)
        self._stream_pub.publish(out)
        self.forwarded["stream"] += 1

    def shape_whole(self, msg: JointTrajectory) -> JointTrajectory:
        """Shape a whole trajectory (raises InputError on bad input)."""
        times, fields = self._trajectory_arrays(msg, require_times=True)
        result = shape_trajectory(times, fields["positions"], self._fir, self.rate, fields.get("velocities"))
        out = JointTrajectory(header=msg.header, joint_names=list(self.joint_names))
        for k in range(result.times.size):
            out.points.append(JointTrajectoryPoint(
                positions=result.positions[k].tolist(), velocities=result.velocities[k].tolist(),
                accelerations=result.accelerations[k].tolist(), time_from_start=sec_to_duration(result.times[k])))
        return out

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
        super().destroy_node()

    def _on_shape_trajectory(self, req, resp):
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
