"""A goal id sent again through a chain of FollowJointTrajectory proxies runs once at the controller, over DDS.

The chain of the arm demo's speed-up case, all real nodes in one process: a client -> the learner's proxy
(``mode: speed_moves``, nodes/learner_speed.py) -> the shaper node's proxy -> a test controller that serves the
real control_msgs interface and records every goal it executes (and holds each until the test releases it). Both
proxies are :class:`~shaper_nodes.nodes.trajectory_action.TrajectoryActionProxy`.

A client's goal request is sent again with the same goal id when no answer has come within its resend period
(:class:`~shaper_nodes.ros.action_client.ResilientActionClient`, the demo client's): under load both requests wait
at the proxy before it takes either. Shown: the proxy runs the goal once and answers the second request as the
same goal (refused as a duplicate id by rclpy's action server, and the client goes on with the goal it accepted:
one goal handle, one result); the controller executes one goal and cancels none (no preemption). The same holds
for a goal id sent again while the goal runs, and for two requests of one id from two clients.
"""

from __future__ import annotations

import time
import uuid

import pytest
import rclpy
from action_msgs.msg import GoalInfo, GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from unique_identifier_msgs.msg import UUID

from shaper_nodes.ros.action_client import ResilientActionClient
from shaper_nodes.ros.conversions import sec_to_duration

pytestmark = pytest.mark.integration

WAIT = 120.0  # s of wall time for a state to come (two busy cores)
NAMES = ["j1", "j2"]
CONTROLLER = "/resend_test_controller/follow_joint_trajectory"
LEARNER = "/learner/follow_joint_trajectory"
Goal = FollowJointTrajectory.Goal


class Controller:
    """Plays joint_trajectory_controller's action server: records each goal it executes, holds it until released."""

    def __init__(self, ctx) -> None:
        self.node = rclpy.create_node("resend_test_controller", context=ctx)
        self.executed: list[bytes] = []  # the goal ids, one per execution
        self.cancels = 0
        self._hold: list[Future] = []
        self.server = ActionServer(self.node, FollowJointTrajectory, CONTROLLER, execute_callback=self._execute,
                                   cancel_callback=self._on_cancel)

    def _on_cancel(self, _handle) -> CancelResponse:
        self.cancels += 1
        return CancelResponse.ACCEPT

    async def _execute(self, handle) -> FollowJointTrajectory.Result:
        self.executed.append(bytes(handle.goal_id.uuid))
        hold = Future()
        self._hold.append(hold)
        await hold
        handle.succeed()
        return FollowJointTrajectory.Result()

    def release(self) -> None:
        for fut in self._hold:
            if not fut.done():
                fut.set_result(None)

    def close(self) -> None:
        self.server.destroy()
        self.node.destroy_node()


def goal() -> Goal:
    points = [JointTrajectoryPoint(positions=[0.1 * k, -0.05 * k], time_from_start=sec_to_duration(0.1 * k))
              for k in range(11)]
    return Goal(trajectory=JointTrajectory(joint_names=NAMES, points=points))


def new_id() -> UUID:
    return UUID(uuid=list(uuid.uuid4().bytes))


class Chain:
    """Client node (its own executor) -> learner proxy -> shaper proxy (its side node's thread) -> controller."""

    def __init__(self, ctx) -> None:
        from shaper_nodes.nodes.learner import LearnerNode
        from shaper_nodes.nodes.shaper import ShaperNode

        self.controller = Controller(ctx)
        self.shaper = ShaperNode(context=ctx, parameter_overrides=[
            Parameter("joint_names", value=NAMES), Parameter("command_rate", value=100.0),
            Parameter("shaper.family", value="zv"), Parameter("shaper.frequency_hz", value=5.0),
            Parameter("action.controller", value=CONTROLLER), Parameter("action.server_timeout", value=30.0)])
        self.learner = LearnerNode(context=ctx, parameter_overrides=[
            Parameter("mode", value="speed_moves"), Parameter("speed.scheduler", value=""),
            Parameter("speed.match_timeout", value=0.0), Parameter("speed.action_timeout", value=60.0),
            Parameter("speed.drift_status", value="")])
        self.servers = SingleThreadedExecutor(context=ctx)
        for n in (self.controller.node, self.shaper, self.learner):
            self.servers.add_node(n)
        self.probe = rclpy.create_node("resend_probe", context=ctx)
        self.clients = SingleThreadedExecutor(context=ctx)
        self.clients.add_node(self.probe)

    def spin_until(self, done, what: str, servers: bool = True, timeout: float = WAIT) -> None:
        """Spin the client (and, with ``servers``, the learner and the controller) until ``done()``."""
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out after {timeout:g} s waiting for {what}"
            self.clients.spin_once(timeout_sec=0.01)
            if servers:
                self.servers.spin_once(timeout_sec=0.01)

    def ready(self, client) -> None:
        self.spin_until(lambda: client.server_is_ready() and self.learner.mode.proxy._client.server_is_ready()
                        and self.shaper._action is not None and self.shaper._action._client.server_is_ready(),
                        "every action server of the chain seen by its client")

    def close(self) -> None:
        self.controller.release()
        self.servers.shutdown()
        self.clients.shutdown()
        self.probe.destroy_node()
        self.learner.destroy_node()
        self.shaper.destroy_node()
        self.controller.close()


