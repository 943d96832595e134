"""The calibrate node's ROS side (:mod:`shaper_nodes.nodes.calibrate` runs it): its action client to the controller,
its subscriptions to the accelerometer and the joint states, the recording of a pose, the waits on the robot's data
and the cancel of the running goal on every stop."""

from __future__ import annotations

import contextlib
import json
import math
import pathlib
import shutil
import struct
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from shaper_nodes.analysis.calibration import (
    EVENTS_TOPIC,
    SETUP_TOPIC,
)
from shaper_nodes.core.calibration import PoseStep, Waypoint
from shaper_nodes.core.interrupts import signals_held
from shaper_nodes.recordings.cdr_sensors import CdrError, JointStateReader
from shaper_nodes.ros.conversions import time_to_sec
from shaper_nodes.ros.diagnostics import Diagnostics

from .calibrate_parameters import CalibrateParams
from .calibrate_stops import (
    Aborted,
    WriteFailed,
    stop_in,
)

POLL = 0.02  # s, executor spin granularity
#: s, the longest a stop waits for the controller's answer to the cancel of the running goal
CANCEL_WAIT = 5.0
#: s the controller's action server must stay out of the graph before calibrate takes it as gone: under load the
#: graph briefly reads it unavailable while it runs (seen in CI: a live controller 'left the graph' 0.8 s after it
#: accepted a goal); a dead controller is still caught in this time, or by its silence (timeouts.peer). While a
#: goal runs it must also be silent that long (no feedback): a controller that sends feedback is there (the
#: full-grid calibration and the MRILC demo saw a live controller out of the graph at load 25-35)
SERVER_GONE = 2.0


class TimedOut(Aborted):
    """A wait of :meth:`Calibrator.spin_until` ended with what it waited for not there; the waits that may end
    so suppress this alone, so that a failed write raised out of a callback during them (:class:`WriteFailed`)
    still ends the run (session 18: suppressed while calibrate waited for the controller's answer, the full
    disk went unnoticed and the run waited on the running goal)."""


