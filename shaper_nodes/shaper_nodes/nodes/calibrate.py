"""calibrate: measure the arm's modes over its workspace and write the scheduler's rule base.

    ros2 run shaper_nodes calibrate --ros-args --params-file calibrate.yaml        # print the plan
    ros2 run shaper_nodes calibrate --execute --out DIR --ros-args --params-file calibrate.yaml
    ros2 run shaper_nodes calibrate --execute --resume --out DIR --ros-args ...  # after a stop
    ros2 run shaper_nodes calibrate --from-bag DIR/recording --out DIR2           # recompute offline

Without ``--execute`` it prints the plan (poses, excitation, duration) and moves nothing: it
moves a real robot. With it, for each pose of the plan (:mod:`shaper_nodes.core.calibration.plan`)
it sends ``control_msgs/action/FollowJointTrajectory`` goals (the controller's action, or the
shaper node's proxy with the shaper set to ``none``): the approach, then ``repeats`` out-and-back
excitations each followed by ``decay`` s of free vibration, and records the accelerometer, the
joint states and its own events to ``DIR/recording/pose_NNN`` (a rosbag2 folder with MCAP
storage, chunks zstd-compressed with ``compression: zstd``, written as ``pose_NNN.partial`` and renamed,
its MCAP file ``pose_NNN.mcap`` with it, when the pose is complete). At the end it
goes back home and writes, from the recording (:mod:`shaper_nodes.analysis.calibration`),
``report.json``, ``report.md`` with figures, ``scheduler.yaml`` and ``shaper.yaml``.

Stops: a goal the controller rejects or aborts, a missing action server or accelerometer, or
Ctrl-C (the running goal is cancelled at the controller) end the run with a message naming the
cause; the pose in progress is discarded, completed poses stay, no report is written, and
``--resume`` continues from the first pose not completed (also after ``kill -9``). A refused
plan (limits, sizes) writes nothing.

Every wait is on the robot's data (feedback stamps, accelerometer stamps), so it runs the same
on a robot, on a simulator in lockstep, or under load. Parameters: :data:`PARAMETERS`
(config/calibrate.yaml).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import pathlib
import shutil
import struct
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rclpy.parameter import Parameter

from shaper_nodes.analysis.calibration import (
    EVENTS_TOPIC,
    SETUP_TOPIC,
    compute,
    plan_from_setup,
    pose_folders,
    read_recording,
    setup_dict,
)
from shaper_nodes.analysis.calibration_report import write_outputs
from shaper_nodes.core.calibration import IdentifySettings, Plan, PlanConfig, PlanError, PoseStep, Waypoint
from shaper_nodes.core.calibration.plan import MAX_AMPLITUDE, make_limits, make_plan, quintic_time
from shaper_nodes.core.calibration.plan import approach as plan_approach
from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.core.files import write_atomic
from shaper_nodes.recordings import COMPRESSIONS
from shaper_nodes.ros.conversions import time_to_sec
from shaper_nodes.ros.parameters import Spec, declare_all, param, table, unflat

EXIT_REFUSED, EXIT_ABORTED, EXIT_CANCELLED = 2, 1, 130
POLL = 0.02  # s, executor spin granularity
_SA, _DA = Parameter.Type.STRING_ARRAY, Parameter.Type.DOUBLE_ARRAY


class Aborted(RuntimeError):
    """The run stopped: the message names why."""


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

    server: float = param(30.0, "Wait for the action server and each goal's answer, s (wall).", (0.1, 3600.0),
                          read_only=True)
    data: float = param(30.0, "Wait for joint states and accelerometer data, s (wall).", (0.1, 3600.0),
                        read_only=True)
    result: float = param(600.0, "Wait for a goal's result, s (wall).", (1.0, 36000.0), read_only=True)
    peer: float = param(10.0, "While a goal runs, the controller's silence that ends the run, s (wall): no feedback"
                        " for this long, or its action server gone from the graph (at once), is a dead or stalled"
                        " controller (the DDS lease alone takes 20 s to notice a killed process).",
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


class Calibrator:
    """The ROS side of a calibration run: a node, its action client, its subscriptions and the recording."""

    def __init__(self, node: Any, executor: Any, params: CalibrateParams) -> None:
        from control_msgs.action import FollowJointTrajectory
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu, JointState

        from shaper_nodes.ros.action_client import ResilientActionClient
        from shaper_nodes.ros.lockstep_reader import STREAM_QOS, LockstepReader

        self.node, self.executor, self.p = node, executor, params
        self.names = list(params.joint_names)
        self.position: np.ndarray | None = None
        self.imu_stamp = -math.inf
        self.writer: Any = None
        self.goal: Any = None
        reliability = ReliabilityPolicy.RELIABLE if params.topics.imu_reliable else ReliabilityPolicy.BEST_EFFORT
        deep = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=reliability)
        self.imu_topic = params.topics.imu
        self.js_topic = params.topics.joint_states
        # a lockstep sim plant that names this node in lockstep.readers waits for it; gaps in the stamps are losses
        self.lockstep = LockstepReader(node, {self.imu_topic: None, self.js_topic: None})
        node.create_subscription(Imu, self.imu_topic, self._on_imu, deep, raw=True)
        node.create_subscription(JointState, self.js_topic, self._on_joint_states, STREAM_QOS)
        self.action = ResilientActionClient(node, FollowJointTrajectory, params.action)
        self._fjt = FollowJointTrajectory

    # ------------------------------------------------------------------ data
    def _record(self, topic: str, type_name: str, msg: Any, stamp: float) -> None:
        if self.writer is not None:
            from rclpy.serialization import serialize_message

            self.writer.add_topic(topic, type_name)
            self.writer.write(topic, int(round(stamp * 1e9)), serialize_message(msg))

    def _on_imu(self, raw: bytes) -> None:
        """Raw CDR (the cheapest callback at the simulator's rates): the header stamp read in place."""
        sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)
        t = sec + nanosec * 1e-9
        self.imu_stamp = max(self.imu_stamp, t)
        self.lockstep.took(self.imu_topic, t)
        if self.writer is not None:
            self.writer.add_topic(self.imu_topic, "sensor_msgs/msg/Imu")
            self.writer.write(self.imu_topic, sec * 1_000_000_000 + nanosec, raw)

    def _on_joint_states(self, msg: Any) -> None:
        try:
            self.position = np.array([msg.position[list(msg.name).index(j)] for j in self.names], dtype=float)
        except (ValueError, IndexError):
            return
        self.lockstep.took(self.js_topic, time_to_sec(msg.header.stamp))
        self._record(self.js_topic, "sensor_msgs/msg/JointState", msg, time_to_sec(msg.header.stamp))

    # ------------------------------------------------------------------ waiting
    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise Aborted(f"no {what} within {timeout:g} s")
            self.executor.spin_once(timeout_sec=POLL)

    def wait_pose(self) -> np.ndarray:
        self.spin_until(lambda: self.position is not None, float(self.p.timeouts.data),
                        f"joint states with {', '.join(self.names)} on {self.js_topic}")
        assert self.position is not None
        return self.position.copy()

    def wait_imu(self, stamp: float, what: str) -> None:
        self.spin_until(lambda: self.imu_stamp >= stamp, float(self.p.timeouts.data),
                        f"accelerometer data on {self.imu_topic} up to {what} (t = {stamp:.3f} s)")

    def _await_result(self, result: Any, stamps: list[float], what: str) -> None:
        """Wait for a goal's result while watching the controller (timeouts.peer): its action server must stay
        in the graph, and its feedback (20 Hz of its time while a goal runs) must keep coming."""
        silence = float(self.p.timeouts.peer)
        deadline = time.monotonic() + float(self.p.timeouts.result)
        heard, count = time.monotonic(), len(stamps)
        while not result.done():
            now = time.monotonic()
            if len(stamps) != count:
                heard, count = now, len(stamps)
            if not self.action.server_is_ready():
                self.goal = None
                raise Aborted(f"the controller's action server {self.p.action} left the graph during {what}"
                              " (the controller stopped?); rerun with --resume once it is back")
            if now - heard > silence:
                self.goal = None
                raise Aborted(f"no feedback from the controller for {silence:g} s during {what} (timeouts.peer): it"
                              " died or stalled; rerun with --resume once it is back")
            if now > deadline:
                raise Aborted(f"no result of {what} within {float(self.p.timeouts.result):g} s")
            self.executor.spin_once(timeout_sec=POLL)

    # ------------------------------------------------------------------ moving
    def move(self, waypoints: tuple[Waypoint, ...], what: str) -> float:
        """Send one trajectory and wait for its success; returns its start (first feedback stamp, s)."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        n = len(self.names)

        def dur(t: float) -> Any:
            ns = int(round(t * 1e9))
            return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

        points = [JointTrajectoryPoint(positions=w.positions.tolist(), velocities=[0.0] * n,
                                       accelerations=[0.0] * n, time_from_start=dur(w.time)) for w in waypoints]
        goal = self._fjt.Goal(trajectory=JointTrajectory(joint_names=self.names, points=points))
        server = float(self.p.timeouts.server)
        self.spin_until(self.action.server_is_ready, server, f"the FollowJointTrajectory server {self.p.action}")
        stamps: list[float] = []

        def on_feedback(m: Any) -> None:
            stamps.append(time_to_sec(m.feedback.header.stamp))

        sent = self.action.send_goal_async(goal, feedback_callback=on_feedback)
        self.spin_until(sent.done, server, f"answer to the goal of {what}")
        handle = sent.result()
        if not handle.accepted:
            raise Aborted(f"the controller rejected the goal of {what} (see its log)")
        self.goal = handle
        result = handle.get_result_async()
        self._await_result(result, stamps, what)
        self.goal = None
        res = result.result()
        from action_msgs.msg import GoalStatus

        if res.status != GoalStatus.STATUS_SUCCEEDED or res.result.error_code != 0:
            state = {GoalStatus.STATUS_ABORTED: "aborted", GoalStatus.STATUS_CANCELED: "canceled"}.get(
                res.status, f"status {res.status}")
            raise Aborted(f"the controller {state} the goal of {what}: error_code {res.result.error_code}"
                          f" {res.result.error_string!r}")
        if not stamps:
            raise Aborted(f"no feedback from the controller for {what}: its start time is unknown")
        return min(stamps)

    def cancel(self) -> None:
        """Cancel the goal in progress at the controller (after Ctrl-C)."""
        if self.goal is None:
            return
        future = self.goal.cancel_goal_async()
        with contextlib.suppress(Aborted):
            self.spin_until(future.done, 5.0, "answer to the cancel request")

    # ------------------------------------------------------------------ one pose
    def event(self, kind: int, repeat: int, pose: PoseStep, stamp: float) -> None:
        from shaper_msgs.msg import CycleEvent
        from shaper_nodes.ros.conversions import sec_to_time

        msg = CycleEvent(event=kind, cycle=repeat, task=f"calibration pose {pose.index} {pose.name}",
                         joint_names=self.names, start_positions=pose.pose.tolist(), goal_positions=pose.pose.tolist())
        msg.header.stamp = sec_to_time(stamp)
        self._record(EVENTS_TOPIC, "shaper_msgs/msg/CycleEvent", msg, time_to_sec(msg.header.stamp))

    def run_pose(self, step: PoseStep, setup: dict[str, Any], folder: pathlib.Path,
                 approach: tuple[Waypoint, ...]) -> str:
        """Record one pose into ``folder``; returns the samples lost in its recording ('' if none)."""
        from std_msgs.msg import String

        from shaper_nodes.recordings import BagWriter, rename_recording

        partial = folder.with_name(folder.name + ".partial")
        if partial.exists():
            shutil.rmtree(partial)
        self.writer = BagWriter(partial, compression=str(self.p.compression))
        try:
            self._record(SETUP_TOPIC, "std_msgs/msg/String", String(data=json.dumps(setup, sort_keys=True)),
                         max(self.imu_stamp, 0.0))
            start = first = self.move(approach, f"the approach to pose {step.index} ({step.name})")
            self.wait_imu(start + approach[-1].time, "the end of the rest before the excitation")
            for rep in range(step.repeats):
                start = self.move(step.excitations[rep], f"excitation {rep + 1} at pose {step.index}")
                motion_end = start + step.excitation_time
                self.wait_imu(motion_end + step.decay, "the end of the free decay")
                self.event(0, rep, step, start)
                self.event(1, rep, step, motion_end)
                self.event(2, rep, step, motion_end + step.decay)
            self.writer.close()
            self.writer = None
            rename_recording(partial, folder)  # pose_NNN/pose_NNN.mcap; the folder's rename is the commit
            return self.lockstep.describe_lost(first, self.imu_stamp)
        finally:
            if self.writer is not None:  # stopped in the middle: the pose is discarded
                with contextlib.suppress(Exception):  # the partial folder is removed anyway
                    self.writer.close()
                self.writer = None
                shutil.rmtree(partial, ignore_errors=True)


def parse_args(argv: list[str]) -> argparse.Namespace:
    from shaper_nodes.ros.node_main import parameter_help

    epilog = ("ROS arguments follow --ros-args: --params-file FILE (see config/calibrate.yaml), -p NAME:=VALUE.\n\n"
              + parameter_help({"": PARAMETERS}) + "\nExample:\n  ros2 run shaper_nodes calibrate --ros-args"
              " --params-file $(ros2 pkg prefix shaper_nodes)/share/shaper_nodes/config/calibrate.yaml\n")
    p = argparse.ArgumentParser(prog="calibrate", description=__doc__.split("\n\n")[0], epilog=epilog,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--execute", action="store_true", help="move the robot through the plan (default: print it)")
    p.add_argument("--resume", action="store_true", help="continue the calibration in --out from its last"
                   " completed pose (with --execute)")
    p.add_argument("--out", type=pathlib.Path, default=None, help="output folder (default:"
                   " calibration-<date-time> in the current folder)")
    p.add_argument("--from-bag", type=pathlib.Path, default=None, metavar="RECORDING",
                   help="recompute the report, rule base and fallback from a calibration's recording folder")
    p.add_argument("--workers", type=int, default=2, help="processes identifying poses in parallel (default 2)")
    return p.parse_args(argv)


def from_bag(recording: pathlib.Path, out: pathlib.Path, workers: int) -> int:
    try:
        setup, poses = read_recording(recording)
        cal = compute(setup, poses, workers=workers)
    except PlanError as err:
        print(f"calibrate: {err}", file=sys.stderr)
        return EXIT_REFUSED
    written = write_outputs(out, cal, str(recording))
    summary(cal)
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def summary(cal: Any) -> None:
    for r in cal.results:
        modes = ", ".join(f"{m.hz:.3f} Hz ({m.zeta:.4f})" for m in r.modes) or "none"
        print(f"  {r.index:3d} {r.name:<12} {modes}{'   ' + '; '.join(r.flags) if r.flags else ''}")
    for n in cal.notes:
        print(f"  note: {n}")


@survives_closed_pipe
def main(args: list[str] | None = None) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import remove_ros_args

    from shaper_nodes.ros.node_main import params_file_problem
    from shaper_nodes.ros.parameters import read

    argv = list(sys.argv if args is None else args)
    problem = params_file_problem(argv)  # before rcl reads the file (remove_ros_args does)
    if problem is not None:
        print(f"calibrate: refused: {problem}", file=sys.stderr)
        return EXIT_REFUSED
    opts = parse_args(remove_ros_args(argv)[1:])
    if opts.from_bag is not None:
        return from_bag(opts.from_bag, opts.out or opts.from_bag.parent, opts.workers)
    if opts.resume and (opts.out is None or not opts.execute):
        print("calibrate: --resume needs --execute and the --out folder of the calibration to continue",
              file=sys.stderr)
        return EXIT_REFUSED
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("calibrate")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    cal: Calibrator | None = None
    try:
        declare_all(node, PARAMETERS)
        v = read(node, CalibrateParams)  # a one-shot command: its parameters do not change while it runs
        if not v.joint_names:
            raise PlanError("parameter joint_names is required: the controller's joints (see config/calibrate.yaml)")
        cal = Calibrator(node, executor, v)
        return _run(cal, v, opts)
    except KeyboardInterrupt:
        if cal is not None:
            cal.cancel()
        print("\ncalibrate: cancelled; the pose in progress was discarded, completed poses are kept (--resume)",
              file=sys.stderr)
        return EXIT_CANCELLED
    except (PlanError, ValueError) as err:
        print(f"calibrate: refused: {err}", file=sys.stderr)
        return EXIT_REFUSED
    except Aborted as err:
        print(f"calibrate: aborted: {err}", file=sys.stderr)
        return EXIT_ABORTED
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


def _run(cal: Calibrator, v: CalibrateParams, opts: argparse.Namespace) -> int:
    out: pathlib.Path = opts.out or pathlib.Path(datetime.datetime.now().strftime("calibration-%Y%m%d-%H%M%S"))
    if opts.resume:
        try:
            setup = json.loads((out / "plan.json").read_text())
        except (OSError, ValueError) as err:
            raise PlanError(f"nothing to resume in {out}: {err}") from None
        plan, _, _, _ = plan_from_setup(setup)
        print(f"calibrate: resuming {out}: {len(pose_folders(out / 'recording'))} of {len(plan.steps)} poses done")
    else:
        here = _start_pose(cal, v, opts.execute)
        config = config_from_values(v, here)
        plan = make_plan(config, here)
        setup = setup_dict(plan, settings_from_values(v), str(v.scheduler.family),
                           float(v.scheduler.premise_threshold),
                           {"action": str(v.action), "joint_states": str(v.topics.joint_states)})
        plan_from_setup(setup)  # the setup recorded recomputes this plan (refused here, not after the moves)
    print(plan.describe(), flush=True)
    if not opts.execute:
        print("calibrate: plan only; add --execute to move the robot", flush=True)
        return 0
    if not opts.resume:
        if out.exists():
            raise PlanError(f"{out} exists: give another --out, or --resume to continue it")
        (out / "recording").mkdir(parents=True)
        write_atomic(out / "plan.json", json.dumps(setup, indent=1, sort_keys=True) + "\n")
    return _execute(cal, plan, setup, out, opts.workers)


def _start_pose(cal: Calibrator, v: CalibrateParams, execute: bool) -> np.ndarray | None:
    """Where the arm is (its joint states), the plan's start: the first approach, and so the plan's duration,
    starts there. A plan only, with base_pose and home_pose given, is still printed when no joint states come
    (no robot running): from the home pose, and it says so."""
    try:
        return cal.wait_pose()
    except Aborted as err:
        if execute or not v.base_pose or not v.home_pose:
            raise
        print(f"calibrate: {err}; the plan below starts at the home pose", flush=True)
        return None


def _execute(cal: Calibrator, plan: Plan, setup: dict[str, Any], out: pathlib.Path, workers: int) -> int:
    recording = out / "recording"
    for partial in recording.glob("*.partial"):
        shutil.rmtree(partial)
    done = {int(p.name.split("_")[1]) for p in pose_folders(recording)}
    c = plan.config
    t_wall = time.monotonic()
    for step in plan.steps:
        if step.index in done:
            continue
        here = cal.wait_pose()
        approach = plan_approach(step.pose, quintic_time(step.pose - here, c.approach_velocity,
                                                         c.approach_acceleration), c.settle)
        lost = cal.run_pose(step, setup, recording / f"pose_{step.index:03d}", approach)
        print(f"calibrate: pose {step.index + 1}/{len(plan.steps)} ({step.name}) recorded"
              f" ({time.monotonic() - t_wall:.0f} s)" + (f"; {lost} (gaps in the stamps)" if lost else ""), flush=True)
    here = cal.wait_pose()
    cal.move((Waypoint(quintic_time(c.home_pose - here, c.approach_velocity, c.approach_acceleration),
                       c.home_pose),), "the move back home")
    print("calibrate: identifying the modes at every pose ...", flush=True)
    setup_read, poses = read_recording(recording)
    result = compute(setup_read, poses, workers=workers)
    written = write_outputs(out, result, "recording")
    summary(result)
    print(f"calibrate: done in {time.monotonic() - t_wall:.0f} s; written: " + ", ".join(p.name for p in written))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
