"""FollowJointTrajectory in front of a controller: shape each goal, forward it, relay the rest.

The shaper node serves ``control_msgs/action/FollowJointTrajectory`` (as joint_trajectory_controller
does) and is a client of the controller's. For each goal:

- goal request: the trajectory is shaped at once (which validates it: the node's joints in any
  order, sizes, finite values, strictly increasing times; tolerances finite, at most one per joint;
  no multi-DOF part). Its size is checked first, from the number of points and joints and the first
  and last points' times, before any work on its points (``WholeShaping.check_size``): a goal too large
  to shape is refused at once, whatever its length. An invalid goal is **rejected**, as
  joint_trajectory_controller rejects one, and the reason goes to the node's log and ``/diagnostics``;
  nothing reaches the controller. After refusing a large goal (:data:`RELEASE_ABOVE` values) the node
  gives the memory its request held back to the system (core/memory.py), once rclpy has dropped it.
  rclpy itself converts the whole request into Python objects before any of this runs: that part of a
  huge goal's cost (about 2 s and 70 MiB per 10^5 points of 6 joints) is beyond the node's reach
  (docs/guide/shaper_node.md, "Goal size").
- a goal whose first point is after time 0: shaped and forwarded as it is, and ``on_late_start`` is called with
  the warning's text (:func:`late_start_warning`): the motion from the robot's state to that point is the
  controller's interpolation, which no shaper in front of it sees (a goal of one point is all of it). Planners
  start trajectories at the current state at time 0; ``send_goal --from-current`` does.
- a goal id already accepted (a client's request sent again after no answer came, as
  ``ResilientActionClient`` does): rclpy's action server refuses it as a duplicate before the goal
  callback (rcl_action checks the id again as it accepts), so the goal runs once and nothing is
  preempted; the client goes on with the goal it accepted (its first answer, or the status topic
  naming the goal). ``tests/test_action_proxy_resend.py`` shows it through the learner's and the shaper
  node's proxies: one execution at the controller, no cancel.
- accepted: a goal still running is preempted (its controller goal is cancelled), as
  joint_trajectory_controller does; one goal is active at a time.
- execution: with a ``reshape`` coroutine (the node's ``action.scheduler``: the trajectory shaped
  for its final pose), first awaits it and sends the trajectory it returns instead, or keeps the trajectory
  shaped at the goal request if it returns none; then waits up to ``timeout`` s for the
  controller's action server, tells ``on_sending`` (the node's ``~/shaped_goals``) what the goal is shaped
  with, sends the shaped trajectory with the goal's tolerances and
  ``goal_time_tolerance`` unchanged, relays every feedback, and ends with the controller's status
  and result (error_code, error_string). A controller that does not answer the goal within ``timeout`` s
  aborts it, and the goal is cancelled at the controller by the id it was sent with: an answer lost on the
  way (and its status with it) leaves an accepted goal running there.
- cancel: accepted and forwarded to the controller goal; the final status is the controller's.
- the node stops (:meth:`TrajectoryActionProxy.stop`, from the node's ``close()`` on SIGINT or SIGTERM):
  new goals are rejected, every goal still running is cancelled at the controller (or not sent, if it
  has not been yet), and the stop waits up to ``timeout`` s for them to end, so the client sees each
  goal CANCELED (or ABORTED) rather than a server that vanished with its goal still moving the arm.

Everything here runs in the node's executor without blocking it: the execute callback is a
coroutine that awaits the controller's futures, so a SingleThreadedExecutor (``rclpy.spin``) is
enough; the shaper node serves it from its side node (ros/side_node.py), on a thread of its own,
so that shaping a long goal never delays its stream (shaping reads the active filter, it never
touches the streaming filters). ``reshape`` is awaited
in the execute callback, not in the goal callback: rclpy awaits a coroutine goal callback, but
inside the action server's callback group (the node's default group), which it would hold, and
with it every subscription and service of the node, for as long as the wait lasts.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Awaitable, Callable
from typing import TypeAlias

from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.client import ClientGoalHandle
from rclpy.action.server import ServerGoalHandle
from rclpy.clock import Clock, ClockType
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.task import Future
from rclpy.timer import Timer
from trajectory_msgs.msg import JointTrajectory
from unique_identifier_msgs.msg import UUID

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.memory import release_freed_memory
from shaper_nodes.ros.action_client import ResilientActionClient
from shaper_nodes.ros.pose_shaper import FALLBACK, Reshaped
from shaper_nodes.ros.qos import ACTION_CLIENT_QOS, ACTION_QOS
from shaper_nodes.ros.shaper_client import wait_for

from .goal_rules import check_tolerance_counts, check_tolerances, late_start_warning, with_trajectory

Goal: TypeAlias = FollowJointTrajectory.Goal
Result: TypeAlias = FollowJointTrajectory.Result
POLL = 0.05  # s, how often a goal waiting for the controller's server looks again
#: goals the proxy holds at once (being shaped, forwarded, or wound down at the controller); one more is
#: rejected at once, with the reason: a storm of goals is refused, not queued behind a controller that lags
MAX_LIVE = 16
#: a refused goal of at least this many values (points x joints) is followed by giving the freed memory back to
#: the system (a 10^5-point goal of 6 joints held about 130 MiB, most of which the allocator kept)
RELEASE_ABOVE = 60_000
#: s after such a refusal: rclpy drops the request once the goal request's task has sent the answer
RELEASE_DELAY = 0.5


class _Forward:
    """One goal of ours and what became of it at the controller."""

    def __init__(self, handle: ServerGoalHandle, goal: Goal) -> None:
        self.handle = handle
        self.goal = goal  # the shaped goal to send
        self.controller: ClientGoalHandle | None = None
        self.cancel_wanted = False  # our client asked to cancel
        self.preempted = False  # a newer goal took over
        self.cancel_sent = False
        self.node_stopping = False  # the node is stopping (TrajectoryActionProxy.stop)

    @property
    def stop(self) -> bool:
        return self.cancel_wanted or self.preempted or self.node_stopping

    @property
    def key(self) -> bytes:
        return bytes(self.handle.goal_id.uuid)


class TrajectoryActionProxy:
    """The FollowJointTrajectory server of a node, forwarding shaped goals to a controller.

    Parameters
    ----------
    node : Node
        The node that owns the server and the client (its executor runs them).
    server_name : str
        Name of the action we serve (``~/follow_joint_trajectory``).
    controller_name : str
        The controller's action (``/joint_trajectory_controller/follow_joint_trajectory``).
    shape : callable
        ``JointTrajectory -> JointTrajectory``, the shaped trajectory in the node's joint order;
        raises :class:`InputError` on bad input.
    on_refused : callable
        Called with the :class:`InputError` of each rejected goal (logging, diagnostics).
    on_forwarded : callable
        Called for each goal the controller accepted.
    timeout : float
        s: how long a goal waits for the controller's action server and for its answer to the
        goal request.
    on_late_start : callable, optional
        Called with :func:`late_start_warning`'s text for each goal accepted whose first point is after time 0.
    reshape : coroutine function, optional
        ``JointTrajectory -> JointTrajectory | Reshaped | None``, awaited for each accepted goal (its request's
        trajectory) before it is sent: the trajectory to send instead of the one shaped at the goal request (None,
        or a :class:`Reshaped` without one: keep that one), a :class:`Reshaped` saying what it was shaped with.
        It must bound its own wait and not raise.
    on_sending : callable, optional
        Called with the goal's handle and its :class:`Reshaped` (None if ``reshape`` gave none) just before the
        goal is sent to the controller.
    """

    def __init__(self, node: Node, server_name: str, controller_name: str,
                 shape: Callable[[JointTrajectory], JointTrajectory],
                 on_refused: Callable[[InputError], None], on_forwarded: Callable[[], None],
                 timeout: float,
                 reshape: Callable[[JointTrajectory], Awaitable[JointTrajectory | Reshaped | None]] | None = None,
                 on_late_start: Callable[[str], object] | None = None,
                 on_sending: Callable[[ServerGoalHandle, Reshaped | None], object] | None = None) -> None:
        self._node = node
        self._on_sending = on_sending
        self._on_late_start = on_late_start
        self._shape = shape
        self._reshape = reshape
        self._on_refused = on_refused
        self._on_forwarded = on_forwarded
        self._timeout = float(timeout)
        self._log = node.get_logger().get_child("follow_joint_trajectory")
        self._shaped: dict[int, tuple[Goal, Goal]] = {}  # id(request) -> (request, shaped goal)
        self._live: dict[bytes, _Forward] = {}
        self._active: _Forward | None = None
        self._stopping = False  # stop() was called: new goals are rejected
        self._release: Timer | None = None  # the timer that gives a refused large goal's memory back
        self.controller_name = controller_name
        # a goal response lost at start-up is recovered from the status topic, or the request sent
        # again, within the timeout (ros/action_client.py)
        self._client = ResilientActionClient(node, FollowJointTrajectory, controller_name,
                                             resend_period=max(0.05, self._timeout / 4),
                                             give_up_after=self._timeout, **ACTION_CLIENT_QOS)
        self._server = ActionServer(
            node, FollowJointTrajectory, server_name, execute_callback=self._execute,
            goal_callback=self._on_goal, handle_accepted_callback=self._on_accepted,
            cancel_callback=self._on_cancel, **ACTION_QOS)

    def stop(self) -> int:
        """Cancel every running goal at the controller, as the node stops; returns how many goals were still
        running after waiting ``timeout`` s for them to end (0: all ended).

        From another thread than the one spinning the node (the node's ``close()`` in the main thread, the
        node served by its side node's thread): the cancels are sent from that executor, which must go on
        spinning meanwhile. New goals are rejected from now on.
        """
        executor = self._node.executor
        if not self._live or executor is None or not self._node.context.ok():
            self._stopping = True
            return len(self._live)
        ended = threading.Event()

        async def cancel_all() -> None:
            self._stopping = True
            for fwd in list(self._live.values()):
                fwd.node_stopping = True
                self._cancel_at_controller(fwd)
            while self._live:  # each one ends in _run with the controller's status, or before it was sent
                await wait_for(self._node, Future(), POLL)
            ended.set()

        executor.create_task(cancel_all)
        ended.wait(self._timeout)
        if self._live:
            self._log.warning(f"{len(self._live)} goal(s) still running at the controller {self._timeout:g} s after"
                              " their cancel was sent; the node stops anyway")
        return len(self._live)

    def destroy(self) -> None:
        self._server.destroy()
        self._client.destroy()

    # ------------------------------------------------------------------ goal requests
    def shaped_goal(self, goal: Goal) -> Goal:
        """The goal to send to the controller: shaped trajectory, the same tolerances.

        Raises
        ------
        InputError
            If the goal is invalid (the message names the problem).
        """
        multi = goal.multi_dof_trajectory
        if multi.joint_names or multi.points:
            raise InputError("unsupported", "multi_dof_trajectory is not supported (only single-DOF joints"
                             " are shaped); send it empty")
        check_tolerance_counts(goal)
        shaped = self._shape(goal.trajectory)  # its size first, then its points (the node's joints from here)
        check_tolerances(goal)
        return with_trajectory(goal, shaped)

    def _on_goal(self, goal: Goal) -> GoalResponse:
        if self._stopping:
            self._log.warning("goal rejected: the node is stopping")
            return GoalResponse.REJECT
        if len(self._live) + len(self._shaped) >= MAX_LIVE:
            self._on_refused(InputError("too_large", f"{len(self._live)} goals are still being forwarded or wound"
                                        f" down at the controller (at most {MAX_LIVE}); this one is rejected at once"))
            return GoalResponse.REJECT
        try:
            shaped = self.shaped_goal(goal)
        except InputError as err:
            self._on_refused(err)
            if len(goal.trajectory.points) * max(1, len(goal.trajectory.joint_names)) >= RELEASE_ABOVE:
                self._release_later()
            return GoalResponse.REJECT
        self._shaped[id(goal)] = (goal, shaped)  # the request object itself keeps the id unique
        first = goal.trajectory.points[0].time_from_start  # (a shaped goal has points)
        if self._on_late_start is not None and (first.sec or first.nanosec):
            self._on_late_start(late_start_warning(first.sec + first.nanosec * 1e-9, len(goal.trajectory.points)))
        return GoalResponse.ACCEPT

    def _release_later(self) -> None:
        """Give the freed memory back to the system :data:`RELEASE_DELAY` s from now (once, however many
        large goals are refused meanwhile): rclpy still holds the request while its goal callback runs."""
        if self._release is not None:
            return

        def release() -> None:
            timer, self._release = self._release, None
            if timer is not None:
                self._node.destroy_timer(timer)
            release_freed_memory()

        self._release = self._node.create_timer(RELEASE_DELAY, release, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _on_accepted(self, handle: ServerGoalHandle) -> None:
        entry = self._shaped.pop(id(handle.request), None)
        shaped = entry[1] if entry is not None else self.shaped_goal(handle.request)
        fwd = _Forward(handle, shaped)
        self._live[fwd.key] = fwd
        previous, self._active = self._active, fwd
        if previous is not None and previous.handle.is_active:
            self._log.info("a new goal preempts the running one: cancelling it at the controller")
            previous.preempted = True
            self._cancel_at_controller(previous)
        handle.execute()

    def _on_cancel(self, handle: ServerGoalHandle) -> CancelResponse:
        fwd = self._live.get(bytes(handle.goal_id.uuid))
        if fwd is not None:
            fwd.cancel_wanted = True
            self._cancel_at_controller(fwd)
        return CancelResponse.ACCEPT

    def _cancel_at_controller(self, fwd: _Forward) -> None:
        # Before the controller has the goal, _run sees fwd.stop and does not send it (or cancels
        # it as soon as it is accepted).
        if fwd.controller is not None and not fwd.cancel_sent:
            fwd.cancel_sent = True
            fwd.controller.cancel_goal_async()

    # ------------------------------------------------------------------ execution
    async def _execute(self, handle: ServerGoalHandle) -> Result:
        fwd = self._live[bytes(handle.goal_id.uuid)]
        try:
            return await self._run(fwd)
        finally:
            del self._live[fwd.key]
            if self._active is fwd:
                self._active = None

    async def _run(self, fwd: _Forward) -> Result:
        name = self.controller_name
        reshaped = None
        if self._reshape is not None:
            reshaped = await self._reshaped(fwd)
            if fwd.stop:
                return self._stopped_before_sending(fwd)
        if not await self._wait_for_server(fwd):
            if fwd.stop:
                return self._stopped_before_sending(fwd)
            return self._abort(fwd, f"controller action server {name} not available after {self._timeout:g} s;"
                                    " the goal was not sent")
        if fwd.stop:
            return self._stopped_before_sending(fwd)

        handle = fwd.handle
        if self._on_sending is not None:
            self._on_sending(handle, reshaped)

        def relay(msg) -> None:
            if handle.is_active:
                handle.publish_feedback(msg.feedback)

        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        sent = self._client.send_goal_async(fwd.goal, feedback_callback=relay, goal_uuid=goal_id)
        if not await wait_for(self._node, sent, self._timeout):
            # not left running: cancelled by its id now (accepted with its answer and status lost, it runs), and
            # again if its acceptance comes late (the client cancels a goal request it gave up on when answered)
            self._client.cancel_goal_id(goal_id)
            return self._abort(fwd, f"controller {name} did not answer the goal request within {self._timeout:g} s")
        fwd.controller = sent.result()
        if not fwd.controller.accepted:
            return self._abort(fwd, f"controller {name} rejected the shaped goal (see the controller's log:"
                                    " joint names, controller not active, trajectory in the past ...)")
        self._on_forwarded()
        if fwd.stop:
            self._cancel_at_controller(fwd)
        # a controller killed or restarted meanwhile never answers: the client watches it and ends the result with
        # STATUS_UNKNOWN and the reason (gone: out of the graph and silent for its period, 2 s at least; restarted:
        # the new instance does not know the goal), which _finish turns into ABORTED. The one watch: a proxy's own,
        # quicker one (1 s of silence and one look at the graph) read a restart as a death (CI, session 21)
        response = await fwd.controller.get_result_async()
        return self._finish(fwd, response.status, response.result)

    async def _reshaped(self, fwd: _Forward) -> Reshaped | None:
        """The goal reshaped (``reshape``; its trajectory put in ``fwd.goal``), and what it was shaped with (None:
        ``reshape`` does not say)."""
        assert self._reshape is not None
        try:
            answer = await self._reshape(fwd.handle.request.trajectory)
        except Exception as err:  # a fault there must not lose the goal: it keeps its shaped trajectory
            self._log.error(f"reshaping the goal failed ({err!r}); it is sent as shaped at its request")
            answer = Reshaped(None, FALLBACK, f"reshaping the goal failed ({err!r})")
        trajectory = answer.trajectory if isinstance(answer, Reshaped) else answer
        if trajectory is not None:
            fwd.goal = with_trajectory(fwd.goal, trajectory)
        return answer if isinstance(answer, Reshaped) else None

    async def _wait_for_server(self, fwd: _Forward) -> bool:
        end = time.monotonic() + self._timeout
        while not self._client.server_is_ready():
            if fwd.stop or time.monotonic() >= end:
                return False
            await wait_for(self._node, Future(), POLL)
        return True

    # ------------------------------------------------------------------ endings
    def _finish(self, fwd: _Forward, status: int, result: Result) -> Result:
        handle = fwd.handle
        if status == GoalStatus.STATUS_SUCCEEDED:
            handle.succeed()
        elif status == GoalStatus.STATUS_CANCELED:
            if fwd.preempted and not result.error_string:
                result.error_string = "preempted by a newer goal"
            elif fwd.node_stopping and not fwd.cancel_wanted and not result.error_string:
                result.error_string = "the shaper node stopped: the goal was cancelled at the controller"
            if not _to_canceling(handle):
                handle.abort()
                return result
            handle.canceled()
        elif status == GoalStatus.STATUS_UNKNOWN:  # the controller gone, or restarted without the goal (the client)
            return self._abort(fwd, result.error_string or f"controller {self.controller_name} does not know the goal")
        else:
            if status != GoalStatus.STATUS_ABORTED and not result.error_string:
                result.error_string = f"controller {self.controller_name} ended the goal with status {status}"
            handle.abort()
        return result

    def _stopped_before_sending(self, fwd: _Forward) -> Result:
        if fwd.preempted:
            result = Result(error_code=Result.INVALID_GOAL,
                            error_string="preempted by a newer goal before it was sent to the controller")
        elif fwd.node_stopping and not fwd.cancel_wanted:
            result = Result(error_code=Result.SUCCESSFUL,
                            error_string="the shaper node stopped before the goal was sent to the controller")
        else:
            result = Result(error_code=Result.SUCCESSFUL,
                            error_string="canceled before it was sent to the controller")
        if _to_canceling(fwd.handle):
            fwd.handle.canceled()
        else:
            fwd.handle.abort()
        return result

    def _abort(self, fwd: _Forward, why: str) -> Result:
        self._log.error(f"goal aborted: {why}")
        fwd.handle.abort()
        return Result(error_code=Result.INVALID_GOAL, error_string=why)


def _to_canceling(handle: ServerGoalHandle) -> bool:
    """Move a goal to CANCELING if it is not there yet (preemption); whether it is there now.

    A goal reaches CANCELED only through CANCELING. A client's cancel request makes that step; a
    preempted goal (or one cancelled at the controller by someone else) has to make it here.
    rclpy has no public call for this (rclcpp_action's ``canceled()`` does it itself), hence the
    private one; if it fails, the caller aborts the goal instead.
    """
    if handle.is_cancel_requested:
        return True
    try:
        handle._update_state(_rclpy.GoalEvent.CANCEL_GOAL)
    except Exception:
        return False
    return handle.is_cancel_requested