@pytest.fixture
def chain(ros_context):
    c = Chain(ros_context)
    yield c
    c.close()


def finish(chain: Chain, handle) -> None:
    """Release the controller's goals; the handle's goal ends SUCCEEDED."""
    result = handle.get_result_async()
    chain.controller.release()
    chain.spin_until(result.done, "the goal's result")
    assert result.result().status == GoalStatus.STATUS_SUCCEEDED


def test_a_request_sent_again_before_the_proxy_answered_runs_once(chain):
    client = ResilientActionClient(chain.probe, FollowJointTrajectory, LEARNER, resend_period=0.2)
    chain.ready(client)
    sent = client.send_goal_async(goal())
    # the learner busy (not spun) beyond the resend period: the client sends the request again, same goal id
    chain.spin_until(lambda: client.resent >= 1, "the client's resend", servers=False)
    chain.spin_until(sent.done, "the answer to the goal")
    handle = sent.result()
    assert handle.accepted
    chain.spin_until(lambda: len(chain.controller.executed) == 1, "the goal at the controller")
    chain.spin_until(lambda: client.pending == 0, "every answer of the two requests taken")
    finish(chain, handle)
    assert len(chain.controller.executed) == 1 and chain.controller.cancels == 0
    client.destroy()


def test_a_goal_id_sent_again_while_it_runs_or_by_two_clients_runs_once(chain):
    first, second = (ActionClient(chain.probe, FollowJointTrajectory, LEARNER) for _ in range(2))
    chain.ready(first)
    chain.spin_until(second.server_is_ready, "the learner's action server, seen by the second client")

    # two requests of one id queued before the proxy takes either
    gid = new_id()
    a, b = first.send_goal_async(goal(), goal_uuid=gid), second.send_goal_async(goal(), goal_uuid=gid)
    chain.spin_until(lambda: a.done() and b.done(), "both answers")
    assert [a.result().accepted, b.result().accepted] == [True, False]
    chain.spin_until(lambda: len(chain.controller.executed) == 1, "the goal at the controller")

    # the same id again while the goal runs at the controller: refused, the running goal not preempted
    again = second.send_goal_async(goal(), goal_uuid=gid)
    chain.spin_until(again.done, "the answer to the id sent again")
    assert not again.result().accepted
    finish(chain, a.result())
    assert len(chain.controller.executed) == 1 and chain.controller.cancels == 0
    assert chain.learner.mode.proxy._live == {} and chain.learner.mode.proxy._shaped == {}
    first.destroy()
    second.destroy()


def test_a_refused_resend_whose_goal_status_comes_after_is_the_same_goal(ros_context):
    """The client's side of a resend whose first answer was lost: the resend is refused as a duplicate id before
    the server's status naming the goal has arrived; once the status comes, the goal goes on as accepted (the
    refusal is final only if no status names the goal within one more resend period). In-process, the client's
    own steps driven by hand."""
    from shaper_nodes.ros.action_client import _GoalSend

    node = rclpy.create_node("resend_unit", context=ros_context)
    client = ResilientActionClient(node, FollowJointTrajectory, "/nobody/follow_joint_trajectory", resend_period=60.0)
    try:
        gid = new_id()
        outer = Future()
        now = time.monotonic()
        send = _GoalSend(goal(), None, gid, outer, now, attempts=2, first_at=now)
        refused = FollowJointTrajectory.Impl.SendGoalService.Response(accepted=False)
        send.rejected, send.rejected_at = refused, now
        client._sends[bytes(gid.uuid)] = send
        client._check()
        assert not outer.done()  # within the period, no status yet: not final
        client._note_statuses([GoalStatus(goal_info=GoalInfo(goal_id=gid), status=GoalStatus.STATUS_EXECUTING)])
        client._check()
        assert outer.done() and outer.result().accepted and client.recovered == 1
        assert client.pending == 0
    finally:
        client.destroy()
        node.destroy_node()
