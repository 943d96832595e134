"""send_goal: send one FollowJointTrajectory goal and print its result (for machines without ros2cli).

    send_goal --action /shaper/follow_joint_trajectory --joints J1 J2 ... --positions P1 P2 ... --duration S
              [--from-current] [--hold S] [--joint-states TOPIC] [--timeout S] [--result-timeout S]
              [--cycle N [--task NAME] [--events TOPIC]] [--ros-args ...]

The goal is a ``trajectory_msgs/JointTrajectory`` for the joints named (the controller's, all of
them: joint_trajectory_controller and the shaper node refuse partial goals) ending at the
positions given (rad, or m for a prismatic joint) ``--duration`` s after its start, at rest
(velocities and accelerations zero). With ``--from-current`` it starts with a point at the arm's
present pose (read from ``--joint-states``) at time 0, so the whole motion is in the trajectory
and a shaper in front of the controller shapes it (without it the controller interpolates from
wherever the arm is to the one point, and what a shaper shapes is that one point); ``--hold S``
adds a last point holding the goal S s longer, so the controller keeps executing while the arm
settles (a simulator in lockstep keeps its time running through it). ``--cycle N`` marks the goal as
cycle N of task ``--task`` on ``--events`` (START, MOTION_END, END, stamped on the joint states' clock;
the hold is the cycle's residual window), for a learner per move, the identifier or a recording
(cli/cycle_marks.py).

It prints a line with the goal's id when the controller accepts it, then the result, ``succeeded`` or
``aborted``/``canceled``/``rejected``/``unknown`` (the action server gone, or restarted without the goal)
with the controller's ``error_code`` (and its name) and ``error_string``, and the last feedback's
largest position error, and exits 0 when the goal succeeded,
1 when it did not (rejected, aborted, canceled, unknown) or a wait ran out (the line names what did
not come: the action server, the joint states, the answer to the goal, its result; a goal sent is
cancelled first), 2 for bad input, 130 after Ctrl-C (SIGINT) and 143 after SIGTERM (the goal is cancelled
first, by the id it was sent with if its answer has not come: an accepted goal whose answer was lost runs
all the same). Every wait is bounded in wall time: ``--timeout`` for the server, the joint states and the
answer, ``--result-timeout`` for the result.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from shaper_nodes.cli.common import Parser, UsageError, count, number
from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.core.interrupts import Stopped, interrupt_in, signals_held, stop_on_signals

PROG = "send_goal"
EXIT_FAILED, EXIT_USAGE, EXIT_CANCELLED = 1, 2, 130
POLL = 0.02  # s, the executor's spin granularity


class WaitError(RuntimeError):
    """A bounded wait ran out; the message names what did not come."""


@dataclass(frozen=True)
class Outcome:
    """A goal's end: its status (``succeeded``, ``aborted``, ``canceled``, ``rejected``, ``unknown``), the controller's
    result (error code, its name, error string) and the last feedback's largest |position error| (rad or m,
    NaN without feedback)."""

    status: str
    error_code: int = 0
    error_name: str = ""
    error_string: str = ""
    max_error: float = math.nan

    @property
    def ok(self) -> bool:
        return self.status == "succeeded" and self.error_code == 0

    def line(self, action: str) -> str:
        """The one line printed for it."""
        if self.status == "rejected":
            return f"{PROG}: rejected: {action} rejected the goal (its node's log says why)"
        code = f"error_code {self.error_code}" + (f" ({self.error_name})" if self.error_name else "")
        err = "" if math.isnan(self.max_error) else f"; last feedback: largest position error {self.max_error:.3g}"
        return f"{PROG}: {self.status}: {code} {self.error_string!r}{err}"


def _names(values: Sequence[str]) -> list[str]:
    """Joint names given as separate words or comma-separated (or both)."""
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


def _positions(values: Sequence[str]) -> list[float]:
    out = []
    for text in (p.strip() for v in values for p in v.split(",") if p.strip()):
        try:
            x = float(text)
        except ValueError:
            raise UsageError(f"--positions: {text!r} is not a number") from None
        if not math.isfinite(x):
            raise UsageError(f"--positions: {text!r} is not finite")
        out.append(x)
    return out


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = Parser(prog=PROG, description=__doc__.split("\n\n")[0],
               epilog="ROS arguments follow --ros-args. The waits are in wall time, whatever the clock of the"
                      " robot or simulator.\n\nExample:\n  send_goal --action /shaper/follow_joint_trajectory --joints"
                      " shoulder_pan_joint shoulder_lift_joint elbow_joint wrist_1_joint wrist_2_joint wrist_3_joint"
                      " --positions 0.5 -1.57 1.57 -1.57 -1.57 0 --duration 2 --from-current --hold 1.5\n",
               formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--action", required=True, help="the FollowJointTrajectory action (the shaper node's"
                   " /shaper/follow_joint_trajectory, or a controller's)")
    p.add_argument("--joints", nargs="+", required=True, metavar="JOINT", help="the joints, in the order of"
                   " --positions (words or comma-separated)")
    p.add_argument("--positions", nargs="+", required=True, metavar="P", help="the goal positions, rad (or m)")
    p.add_argument("--duration", required=True, type=number("--duration", positive=True),
                   help="time from the trajectory's start to the goal, s")
    p.add_argument("--from-current", action="store_true", help="start the trajectory at the present pose (from"
                   " --joint-states) at time 0, so that the whole motion is in it (and a shaper shapes it)")
    p.add_argument("--hold", type=number("--hold"), default=0.0, help="hold the goal this long after --duration,"
                   " inside the trajectory, s (default 0)")
    p.add_argument("--joint-states", default="/joint_states", help="joint states topic for --from-current"
                   " (default /joint_states)")
    p.add_argument("--timeout", type=number("--timeout", positive=True), default=10.0,
                   help="wait for the action server, the joint states and the answer to the goal, s (wall; default"
                        " 10)")
    p.add_argument("--cycle", type=count("--cycle"), default=None, metavar="N",
                   help="mark the goal as cycle N (an integer >= 0) on --events: START before it, MOTION_END"
                   " --duration s and END --duration + --hold s later, stamped on the joint states' clock; needs"
                   " --hold > 0 (the residual window)")
    p.add_argument("--task", default=PROG, help=f"the task named in the cycle marks (default {PROG})")
    p.add_argument("--events", default="/cycle_events", help="topic of the cycle marks (default /cycle_events)")
    p.add_argument("--result-timeout", type=number("--result-timeout", positive=True), default=None,
                   help="wait for the result, s (wall; default 60 + 10 x (duration + hold))")
    args = p.parse_args(list(argv))
    args.joints = _names(args.joints)
    args.positions = _positions(args.positions)
    if not args.joints or len(set(args.joints)) != len(args.joints):
        raise UsageError(f"--joints must be distinct names, got {args.joints}")
    if len(args.positions) != len(args.joints):
        raise UsageError(f"--positions needs one value per joint ({len(args.joints)}), got {len(args.positions)}")
    if args.hold < 0:
        raise UsageError(f"--hold must be >= 0, got {args.hold:g}")
    if args.cycle is not None and not args.hold > 0:
        raise UsageError("--cycle needs --hold > 0: the hold after the motion is the cycle's residual window")
    if args.result_timeout is None:
        args.result_timeout = 60.0 + 10.0 * (args.duration + args.hold)
    return args


def trajectory_points(positions: Sequence[float], duration: float, start: Sequence[float] | None = None,
                      hold: float = 0.0) -> list[tuple[float, list[float]]]:
    """The goal's points as (time from start s, positions): ``start`` at 0 if given, ``positions`` at
    ``duration``, and again at ``duration + hold`` if ``hold`` > 0; all at rest."""
    pts = [] if start is None else [(0.0, [float(x) for x in start])]
    pts.append((float(duration), [float(x) for x in positions]))
    if hold > 0:
        pts.append((float(duration + hold), [float(x) for x in positions]))
    return pts


class GoalSender:
    """One node that sends one goal: the action client, the joint states, bounded waits."""

    def __init__(self, node: Any, executor: Any, action: str) -> None:
        from control_msgs.action import FollowJointTrajectory

        from shaper_nodes.ros.action_client import ResilientActionClient

        self.node, self.executor, self.action_name = node, executor, action
        self.fjt = FollowJointTrajectory
        self.client = ResilientActionClient(node, FollowJointTrajectory, action)
        self.handle: Any = None
        self.sent: Any = None  # the goal's request while its answer is awaited, and the id it was sent with
        self.goal_id: Any = None

    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                raise WaitError(f"no {what} within {timeout:g} s")
            try:
                with signals_held():  # a Ctrl-C inside the take would drop what it took (the goal's answer)
                    self.executor.spin_once(timeout_sec=POLL)
            except Exception as err:  # a Ctrl-C that landed inside rclpy's C++ comes out as another error
                interrupt = interrupt_in(err, KeyboardInterrupt)
                if interrupt is None:
                    raise
                raise interrupt from None

    def current(self, topic: str, joints: Sequence[str], timeout: float) -> tuple[list[float], float]:
        """The present positions of ``joints`` from the first joint state that names them all, and its stamp (s)."""
        from sensor_msgs.msg import JointState

        got: list[tuple[list[float], float]] = []

        def on_state(msg: Any) -> None:
            names = list(msg.name)
            if not got and all(j in names for j in joints) and len(msg.position) == len(names):
                got.append(([float(msg.position[names.index(j)]) for j in joints],
                            msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec))

        sub = self.node.create_subscription(JointState, topic, on_state, 10)
        try:
            self.spin_until(lambda: bool(got), timeout, f"joint states naming {', '.join(joints)} on {topic}")
        finally:
            self.node.destroy_subscription(sub)
        return got[0]

    def send(self, joints: Sequence[str], points: Sequence[tuple[float, Sequence[float]]], timeout: float,
             result_timeout: float, on_send: Callable[[], None] | None = None) -> Outcome:
        import uuid

        from action_msgs.msg import GoalStatus
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        from unique_identifier_msgs.msg import UUID

        def dur(t: float) -> Any:
            ns = int(round(t * 1e9))
            return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

        n = len(joints)
        goal = self.fjt.Goal(trajectory=JointTrajectory(joint_names=list(joints), points=[
            JointTrajectoryPoint(positions=list(p), velocities=[0.0] * n, accelerations=[0.0] * n,
                                 time_from_start=dur(t)) for t, p in points]))
        self.spin_until(self.client.server_is_ready, timeout, f"FollowJointTrajectory server {self.action_name}")
        errors: list[float] = []
        if on_send is not None:
            on_send()

        def on_feedback(msg: Any) -> None:
            e = [abs(x) for x in msg.feedback.error.positions]
            if e:
                errors.append(max(e))

        self.goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        sent = self.sent = self.client.send_goal_async(goal, feedback_callback=on_feedback, goal_uuid=self.goal_id)
        self.spin_until(sent.done, timeout, f"answer from {self.action_name} to the goal")
        self.sent = None
        handle = sent.result()
        if not handle.accepted:
            return Outcome("rejected")
        self.handle = handle
        print(f"{PROG}: accepted by {self.action_name}, goal id {uuid.UUID(bytes=bytes(self.goal_id.uuid))}",
              flush=True)
        result = handle.get_result_async()
        self.spin_until(result.done, result_timeout, f"result from {self.action_name}")
        self.handle = None
        res = result.result()
        status = {GoalStatus.STATUS_SUCCEEDED: "succeeded", GoalStatus.STATUS_ABORTED: "aborted",
                  GoalStatus.STATUS_CANCELED: "canceled", GoalStatus.STATUS_UNKNOWN: "unknown"}.get(
                      res.status, f"status {res.status}")
        code = int(res.result.error_code)
        return Outcome(status, code, _code_name(self.fjt.Result, code), str(res.result.error_string),
                       errors[-1] if errors else math.nan)

    def cancel(self) -> str:
        """Cancel the goal out at the controller (after Ctrl-C, or a wait that ran out), waiting at most 5 s for
        the answer; returns what happened in words for the last line ('' if no goal was out). A goal whose
        answer has not come is cancelled by the id it was sent with (accepted with its answer lost, it runs)."""
        if self.handle is not None:
            future, why = self.handle.cancel_goal_async(), ""
        elif self.sent is not None:
            future, why = self.client.cancel_goal_id(self.goal_id), " (by its goal id: its answer had not come)"
        else:
            return ""
        self.handle = self.sent = None
        try:
            self.spin_until(future.done, 5.0, "answer to the cancel request")
        except WaitError:
            return f"; a cancel of the goal was sent{why}, not confirmed within 5 s"
        answer = future.result()
        if answer is not None and answer.goals_canceling:
            return f"; the goal was cancelled at the controller{why}"
        code = answer.return_code if answer is not None else "none"
        return f"; a cancel of the goal was sent{why}: the controller had no such goal running (return code {code})"


def _code_name(result_type: Any, code: int) -> str:
    """The name of a FollowJointTrajectory result code (SUCCESSFUL, PATH_TOLERANCE_VIOLATED, ...)."""
    return next((k for k in dir(result_type) if k.isupper() and getattr(result_type, k) == code), "")


@survives_closed_pipe
def main(args: list[str] | None = None) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv if args is None else args)
    try:
        opts = parse_args(remove_ros_args(argv)[1:])
    except UsageError as err:
        msg = str(err)
        print(msg if msg.startswith(PROG) else f"{PROG}: error: {msg}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("send_goal")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    sender = GoalSender(node, executor, opts.action)
    stop_on_signals()  # SIGINT and SIGTERM cancel the goal, also where SIGINT came ignored (a background job)
    marks = None
    try:
        if opts.cycle is not None:  # first: DDS matches the marks' publisher while the rest is waited for
            from shaper_nodes.cli.cycle_marks import CycleMarks, CycleSpec

            marks = CycleMarks(node, CycleSpec(opts.cycle, opts.task, opts.events), opts.joints, opts.joint_states)
        here, stamp = (sender.current(opts.joint_states, opts.joints, opts.timeout)
                       if opts.from_current or opts.cycle is not None else (None, 0.0))
        points = trajectory_points(opts.positions, opts.duration, here if opts.from_current else None, opts.hold)
        on_send = None
        if marks is not None and here is not None:
            marks.wait_listeners(sender.spin_until, opts.timeout, PROG)
            cycle_marks, start_pose = marks, here

            def on_send() -> None:  # START as the goal goes out, at the latest joint state's stamp
                nonlocal stamp
                stamp = max(stamp, cycle_marks.latest)
                cycle_marks.start(stamp, start_pose, opts.positions, opts.timeout, PROG)
        print(f"{PROG}: sending {len(points)} point(s) over {points[-1][0]:g} s to {opts.action}", flush=True)
        outcome = sender.send(opts.joints, points, opts.timeout, opts.result_timeout, on_send)
        if marks is not None and here is not None and outcome.ok:
            marks.finish(stamp, opts.duration, opts.hold, here, opts.positions, opts.timeout, PROG)
            print(f"{PROG}: marked cycle {opts.cycle} of {opts.task!r} on {opts.events}: START at {stamp:.3f} s,"
                  f" MOTION_END {stamp + opts.duration:.3f} s, END {stamp + opts.duration + opts.hold:.3f} s",
                  flush=True)
    except KeyboardInterrupt as stop:  # SIGINT or SIGTERM (stop_on_signals)
        note = sender.cancel()
        name = f"{stop}" if isinstance(stop, Stopped) else "SIGINT"
        print(f"\n{PROG}: cancelled by {name}{note}", file=sys.stderr)
        return stop.status if isinstance(stop, Stopped) else EXIT_CANCELLED
    except WaitError as err:  # a goal out whose answer or result did not come is not left running
        note = sender.cancel()
        print(f"{PROG}: {err}{note}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    print(outcome.line(opts.action), file=sys.stdout if outcome.ok else sys.stderr, flush=True)
    return 0 if outcome.ok else EXIT_FAILED


if __name__ == "__main__":
    raise SystemExit(main())
