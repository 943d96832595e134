# Copyright 2026 The ros2 vibration suppression authors
# SPDX-License-Identifier: Apache-2.0
"""An action client whose goals survive a lost service response.

ROS 2 actions ride on services, and a service response can be lost at start-up: the server's
response writer may not yet have matched the client's response reader when it answers, although
the client already sees the server (``server_is_ready()`` is true). Fast DDS then drops the
response with ``failed to send response (timeout): client will not receive response``
(rmw_fastrtps, ``rmw_response.cpp``), and ``send_goal_async`` never completes, although the server
accepted the goal and is executing it. It happens on busy machines and, rarely, on quiet ones.

:class:`ResilientActionClient` is an :class:`rclpy.action.ActionClient` that recovers from it
without guessing:

* **A goal accepted but not answered** is seen on the action's status topic (the server publishes
  every accepted goal's status there, transient local): when no response has come ``resend_period``
  after the request, the goal's future completes with a goal handle built from that status, as if
  the response had arrived.
* **A goal request answered by nobody** (neither a response nor a status naming its id within
  ``resend_period``) is sent again *with the same goal id*. A server that never saw it handles it
  now; one that accepted it refuses the duplicate id, and the status decides (a rejection of a
  resent request is taken as final only when no status names the goal one more period later).
* **A result lost** (the status says the goal has ended, and no result arrives within
  ``resend_period``) is asked for again; the server keeps results for its ``result_timeout``.
* **A server killed or restarted while a goal runs** never says that the goal ended. While a result
  is awaited the client watches the server: a new instance (a status publisher GID not there when the
  result was first asked for, or a status list dropping a goal it named, not ended) makes it ask for
  the result again, which a server not knowing the goal answers ``STATUS_UNKNOWN`` at once; a server
  out of the graph (and silent) for a period, :data:`GONE_AFTER` at least, is gone. Either way the
  result comes with status ``STATUS_UNKNOWN`` and the reason in its ``error_string`` (if it has one):
  only ``STATUS_SUCCEEDED`` is success. A paused server (SIGSTOP shorter than the DDS lease, 20 s with
  Fast DDS) keeps its endpoints and its goals: nothing ends.

Nothing here waits a fixed time for a state: the periods are resend intervals, and every outcome
is a message (a response or a status). The work is bounded: one timer, active only while a request
is pending, and at most :data:`MAX_STATUSES` goal statuses remembered. With ``give_up_after`` a goal
request is sent again only until that many seconds after its first sending (its caller has given
up by then): a storm of goals against a server that does not answer costs at most
``give_up_after / resend_period`` resends each; a goal abandoned so and accepted late is cancelled
at once. ``pending`` says how many goal requests await an answer, for a caller that bounds them.
"""

from __future__ import annotations

import threading
import time
import uuid
import weakref
from dataclasses import dataclass, field
from typing import Any

from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.clock import Clock, ClockType
from rclpy.task import Future

from .goal_feedback import GoalFeedback as GoalFeedback  # handed on: it lived here
from .qos import ACTION_CLIENT_QOS

#: goal statuses remembered (the newest), to recognise goals accepted without a response
MAX_STATUSES = 1024
#: the goal states after which the server has a result
TERMINAL = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)
#: s out of the graph (and silent) at least to be gone: a restarted server can drop the killed one from the graph
#: a moment before its own endpoints show (docs/results/testing.md, H8 deadserver)
GONE_AFTER = 2.0


@dataclass
class _GoalSend:
    goal: Any
    feedback: Any
    goal_id: Any
    future: Future
    sent_at: float
    attempts: int = 1
    first_at: float = 0.0
    rejected: Any = None  # the rejection of a resent request, waiting one period for a status
    rejected_at: float = 0.0


@dataclass
class _ResultWait:
    handle: ClientGoalHandle
    future: Future
    asked_at: float
    ended_at: float | None = None
    attempts: int = 1
    requests: list[Future] = field(default_factory=list)
    gids: frozenset[bytes] | None = None  # the server's status publisher endpoints when first seen
    seen: bool = False  # a status list has named the goal (not ended): a later list without it lost it
    gone_since: float | None = None  # the server out of the graph since
    restarted: bool = False  # a new server instance suspected: asked again, UNKNOWN is its answer