class Calibrator:
    """The ROS side of a calibration run: a node, its action client, its subscriptions and the recording."""

    def __init__(self, node: Any, executor: Any, params: CalibrateParams) -> None:
        from control_msgs.action import FollowJointTrajectory
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu, JointState

        from shaper_nodes.ros.action_client import ResilientActionClient
        from shaper_nodes.ros.goal_feedback import GoalFeedback
        from shaper_nodes.ros.lockstep_reader import STREAM_QOS, LockstepReader, subscribe_draining

        self.node, self.executor, self.p = node, executor, params
        self.names = list(params.joint_names)
        self.position: np.ndarray | None = None
        self.imu_stamp = -math.inf
        self.writer: Any = None
        self.write_failed: WriteFailed | None = None  # the recording's failure: nothing more is written
        self.goal: Any = None  # the running goal's handle (cancelled on every stop), what it is, its answer
        self.goal_what = ""
        self.goal_id: Any = None  # the id the running goal was sent with (its cancel names it)
        self.sent: Any = None
        self.peer_lost = False  # the controller went away or went silent: a cancel is sent, not awaited
        self._absent_since: float | None = None  # wall time the action server was first seen out of the graph
        reliability = ReliabilityPolicy.RELIABLE if params.topics.imu_reliable else ReliabilityPolicy.BEST_EFFORT
        deep = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=reliability)
        self.imu_topic = params.topics.imu
        self.js_topic = params.topics.joint_states
        # a lockstep sim plant that names this node in lockstep.readers waits for it; gaps in the stamps are losses
        self.lockstep = LockstepReader(node, {self.imu_topic: None, self.js_topic: None})
        # raw, every queued sample per wake-up (a plant running ahead costs one executor turn per batch)
        self._imu_sub = subscribe_draining(node, Imu, self.imu_topic, self._on_imu, deep)
        self._js_read = JointStateReader()
        self._js_names: tuple[str, ...] | None = None  # the names of the last layout, and this node's joints' indices
        self._js_index: list[int] = []
        subscribe_draining(node, JointState, self.js_topic, self._on_joint_states, STREAM_QOS)
        self.action = ResilientActionClient(node, FollowJointTrajectory, params.action)
        self.feedback = GoalFeedback(node, FollowJointTrajectory, params.action)
        # made now, so that a monitor's subscription has matched by the time a sensor fault is reported
        self.diagnostics = Diagnostics(node)
        self._fjt = FollowJointTrajectory

    # ------------------------------------------------------------------ data
    def _write(self, topic: str, type_name: str, stamp_ns: int, data: bytes) -> None:
        """Record one message; a failed write (a full disk) abandons the pose's file and raises
        :class:`WriteFailed` out of the callback, through the executor, to the run."""
        if self.writer is None or self.write_failed is not None:
            return
        try:
            self.writer.add_topic(topic, type_name)
            self.writer.write(topic, stamp_ns, data)
        except OSError as err:
            self.write_failed = WriteFailed(err, self.writer.file)
            self.writer.abandon()
            raise self.write_failed from None

    def _record(self, topic: str, type_name: str, msg: Any, stamp: float) -> None:
        if self.writer is not None:
            from rclpy.serialization import serialize_message

            self._write(topic, type_name, int(round(stamp * 1e9)), serialize_message(msg))

    def _on_imu(self, raw: bytes) -> None:
        """Raw CDR (the cheapest callback at the simulator's rates): the header stamp read in place."""
        sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)
        t = sec + nanosec * 1e-9
        self.imu_stamp = max(self.imu_stamp, t)
        self.lockstep.took(self.imu_topic, t)
        self._write(self.imu_topic, "sensor_msgs/msg/Imu", sec * 1_000_000_000 + nanosec, raw)

    def _on_joint_states(self, raw: bytes) -> None:
        """Raw CDR: the stamp, names and positions read by a checked decoder; the bytes recorded as they came."""
        try:
            t, names, positions = self._js_read(raw)
        except CdrError as err:  # dropped (its gap then counts as lost)
            self.node.get_logger().error(f"{self.js_topic}: a message dropped: {err}", throttle_duration_sec=1.0)
            return
        if names is not self._js_names:  # a new layout: where this node's joints are in it
            self._js_names = names
            self._js_index = [names.index(j) if j in names else -1 for j in self.names]
        if any(i < 0 or i >= len(positions) for i in self._js_index):
            return
        self.position = np.array([positions[i] for i in self._js_index], dtype=float)
        self.lockstep.took(self.js_topic, t)
        self._write(self.js_topic, "sensor_msgs/msg/JointState", int(round(t * 1e9)), raw)

    # ------------------------------------------------------------------ waiting
    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        """Spin until ``done()``; :class:`TimedOut` after ``timeout`` s. What a callback raises comes out as it is
        (a failed write's :class:`WriteFailed`, also an :class:`Aborted`): a wait that may end unmet suppresses
        :class:`TimedOut` only."""
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise TimedOut(f"no {what} within {timeout:g} s")
            try:
                with signals_held():  # a stop inside the take would drop what it took (the goal's answer)
                    self.executor.spin_once(timeout_sec=POLL)
            except Exception as err:  # a stop signal that landed inside rclpy's C++ comes out as another error
                stop = stop_in(err)
                if stop is None:
                    raise
                raise stop from None

    def wait_pose(self) -> np.ndarray:
        self.spin_until(lambda: self.position is not None, float(self.p.timeouts.data),
                        f"joint states with {', '.join(self.names)} on {self.js_topic}")
        assert self.position is not None
        return self.position.copy()

    def wait_imu(self, stamp: float, what: str) -> None:
        self.spin_until(lambda: self.imu_stamp >= stamp, float(self.p.timeouts.data),
                        f"accelerometer data on {self.imu_topic} up to {what} (t = {stamp:.3f} s)")

    def _server_gone(self) -> bool:
        """Whether the controller's action server has been out of the graph for :data:`SERVER_GONE` s."""
        if self.action.server_is_ready():
            self._absent_since = None
            return False
        now = time.monotonic()
        if self._absent_since is None:
            self._absent_since = now
        return now - self._absent_since >= SERVER_GONE

    def _await_answer(self, sent: Any, what: str) -> None:
        """Wait for the controller's answer to a goal while watching it as :meth:`_await_result` does: a live
        controller answers at once, so its silence for timeouts.peer (or timeouts.server if shorter), or its
        action server gone from the graph, is a dead or stalled controller (a kill between two goals)."""
        bound, name = min((float(self.p.timeouts.peer), "timeouts.peer"), (float(self.p.timeouts.server),
                                                                           "timeouts.server"))
        deadline = time.monotonic() + bound
        while True:
            with contextlib.suppress(TimedOut):
                self.spin_until(lambda: sent.done() or self._server_gone(), max(deadline - time.monotonic(), 0.0), "")
            if sent.done():
                return
            if self._server_gone():  # still out of the graph: gone
                self.peer_lost = True
                raise Aborted(f"the controller's action server {self.p.action} left the graph before it answered"
                              f" the goal of {what} (the controller stopped?); rerun with --resume once it is back")
            if time.monotonic() >= deadline:
                break
            # out of the graph for SERVER_GONE s and back in it: a live controller whose graph entry lagged (under
            # load); its answer is awaited on (before, this ended the run as 'no answer ... for <bound> s' early)
        self.peer_lost = True
        raise Aborted(f"no answer and no feedback from the controller for {bound:g} s after the goal of {what}"
                      f" was sent ({name}): it died or stalled; rerun with --resume once it is back")

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
            if self._server_gone() and now - heard >= SERVER_GONE:  # (a controller that sends feedback is there:
                self.peer_lost = True                                # the graph can lag under load)
                raise Aborted(f"the controller's action server {self.p.action} left the graph during {what}"
                              " (the controller stopped?); rerun with --resume once it is back")
            if now - heard > silence:
                self.peer_lost = True
                raise Aborted(f"no feedback from the controller for {silence:g} s during {what} (timeouts.peer): it"
                              " died or stalled; rerun with --resume once it is back")
            if now > deadline:
                raise Aborted(f"no result of {what} within {float(self.p.timeouts.result):g} s")
            with signals_held():
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
        self.spin_until(self.action.server_is_ready, server, f"FollowJointTrajectory server {self.p.action}")
        # the accelerometer matched before the arm moves: a simulator in lockstep runs a goal in a blink, and the
        # samples published before the match never come (the rest after the goal publishes none)
        self.spin_until(lambda: self._imu_sub.get_publisher_count() > 0, server,
                        f"publisher of {self.imu_topic} (the accelerometer)")
        # the goal's feedback on a subscription of calibrate's own: rclpy's client drops what it has not handed
        # over when the result comes, and the first stamp is the start (GoalFeedback)
        goal_id, stamps = self.feedback.new_goal()
        try:
            return self._run_goal(goal, goal_id, stamps, what)
        finally:
            self.feedback.forget(goal_id)

    def _run_goal(self, goal: Any, goal_id: Any, stamps: list[float], what: str) -> float:
        self.goal_what, self.goal_id = what, goal_id
        sent = self.sent = self.action.send_goal_async(goal, goal_uuid=goal_id)
        self._await_answer(sent, what)
        self.sent = None
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
            state = {GoalStatus.STATUS_ABORTED: "aborted", GoalStatus.STATUS_CANCELED: "canceled",
                     GoalStatus.STATUS_UNKNOWN: "lost (gone, or restarted without it)"}.get(
                res.status, f"status {res.status}")
            raise Aborted(f"the controller {state} the goal of {what}: error_code {res.result.error_code}"
                          f" {res.result.error_string!r}")
        if not stamps:  # the result came first: the feedback waits behind a batch of samples (a deep queue)
            with contextlib.suppress(TimedOut):
                self.spin_until(lambda: bool(stamps), float(self.p.timeouts.data), "")
        if not stamps:
            raise Aborted(f"no feedback from the controller for {what}: its start time is unknown")
        return min(stamps)

    def cancel(self) -> str:
        """Cancel the goal running at the controller, on every stop (a signal, a failed write, a dead
        controller, an error); returns what happened in words for the stop's line ('' if no goal ran).

        A goal sent but not answered yet is awaited (at most :data:`CANCEL_WAIT` s) and cancelled if
        accepted; with no acceptance known by then (the answer lost, or its resend refused as a duplicate id
        with the status lost too, as when the stop's signal lands in rclpy's take of both) it is cancelled by
        the id it was sent with: a controller that never took it refuses that, harmless. The controller's
        answer to the cancel is awaited at most :data:`CANCEL_WAIT` s, and not at all when the controller went
        away or silent (the cancel is still sent, for a stalled one)."""
        wait = 0.0 if self.peer_lost else CANCEL_WAIT
        sent, self.sent = self.sent, None
        unanswered = False
        if self.goal is None and sent is not None:
            if wait:
                with contextlib.suppress(Aborted):
                    self.spin_until(sent.done, wait, "answer to the goal")
            if sent.done() and sent.result().accepted:
                self.goal = sent.result()
            else:
                unanswered = True
        if self.goal is None and not unanswered:
            return ""
        handle, self.goal = self.goal, None
        future = self.action.cancel_goal_id(self.goal_id) if unanswered else handle.cancel_goal_async()
        why = "; its acceptance had not come, so it was cancelled by the goal id it was sent with" if unanswered else ""
        if not wait:
            with signals_held():
                self.executor.spin_once(timeout_sec=0.0)
            return f"; a cancel of {self.goal_what} was sent to the controller{why}"
        with contextlib.suppress(Aborted):
            self.spin_until(future.done, wait, "answer to the cancel request")
        answer = future.result() if future.done() else None
        if answer is not None and answer.goals_canceling:
            return f"; {self.goal_what} was cancelled at the controller{why}"
        if answer is not None:  # refused: the goal was not running there (never taken, or already ended)
            return (f"; a cancel of {self.goal_what} was sent to the controller: it had no such goal running"
                    f" (return code {answer.return_code}){why}")
        return f"; a cancel of {self.goal_what} was sent to the controller (not confirmed within {wait:g} s){why}"

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
        try:
            self.writer = BagWriter(partial, compression=str(self.p.compression))
        except OSError as err:
            raise WriteFailed(err, partial) from None
        self.write_failed = None
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
            file = self.writer.file
            try:
                self.writer.close()
                self.writer = None
                rename_recording(partial, folder)  # pose_NNN/pose_NNN.mcap; the folder's rename is the commit
            except OSError as err:
                raise WriteFailed(err, file) from None
            return self.lockstep.describe_lost(first, self.imu_stamp)
        finally:
            if self.writer is not None:  # stopped in the middle: the pose is discarded
                with contextlib.suppress(Exception):  # the partial folder is removed anyway
                    self.writer.close()
                self.writer = None
                shutil.rmtree(partial, ignore_errors=True)
