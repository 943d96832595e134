"""The shaper node: a causal real-time FIR per joint between a motion source and a controller.

Inputs and outputs (topic names are parameters, see config/shaper.yaml)
-----------------------------------------------------------------------
topics.array_in -> topics.array_out
    std_msgs/Float64MultiArray, one setpoint per joint in ``joint_names`` order (the input of
    forward_command_controller), one sample per message at ``command_rate``. A message whose layout
    has two dimensions, [samples, joints], carries a block of consecutive samples (the sim plant's
    lockstep exchange, ``lockstep.block``): shaped as those samples one by one would be, and sent on
    as one message with the same layout. Taken and sent as serialized bytes, never as message
    objects (ros/raw_stream.py); bytes that are not a Float64MultiArray are refused as ``malformed``.
topics.stream_in -> topics.stream_out
    trajectory_msgs/JointTrajectory streamed with one or a few points per message (as MoveIt
    Servo does); every point is one sample at ``command_rate``; positions are shaped, and
    velocities and accelerations too when given. Taken and sent as serialized bytes as well.
topics.trajectory_in -> topics.trajectory_out, and service ~/shape_trajectory
    A whole trajectory for joint_trajectory_controller, resampled at ``command_rate`` and shaped.
action.server_name (~/follow_joint_trajectory) -> action.controller
    control_msgs/action/FollowJointTrajectory: each goal's trajectory shaped as above and
    forwarded to the controller's action, feedback, result and cancel relayed; a new goal
    preempts the running one (see trajectory_action.py). With ``action.scheduler`` set, each goal
    is shaped with the shaper that scheduler gives for the goal's final point (see
    ros/pose_shaper.py); the active shaper is not changed by it. ``~/shaped_goals``
    (shaper_msgs/ShapedGoal, ros/shaped_goals.py) says, per goal, what it was shaped with.
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
the reason (``/diagnostics``, the log, the service's or goal's answer) and publishes nothing. The
streamed inputs' rules (input bounds, joint limits, time order, the output check, the restart of the
filters after a refused output, blocks, fields that appear or vanish) are the core's
(core/shaping/stream.py); whole trajectories' are core/shaping/trajectory.py and limits.py.

Threads
-------
The streamed inputs (array, stream) are taken by a lean second node, ``<name>_stream``, served on a
thread of its own by a take loop (``stream_executor`` 'take', the default: one wait set built once,
ros/take_loop.py) or spun there by rclpy's executor ('thread'); it has nothing but those two
subscriptions (docs/results/benchmarks.md). Their topic names are resolved by this node, so
``~/commands`` is ``/<name>/commands`` as before. Shaper changes and parameters run in this node's
executor; :attr:`ShaperNode.stream_lock` keeps them between two streamed samples. With
``stream_executor`` 'node' the streamed inputs run in this node's executor as well. Whole
trajectories (topic, ``~/shape_trajectory``, the FollowJointTrajectory proxy) are served, under the
same names, by a side node ``<name>_trajectories`` on a thread of its own
(ros/side_node.py), so that the stream never waits for a long trajectory. Shaping a whole
trajectory only reads the active filter, never the streaming filters' state. The interpreter's
thread switch interval is shortened (:data:`SWITCH_INTERVAL` in nodes/shaper_interpreter.py) so that a thread
doing Python work on a long trajectory yields within a fraction of a command period.

Update policy (:mod:`shaper_nodes.core.shaping.policy`): every change names its source;
``allowed_sources`` lists the sources that may change the shaper (parameters count as source
"parameters"); every path gets the same check; the last accepted change wins, and a change that
replaces another source's shaper is reported; a setting that cannot take effect is refused
(docs/guide/shaper_node.md, "Who sets the shaper"). Changes from the sources in ``retime_sources``
(e.g. the scheduler) re-time the motion already commanded instead of switching bumplessly
(time-varying shaping, see core/shaping/fir.py). The active shaper, its revision and every change to it
(the design parameters, ``~/set_shaper``, ``~/get_shaper``, :meth:`ShaperNode.request`) are
:class:`ShaperChanges`'s (nodes/shaper_changes.py); this module wires it and serves the data paths.

Parameters: :class:`ShaperParams` and its table :data:`PARAMETERS` (names, defaults, ranges and descriptions;
config/shaper.yaml), written in nodes/shaper_parameters.py with what their values mean (the design, the joint
limits); the node reads them typed, ``self.params.value`` (kept up to date on every accepted change).
"""