class ResilientActionClient(ActionClient):
    """An :class:`~rclpy.action.ActionClient` that recovers goals and results whose service response
    was lost (see the module docstring). Use it as the rclpy class: same constructor, same futures.

    Parameters
    ----------
    node : rclpy.node.Node
        The node the client belongs to (its executor runs the resend timer).
    action_type, action_name
        As for :class:`~rclpy.action.ActionClient`.
    resend_period : float
        s without an answer after which a goal request or a result request is sent again (steady
        clock, so it runs while simulated time stands still).
    **kwargs
        Passed to :class:`~rclpy.action.ActionClient` (QoS profiles, callback group); the QoS profiles not given
        are the suite's (:data:`~shaper_nodes.ros.qos.ACTION_CLIENT_QOS`: queued goal, cancel and result calls, a
        deep feedback queue).
    """

    def __init__(self, node: Any, action_type: Any, action_name: str, *, resend_period: float = 2.0,
                 give_up_after: float | None = None, **kwargs: Any) -> None:
        if not resend_period > 0:
            raise ValueError(f"resend_period must be positive, got {resend_period!r}")
        super().__init__(node, action_type, action_name, **{**ACTION_CLIENT_QOS, **kwargs})
        self.resend_period = float(resend_period)
        self.give_up_after = None if give_up_after is None else float(give_up_after)
        #: goal requests given up (no answer within give_up_after); a late acceptance of one is cancelled
        self.given_up = 0
        self._abandoned: dict[bytes, None] = {}
        self._lock = threading.Lock()
        self._statuses: dict[bytes, tuple[int, Any]] = {}  # goal id -> (status, goal_info)
        self._sends: dict[bytes, _GoalSend] = {}
        self._results: dict[bytes, _ResultWait] = {}
        self._own_handles: dict[bytes, weakref.ref[ClientGoalHandle]] = {}
        #: requests sent again (goal and result), for diagnostics and tests
        self.resent = 0
        #: goals whose handle came from the status topic because their response was lost
        self.recovered = 0
        #: results ended by the client because the server was gone or restarted (status UNKNOWN)
        self.lost = 0
        self._heard = time.monotonic()  # the last status or feedback message (steady s)
        self._status_topic = action_name.rstrip("/") + "/_action/status"
        self._timer = node.create_timer(self.resend_period / 4, self._check, callback_group=self.callback_group,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._timer.cancel()

    # ------------------------------------------------------------------ goals
    def send_goal_async(self, goal: Any, feedback_callback: Any = None, goal_uuid: Any = None) -> Future:
        """Send a goal; the future completes with a :class:`ClientGoalHandle` once the server's answer
        is known (its response, or its status topic naming the goal)."""
        goal_id = self._generate_random_uuid() if goal_uuid is None else goal_uuid
        outer = Future()
        self.add_future(outer)
        now = time.monotonic()
        send = _GoalSend(goal, feedback_callback, goal_id, outer, now, first_at=now)
        with self._lock:
            self._sends[bytes(goal_id.uuid)] = send
        self._request_goal(send)
        self._timer.reset()
        return outer

    def _request_goal(self, send: _GoalSend) -> None:
        inner = super().send_goal_async(send.goal, send.feedback, send.goal_id)
        inner.add_done_callback(lambda f, s=send: self._on_goal_response(s, f))

    @property
    def pending(self) -> int:
        """Goal requests sent and not yet answered (nor given up)."""
        with self._lock:
            return len(self._sends)

    def _on_goal_response(self, send: _GoalSend, inner: Future) -> None:
        handle = inner.result()
        key = bytes(send.goal_id.uuid)
        with self._lock:
            late = self._abandoned.pop(key, 0) is None
        if late:
            if handle is not None and handle.accepted:  # accepted after its caller gave up: not left running
                handle.cancel_goal_async()
            return
        with self._lock:
            if send.future.done() or self._sends.get(key) is not send:
                return
            if handle.accepted or send.attempts == 1:
                del self._sends[key]
                done: Any = handle
            elif key in self._statuses:  # the resend was refused as a duplicate: accepted before
                del self._sends[key]
                done = self._handle_from_status(key)
            else:  # a resend refused: final unless a status names the goal within a period
                send.rejected, send.rejected_at = handle, time.monotonic()
                return
        send.future.set_result(done)

    def _handle_from_status(self, key: bytes) -> ClientGoalHandle:
        """A goal handle for an accepted goal known from the status topic (lock held)."""
        status, info = self._statuses[key]
        response = self._action_type.Impl.SendGoalService.Response(accepted=True, stamp=info.stamp)
        handle = ClientGoalHandle(self, info.goal_id, response)
        handle._status = status
        self._own_handles[key] = weakref.ref(handle)
        self.recovered += 1
        self._node.get_logger().warning(
            f"{self._action_name}: the goal response was lost on the way (the server accepted the goal:"
            " its status says so); going on with the goal")
        return handle

    def cancel_goal_id(self, goal_id: Any) -> Future:
        """Ask the server to cancel goal ``goal_id`` whatever this client knows of its answer: a stop that cannot
        wait for the answer to a goal request (a signal, a dead link) cancels so a goal the server accepted but
        whose response and status were lost; a server that never took the goal refuses the cancel, harmless. A
        goal request still pending is given up (a late acceptance of it is cancelled on arrival). The future
        completes with the server's ``CancelGoal`` response."""
        key = bytes(goal_id.uuid)
        with self._lock:
            send = self._sends.pop(key, None)
            if send is not None and not send.future.done():
                self._abandon(key)
        response = self._action_type.Impl.SendGoalService.Response(accepted=True)
        return self._cancel_goal_async(ClientGoalHandle(self, goal_id, response))

    # ------------------------------------------------------------------ results
    def _get_result_async(self, goal_handle: ClientGoalHandle) -> Future:
        outer = Future()
        self.add_future(outer)
        wait = _ResultWait(goal_handle, outer, time.monotonic())
        key = bytes(goal_handle.goal_id.uuid)
        wait.gids = self._server_gids() or None
        with self._lock:
            self._results[key] = wait
            if self._statuses.get(key, (GoalStatus.STATUS_UNKNOWN,))[0] in TERMINAL:
                wait.ended_at = time.monotonic()
            wait.seen = key in self._statuses
        self._request_result(wait)
        self._timer.reset()
        return outer

    def _request_result(self, wait: _ResultWait) -> None:
        inner = super()._get_result_async(wait.handle)
        wait.requests.append(inner)
        inner.add_done_callback(lambda f, w=wait: self._on_result(w, f))

    def _on_result(self, wait: _ResultWait, inner: Future) -> None:
        response = inner.result()
        if response.status == GoalStatus.STATUS_UNKNOWN:
            self._end_lost(wait, response, f"the action server {self._action_name} "
                           + ("restarted and does not know goal" if wait.restarted
                              else "does not know goal (it restarted, or the goal's result expired):")
                           + f" {_goal_name(wait)}")
        else:
            self._end(wait, response)

    def _end(self, wait: _ResultWait, response: Any) -> bool:
        """Complete the result's future with ``response`` (once); drop its requests still pending."""
        key = bytes(wait.handle.goal_id.uuid)
        with self._lock:
            if wait.future.done():
                return False
            if self._results.get(key) is wait:
                del self._results[key]
        for request in wait.requests:
            if not request.done():
                self._remove_pending_result_request(request)
        wait.future.set_result(response)
        return True

    def _end_lost(self, wait: _ResultWait, response: Any, why: str) -> None:
        """End the goal as failed: status UNKNOWN, ``why`` in the result's ``error_string`` (if it has one)."""
        response.status = GoalStatus.STATUS_UNKNOWN
        if hasattr(response.result, "error_string") and not response.result.error_string:
            response.result.error_string = why
        if self._end(wait, response):
            self.lost += 1
            self._node.get_logger().error(f"{self._action_name}: the goal has failed: {why}")

    def _server_gids(self) -> frozenset[bytes]:
        """The endpoint GIDs of the action's status publishers in the graph (one per server instance)."""
        return frozenset(bytes(i.endpoint_gid) for i in self._node.get_publishers_info_by_topic(self._status_topic))

    # ------------------------------------------------------------------ status and resends
    async def execute(self, taken_data: Any) -> None:
        if "status" in taken_data or "feedback" in taken_data:
            self._heard = time.monotonic()
        if "status" in taken_data:
            self._note_statuses(taken_data["status"].status_list)
        await super().execute(taken_data)

    def _note_statuses(self, status_list: Any) -> None:
        now = time.monotonic()
        with self._lock:
            named = {bytes(s.goal_info.goal_id.uuid) for s in status_list}
            for key, waiting in self._results.items():  # named, then dropped while not ended: the server lost it
                if key in named:
                    waiting.seen = True
                elif waiting.seen and waiting.ended_at is None and not waiting.future.done():
                    waiting.restarted = True
                    self._ask_again(waiting, now)
            for s in status_list:
                key = bytes(s.goal_info.goal_id.uuid)
                self._statuses.pop(key, None)
                self._statuses[key] = (s.status, s.goal_info)
                ref = self._own_handles.get(key)
                handle = ref() if ref is not None else None
                if handle is not None:
                    handle._status = s.status
                wait = self._results.get(key)
                if wait is not None and s.status in TERMINAL and wait.ended_at is None:
                    wait.ended_at = now
            while len(self._statuses) > MAX_STATUSES:
                self._statuses.pop(next(iter(self._statuses)))
            for key in [k for k, r in self._own_handles.items() if r() is None]:
                del self._own_handles[key]

    def _due_goals(self, now: float, period: float) -> tuple[list[_GoalSend], list[tuple[Future, Any]]]:
        """The goal requests to send again, and the futures to complete with their handle (refused after
        a resend, or recovered from the status topic); the abandoned ones dropped (lock held)."""
        goals, done = [], []
        for key, send in list(self._sends.items()):
            if send.future.done():
                del self._sends[key]
            elif send.rejected is not None:
                if key in self._statuses:  # the refused resend's goal is there after all: accepted before
                    del self._sends[key]
                    done.append((send.future, self._handle_from_status(key)))
                elif now - send.rejected_at > period:
                    del self._sends[key]
                    done.append((send.future, send.rejected))
            elif now - send.sent_at <= period:
                continue
            elif self.give_up_after is not None and now - send.first_at > self.give_up_after:
                del self._sends[key]
                self._abandon(key)
                self.given_up += 1
            elif key in self._statuses:  # accepted (the status says so), and no response came
                del self._sends[key]
                done.append((send.future, self._handle_from_status(key)))
            else:
                send.sent_at, send.attempts = now, send.attempts + 1
                goals.append(send)
        return goals, done

    def _abandon(self, key: bytes) -> None:
        """Remember a goal request given up, so that its late acceptance is cancelled (lock held)."""
        self._abandoned[key] = None
        while len(self._abandoned) > MAX_STATUSES:
            self._abandoned.pop(next(iter(self._abandoned)))

    def _check(self) -> None:
        """Resend what has had no answer for a period; conclude the refusals of resent goals."""
        now = time.monotonic()
        period = self.resend_period
        results = []
        with self._lock:
            goals, done = self._due_goals(now, period)
            waits = [w for w in self._results.values() if not w.future.done()]
        gone = self._watch_server(waits, now) if waits else []
        with self._lock:
            for key, wait in list(self._results.items()):
                if wait.future.done():
                    del self._results[key]
                elif wait.ended_at is not None and now - max(wait.ended_at, wait.asked_at) > period:
                    wait.asked_at, wait.attempts = now, wait.attempts + 1
                    results.append(wait)
            idle = not self._sends and not self._results
        for future, handle in done:
            future.set_result(handle)
        for send in goals:
            self.resent += 1
            self._node.get_logger().warning(
                f"{self._action_name}: no answer to a goal request after {period:g} s (a response lost at"
                f" start-up?); sending it again with the same goal id (attempt {send.attempts})")
            self._request_goal(send)
        for wait in results:
            self.resent += 1
            self._node.get_logger().warning(
                f"{self._action_name}: the goal has ended but its result has not arrived after {period:g} s;"
                " asking again")
            self._request_result(wait)
        for wait in gone:
            self._end_lost(wait, self._action_type.Impl.GetResultService.Response(),
                           f"the action server {self._action_name} is gone (out of the graph and silent for"
                           f" {max(period, GONE_AFTER):g} s) with goal {_goal_name(wait)}")
        if idle:
            self._timer.cancel()

    def _watch_server(self, waits: list[_ResultWait], now: float) -> list[_ResultWait]:
        """Note a restarted server (a status publisher not there before: its results are asked for again) and
        return the waits whose server is gone (out of the graph, and nothing heard, for a period)."""
        period = self.resend_period
        if not self.server_is_ready():
            gone, after = [], max(period, GONE_AFTER)
            for wait in waits:
                wait.gone_since = now if wait.gone_since is None else wait.gone_since
                if now - wait.gone_since > after and now - self._heard > after:
                    gone.append(wait)
            return gone
        gids = self._server_gids()
        with self._lock:
            for wait in waits:
                wait.gone_since = None
                if wait.gids is None:
                    wait.gids = gids or None
                elif gids - wait.gids and not wait.restarted:
                    wait.gids = gids
                    wait.restarted = True
                    self._ask_again(wait, now)
        return []

    def _ask_again(self, wait: _ResultWait, now: float) -> None:
        """Make the result's request due at the next check, and again every period until answered (lock held)."""
        past = now - 2 * self.resend_period
        wait.asked_at = past
        if wait.ended_at is None:
            wait.ended_at = past

    def destroy(self) -> None:
        self._timer.cancel()
        self._node.destroy_timer(self._timer)
        super().destroy()


def _goal_name(wait: _ResultWait) -> str:
    return str(uuid.UUID(bytes=bytes(wait.handle.goal_id.uuid)))
