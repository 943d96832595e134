"""ResilientActionClient against a real rclpy action server over DDS that loses responses.

The server is a real :class:`rclpy.action.ActionServer`; losing a response is injected where
rmw_fastrtps loses it at start-up: the server handles the request (accepts or rejects the goal,
finishes it) and its response is not delivered. The client must carry on from what it can see (the
status topic) and ask again where nothing can be seen.
"""

from __future__ import annotations

import time
import uuid
from typing import Any

import pytest
import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.executors import SingleThreadedExecutor

from shaper_nodes.ros.action_client import GoalFeedback, ResilientActionClient

pytestmark = pytest.mark.integration
ACTION = "/lossy_controller/follow_joint_trajectory"
Goal = FollowJointTrajectory.Goal


class LossyHandle:
    """The server's rclpy handle, losing the first ``lose_goal`` goal responses and the first
    ``lose_result`` result responses (they are handled, then not sent); ``result_requests`` counts the result
    requests taken (a client asks for the result once it has the goal's answer)."""

    def __init__(self, handle: Any, lose_goal: int = 0, lose_result: int = 0, lose_status: bool = False) -> None:
        self._handle, self.lose_goal, self.lose_result = handle, lose_goal, lose_result
        self.lose_status = lose_status
        self.goal_requests = 0
        self.result_requests = 0
        self.lost = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)

    def __enter__(self) -> Any:
        return self._handle.__enter__()

    def __exit__(self, *exc: Any) -> Any:
        return self._handle.__exit__(*exc)

    def send_goal_response(self, header: Any, response: Any) -> None:
        self.goal_requests += 1
        if self.lose_goal > 0:
            self.lose_goal -= 1
            self.lost += 1
            return
        self._handle.send_goal_response(header, response)

    def take_result_request(self, *args: Any) -> Any:
        taken = self._handle.take_result_request(*args)
        if taken is not None and taken[0] is not None:
            self.result_requests += 1
        return taken

    def publish_status(self) -> None:
        if not self.lose_status:
            self._handle.publish_status()

    def send_result_response(self, header: Any, response: Any) -> None:
        if self.lose_result > 0:
            self.lose_result -= 1
            self.lost += 1
            return
        self._handle.send_result_response(header, response)