from __future__ import annotations

from time import time_ns
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper, ShapeTrajectory
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.shaping import Shaper, UpdatePolicy, discretize
from shaper_nodes.core.shaping.stream import CommandStream
from shaper_nodes.ros.diagnostics import WARN, Diagnostics
from shaper_nodes.ros.graph_watch import GraphWatch
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import declare
from shaper_nodes.ros.pose_shaper import PoseShaperClient
from shaper_nodes.ros.qos import SERVICE_QOS
from shaper_nodes.ros.raw_stream import RawArrays, RawTrajectories
from shaper_nodes.ros.shaped_goals import ShapedGoals
from shaper_nodes.ros.side_node import SideNode
from shaper_nodes.ros.stream_watch import WATCH_PERIOD, StreamWatch, WorkTiming
from shaper_nodes.ros.whole_trajectory import TrajectoryWorker, WholeShaping

from .shaper_changes import ShaperChanges
from .shaper_interpreter import background_pause
from .shaper_interpreter import tune_interpreter as _tune_interpreter  # (benchmarks call it from here)
from .shaper_parameters import (  # the table and its constants, importable from here as before
    DEFAULT_MAX_SAMPLES,
    DESIGN_PARAMS,
    DISCRETIZATIONS,
    PARAMETERS,
    STREAM_EXECUTORS,
    TOPICS,
    ShaperParams,
    design_from_params,
    limits_from_params,
)
from .trajectory_action import TrajectoryActionProxy

__all__ = ["DEFAULT_MAX_SAMPLES", "DESIGN_PARAMS", "DISCRETIZATIONS", "PARAMETERS", "STREAM_EXECUTORS", "TOPICS",
           "ShaperNode", "ShaperParams", "main"]

#: s, the longest a whole trajectory may take in the worker process (300,000 samples take about 10 s)
WORKER_TIMEOUT = 120.0


class ShaperNode(Node):
    """Input-shaping node; see the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("shaper", *args, **kwargs)
        #: the parameters, typed (nodes/shaper_parameters.py), read again on every accepted change
        self.params = declare(self, ShaperParams)
        p = self.params.value
        self.joint_names = list(p.joint_names)
        if not self.joint_names or len(set(self.joint_names)) != len(self.joint_names):
            raise ValueError("parameter joint_names must be a non-empty list of distinct names")
        self.rate = float(p.command_rate)
        self.policy = UpdatePolicy.of(p.allowed_sources, p.retime_sources)
        n = len(self.joint_names)

        shaper, method = design_from_params(p, self.rate)
        fir = discretize(shaper, self.rate, method)
        self.limits = limits_from_params(self.joint_names, p.limits)  # the parameters' and the URDF's
        #: the streamed inputs' filters and rules (core/shaping/stream.py); it owns the stream lock
        self.stream = CommandStream(fir, self.limits, retiming=bool(self.policy.retime_sources),
                                    max_abs=float(p.limits.max_abs_value),
                                    max_samples=int(p.limits.max_trajectory_samples))
        #: held while a streamed sample is shaped and while the shaper changes (they run on different threads
        #: with stream_executor 'take' or 'thread'); a holder stalls the streamed inputs
        self.stream_lock = self.stream.lock
        self._array_filter = self.stream.array_filter
        self._raw_arrays = RawArrays(self.stream)  # the array input and output as serialized messages
        self._raw_trajectories = RawTrajectories(self.stream, self.joint_names)  # the stream topic's, likewise
        self.diagnostics = Diagnostics(self, lambda: float(self.params.value.error_throttle))
        # arrivals, rate watches, forwarded and refused counts (ros/stream_watch.py)
        self.watch = StreamWatch(self.rate, self.diagnostics, lambda k: self._subs[f"{k}_in"].get_publisher_count())
        self.rejections, self.forwarded, self.watched = self.watch.rejections, self.watch.forwarded, self.watch.watched
        self._arrived, self._count_forwarded, self._passed = (self.watch.arrived, self.watch.count_forwarded,
                                                              self.watch.passed)
        self._arrivals_max = self.watch.arrivals_max
        # whole trajectories: served by a side node on a thread of its own, never in the streaming thread
        self._side = SideNode(self, "trajectories")
        self._worker = TrajectoryWorker()  # the trajectory topic's shaping, in a process of its own
        side = self._side.node
        # the command path's endpoints are made through the graph watch, which looks from the side thread
        self.graph = GraphWatch(self, self.diagnostics, float(p.graph_watch.period), looker=side)

        tp = p.topics
        pubs: dict[str, Any] = {}

        def pub(name: str, typ: Any) -> Any:
            if name not in pubs:
                pubs[name] = self.graph.publisher(typ, name, 10)
            return pubs[name]

        self._array_pub = pub(tp.array_out, Float64MultiArray)
        self._stream_pub = pub(tp.stream_out, JointTrajectory)
        self._traj_pub = pub(tp.trajectory_out, JointTrajectory)
        #: the active shaper and its changes (nodes/shaper_changes.py): it makes the latched ~/active_shaper here
        self.changes = ShaperChanges(self, self.params, self.policy, self.stream, self.diagnostics, shaper, method,
                                     fir, self.rate)
        depth = int(p.queue_depth)
        # the streamed inputs: on a lean node of their own, spun on a thread of its own (the names resolved by
        # this node), or on this node
        self._stream_side: SideNode | None = None
        stream_node: Node = self
        streamed = {"array_in": tp.array_in, "stream_in": tp.stream_in}  # resolved here for a lean node of their own
        if str(p.stream_executor) != "node":  # thread, take (ros/take_loop.py)
            self._stream_side = SideNode(self, "stream", lean=True, take=str(p.stream_executor) == "take")
            stream_node = self._stream_side.node
            streamed = {k: self.resolve_topic_name(name) for k, name in streamed.items()}
        on_array: Any = self._on_array
        #: the array path's timers, with SHAPER_WORK_TIMING set (benchmarks; ros/stream_watch.py): None, no cost
        self.work_timing = WorkTiming.from_env()
        if self.work_timing is not None:  # the work (read, rules, FIR, write), the publish, the whole callback
            self.work_timing.patch(self._raw_arrays, "shape", "work")
            self.work_timing.patch(self._array_pub, "publish", "publish")
            on_array = self.work_timing.timed_callback(on_array)  # and its wake-up
        # two-argument callbacks: rclpy passes each message's info (stamps, sequence number) for the rate watch
        subs = {
            # raw: read and written as serialized bytes (ros/raw_stream.py)
            "array_in": self.graph.subscription(Float64MultiArray, streamed["array_in"], on_array, depth,
                                                on=stream_node, raw=True),
            "stream_in": self.graph.subscription(JointTrajectory, streamed["stream_in"], self._on_stream, depth,
                                                 on=stream_node, raw=True),
            # raw: the bytes go to the trajectory worker process undecoded (ros/whole_trajectory.py)
            "trajectory_in": self.graph.subscription(JointTrajectory, self.resolve_topic_name(tp.trajectory_in),
                                                     self._on_trajectory, 10, on=side, raw=True),
        }
        self._subs = subs
        self._in_topics = {k: sub.topic_name for k, sub in subs.items()}  # fully qualified, for messages
        self.create_service(SetShaper, "~/set_shaper", self.changes.on_set_shaper, qos_profile=SERVICE_QOS)
        self.create_service(GetShaper, "~/get_shaper", self.changes.on_get_shaper, qos_profile=SERVICE_QOS)
        side.create_service(ShapeTrajectory, self.resolve_service_name("~/shape_trajectory"),
                            self._on_shape_trajectory, qos_profile=SERVICE_QOS)
        self._action: TrajectoryActionProxy | None = None
        self.pose_shaper: PoseShaperClient | None = None
        server_name = str(p.action.server_name)
        action_topic = self.resolve_topic_name(server_name) if server_name else ""
        if server_name:
            scheduler = str(p.action.scheduler).strip()
            if scheduler:
                self.pose_shaper = PoseShaperClient(
                    side, scheduler, float(p.action.server_timeout), self.shape_whole, self.diagnostics,
                    max_gain=lambda: float(self.params.value.shaper.max_gain), rate=self.rate)
            self._action = TrajectoryActionProxy(
                side, action_topic, str(p.action.controller), self.shape_whole,
                on_refused=lambda err: self._reject(action_topic, err),
                on_forwarded=lambda: self._count_forwarded("action"),
                timeout=float(p.action.server_timeout), reshape=self.pose_shaper,
                on_late_start=lambda text: self.diagnostics.report("late_start", WARN, text, name="action"),
                on_sending=ShapedGoals(self, self.active_msg).tell)  # ~/shaped_goals (ros/shaped_goals.py)
        self.add_on_set_parameters_callback(self.changes.validate_params)
        self.add_post_set_parameters_callback(self.changes.apply_params)
        self.create_timer(float(p.diagnostics_period), self._publish_summary,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        if float(p.diagnostics_period) > WATCH_PERIOD:  # (each summary watches the arrivals too)
            self.create_timer(WATCH_PERIOD, self.watch.watch, clock=Clock(clock_type=ClockType.STEADY_TIME))
        #: which node of this process serves which input (``ros2 node info`` lists a node's own entities)
        self.side_nodes = {stream_node.get_fully_qualified_name(): "array_in, stream_in",
                           side.get_fully_qualified_name(): "trajectory_in, ~/shape_trajectory"
                           + (", action.server_name" if self._action else "")}
        self.changes.publish()
        self.graph.start()
        self._side.start()
        if self._stream_side is not None:
            self._stream_side.start()
        self.get_logger().info(
            f"shaping {n} joints at {self.rate:g} Hz with {self.changes.describe()};"
            f" {self._in_topics['array_in']} -> {self._array_pub.topic_name}"
            + (f"; FollowJointTrajectory {action_topic} -> {self._action.controller_name}" if self._action else "")
            + (f", each goal shaped for its final pose by {self.pose_shaper.srv_name}" if self.pose_shaper else "")
            + f"; {self.limits.describe()}; inputs served by "
            + "; ".join(f"{k} ({v})" for k, v in self.side_nodes.items()))

    # ----------------------------------------------------------------- the active shaper (nodes/shaper_changes.py)
    def request(self, shaper: Shaper, source: str) -> tuple[bool, str]:
        """Validate and make ``shaper`` active on behalf of ``source``; returns (accepted, why)."""
        return self.changes.request(shaper, source)

    def active_msg(self) -> ShaperMsg:
        """The active shaper as a message, stamped now."""
        return self.changes.msg()

    # ----------------------------------------------------------------- bad input, summary
    def _reject(self, topic: str, err: InputError) -> None:
        self.watch.refused(topic, err)

    def _publish_summary(self) -> None:
        c = self.changes
        head = [("revision", str(c.revision)), ("source", c.source), ("family", c.shaper.family),
                ("command_rate_hz", f"{self.rate:g}"),
                *((f"inputs on {k}", v) for k, v in self.side_nodes.items())]
        tail = [] if self.pose_shaper is None else [("action.scheduler.shaped", str(self.pose_shaper.shaped)),
                                                     ("action.scheduler.fallbacks", str(self.pose_shaper.fallbacks))]
        level, msg, values = self.watch.summary(f"shaping with {c.describe()}", head, tail)
        self.diagnostics.publish("shaper", level, msg, values)

    # ----------------------------------------------------------------- data paths
    def _on_array(self, data: bytes, info: dict[str, Any] | None) -> None:
        """The array input, serialized: shaped and published as bytes (ros/raw_stream.py); its arrival and
        count kept after the publish (the time it was taken read first)."""
        taken = time_ns()
        try:
            out = self._raw_arrays.shape(data)
        except InputError as err:
            self._arrived("array", info, taken)
            self._reject(self._in_topics["array_in"], err)
            return
        self._array_pub.publish(out)
        self._passed("array", info, taken)

    def _on_stream(self, data: bytes, info: dict[str, Any] | None) -> None:
        """The stream topic's JointTrajectory, serialized: shaped and published as bytes (ros/raw_stream.py)."""
        self._arrived("stream", info)
        try:
            out = self._raw_trajectories.shape(data)
        except InputError as err:
            self._reject(self._in_topics["stream_in"], err)
            return
        self._stream_pub.publish(out)
        self._count_forwarded("stream")

    def whole_shaping(self, shaper: Shaper | None = None) -> WholeShaping:
        """What a whole trajectory is shaped with now: the active FIR, or ``shaper`` discretised as the
        active one is (ShaperError or ValueError if it cannot be), the limits in force."""
        fir = self.changes.fir if shaper is None else discretize(shaper, self.rate, self.changes.method)
        return WholeShaping(tuple(self.joint_names), self.rate, fir, self.limits, self.stream.max_abs,
                            self.stream.max_samples)

    def shape_whole(self, msg: JointTrajectory, shaper: Shaper | None = None) -> JointTrajectory:
        """Shape a whole trajectory with the active shaper, or with ``shaper`` (discretised as the
        active one is; the active shaper is not changed), and check it against the output invariants.
        Raises InputError on bad input or output, and ShaperError or ValueError if ``shaper`` cannot
        be discretised."""
        return self.whole_shaping(shaper).shape(msg, pause=background_pause)

    def _on_trajectory(self, data: bytes) -> None:
        """The trajectory topic: the serialized message shaped in the worker process, published as bytes."""
        topic = self._in_topics["trajectory_in"]
        answer = self._worker.shape(self.whole_shaping(), data, WORKER_TIMEOUT)
        if answer[0] != "shaped":
            self._reject(topic, InputError(str(answer[1]), str(answer[2])))
            return
        self._traj_pub.publish(answer[1])
        self._count_forwarded("trajectory")

    def close(self) -> None:
        """The node stops (run_node, on SIGINT or SIGTERM): a FollowJointTrajectory goal still running is
        cancelled at the controller, waiting up to ``action.server_timeout`` s for it to end."""
        if self._action is not None:
            self._action.stop()

    def destroy_node(self) -> None:
        if self._stream_side is not None:  # the streamed inputs stop first
            self._stream_side.close()
            self._stream_side = None
        if self.work_timing is not None:
            self.work_timing.write()
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


def main(args: list[str] | None = None) -> int:
    _tune_interpreter()
    return run_node(ShaperNode, "shaper_node", args, examples=(
        with_config("shaper_nodes", "shaper_node", "shaper.yaml"),
        with_config("shaper_nodes", "shaper_node", "shaper.yaml",
                    "-r __node:=left_arm_shaper -p shaper.family:=zvd -p shaper.frequency_hz:=8")))


if __name__ == "__main__":
    raise SystemExit(main())