class Rig:
    """A server node and a client node in one executor."""

    def __init__(self, ctx: Any, *, accept: bool = True, lose_goal: int = 0, lose_result: int = 0,
                 lose_status: bool = False, hold: bool = False, give_up_after: float | None = None,
                 feedback: int = 0) -> None:
        self.server_node = rclpy.create_node("lossy_controller", context=ctx)
        self.client_node = rclpy.create_node("resilient_client", context=ctx)
        self.executed = 0
        self.cancelled: list[bytes] = []  # the ids of the goals whose cancel the server took

        def execute(handle: Any) -> Any:
            self.executed += 1
            for k in range(1, feedback + 1):  # stamped k s, then the result at once
                fb = FollowJointTrajectory.Feedback()
                fb.header.stamp.sec = k
                handle.publish_feedback(fb)
            handle.succeed()
            return FollowJointTrajectory.Result(error_code=0, error_string=f"done {self.executed}")

        def cancel(handle: Any) -> CancelResponse:
            self.cancelled.append(bytes(handle.goal_id.uuid))
            return CancelResponse.ACCEPT

        # hold: an accepted goal is not started (it stays ACCEPTED, as a goal queued at a busy controller)
        self.server = ActionServer(self.server_node, FollowJointTrajectory, ACTION, execute_callback=execute,
                                   goal_callback=lambda _goal: GoalResponse.ACCEPT if accept else GoalResponse.REJECT,
                                   cancel_callback=cancel,
                                   handle_accepted_callback=(lambda _h: None) if hold else None)
        self.lossy = LossyHandle(self.server._handle, lose_goal, lose_result, lose_status)
        self.server._handle = self.lossy
        self.client = ResilientActionClient(self.client_node, FollowJointTrajectory, ACTION, resend_period=0.5,
                                            give_up_after=give_up_after)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.server_node)
        self.ex.add_node(self.client_node)
        self.spin_until(self.client.server_is_ready, "the server")

    def spin_until(self, cond: Any, what: str, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def send(self, goal: Goal | None = None) -> Any:
        future = self.client.send_goal_async(goal or Goal())
        self.spin_until(future.done, "the goal's handle")
        return future.result()

    def result(self, handle: Any) -> Any:
        future = handle.get_result_async()
        self.spin_until(future.done, "the result")
        return future.result()

    def close(self) -> None:
        self.ex.shutdown()
        self.client.destroy()
        self.server.destroy()
        self.client_node.destroy_node()
        self.server_node.destroy_node()


@pytest.fixture
def rig(ros_context, request):
    rigs: list[Rig] = []

    def make(**kw: Any) -> Rig:
        rigs.append(Rig(ros_context, **kw))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def test_a_goal_whose_response_is_lost_goes_on_from_its_status(rig):
    r = rig(lose_goal=1)
    handle = r.send()
    assert handle.accepted
    assert r.lossy.lost == 1 and r.client.recovered == 1
    res = r.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED
    assert res.result.error_string == "done 1"
    assert r.executed == 1, "the goal ran once: a resend must not start it twice"


def test_a_rejection_whose_response_is_lost_is_asked_again_and_stays_a_rejection(rig):
    r = rig(accept=False, lose_goal=1)
    handle = r.send()
    assert not handle.accepted
    assert r.lossy.goal_requests >= 2 and r.client.resent >= 1
    assert r.executed == 0


def test_a_goal_whose_answer_and_status_are_lost_is_cancelled_by_its_id(rig):
    """The worst a stop meets (calibrate's SIGTERM landing in rclpy's take of the goal's response and status
    together, session 19): the goal runs at the server, the client never learns it was accepted, and its resend
    is refused as a duplicate id. ``cancel_goal_id`` cancels it by the id it was sent with all the same."""
    from unique_identifier_msgs.msg import UUID

    r = rig(lose_goal=1, lose_status=True, hold=True)
    goal_id = UUID(uuid=list(uuid.uuid4().bytes))
    future = r.client.send_goal_async(Goal(), goal_uuid=goal_id)
    r.spin_until(future.done, "the refusal of the resent request")
    assert not future.result().accepted and r.lossy.goal_requests == 2  # what the client knows: refused
    cancel = r.client.cancel_goal_id(goal_id)
    r.spin_until(cancel.done, "the answer to the cancel")
    assert r.cancelled == [bytes(goal_id.uuid)]
    assert [bytes(g.goal_id.uuid) for g in cancel.result().goals_canceling] == [bytes(goal_id.uuid)]


def test_a_cancel_by_id_of_a_goal_the_server_never_had_is_refused(rig):
    from action_msgs.srv import CancelGoal
    from unique_identifier_msgs.msg import UUID

    r = rig(hold=True)
    cancel = r.client.cancel_goal_id(UUID(uuid=list(uuid.uuid4().bytes)))
    r.spin_until(cancel.done, "the answer to the cancel")
    assert r.cancelled == [] and not cancel.result().goals_canceling
    assert cancel.result().return_code == CancelGoal.Response.ERROR_UNKNOWN_GOAL_ID


def test_a_lost_result_is_asked_for_again(rig):
    r = rig(lose_result=1)
    handle = r.send()
    assert handle.accepted and r.client.recovered == 0
    res = r.result(handle)
    assert res.status == GoalStatus.STATUS_SUCCEEDED and res.result.error_string == "done 1"
    assert r.lossy.lost == 1 and r.client.resent >= 1


def test_a_goal_request_nobody_answers_is_resent_only_until_give_up_after(rig):
    """Every answer lost (a rejection: no status names the goal either): the request is sent again every
    0.5 s until 2 s after its first sending, then given up: at most 4 resends, nothing left pending (so
    nothing more is sent), the caller's future left to its own timeout (the proxy's server_timeout)."""
    r = rig(accept=False, lose_goal=1000, give_up_after=2.0)
    future = r.client.send_goal_async(Goal())
    r.spin_until(lambda: r.client.given_up == 1, "the request given up")
    assert r.client.pending == 0 and not future.done()
    assert 1 <= r.client.resent <= 4 and r.lossy.goal_requests <= 1 + r.client.resent


def test_without_losses_it_is_the_plain_client(rig):
    r = rig()
    for k in (1, 2, 3):
        handle = r.send()
        assert handle.accepted
        res = r.result(handle)
        assert res.status == GoalStatus.STATUS_SUCCEEDED and res.result.error_string == f"done {k}"
    assert r.client.resent == 0 and r.client.recovered == 0 and r.lossy.lost == 0
    assert isinstance(r.client, ActionClient)


def test_a_goals_feedback_is_kept_when_its_result_comes_first(rig):
    """rclpy drops a goal's feedback callback when its result is handled, and a busy executor can handle a
    short goal's result before its feedback: GoalFeedback keeps every stamp of the goal it follows, in order,
    whatever came first, and nothing of a goal it does not follow."""
    r = rig(feedback=5)
    follow = GoalFeedback(r.client_node, FollowJointTrajectory, ACTION)
    other = r.client.send_goal_async(Goal())  # not followed
    r.spin_until(other.done, "the first goal's handle")
    r.result(other.result())
    goal_id, stamps = follow.new_goal()
    handed: list[float] = []
    future = r.client.send_goal_async(Goal(), feedback_callback=lambda m: handed.append(m.feedback.header.stamp.sec),
                                      goal_uuid=goal_id)
    r.spin_until(future.done, "the goal's handle")
    res = r.result(future.result())
    assert res.status == GoalStatus.STATUS_SUCCEEDED
    r.spin_until(lambda: len(stamps) == 5, "the five feedbacks")
    assert stamps == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert len(handed) <= 5  # (rclpy's own callback: whatever it was handed before the result)
    follow.forget(goal_id)
    assert follow.new_goal()[1] == []


def test_a_resend_period_that_is_not_positive_is_refused(ros_context):
    node = rclpy.create_node("bad_period", context=ros_context)
    try:
        with pytest.raises(ValueError, match="resend_period must be positive"):
            ResilientActionClient(node, FollowJointTrajectory, ACTION, resend_period=0.0)
    finally:
        node.destroy_node()
