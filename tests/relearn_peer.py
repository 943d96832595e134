"""The test's side of the per-move learners' tests that drive a learner without the arm: one real node named
``identifier`` (tests/test_learning_speed_relearn.py, test_learning_mrilc_relearn.py, test_learning_list_kill.py).

:class:`Peer` publishes the drift watch's status on ``/diagnostics`` through the identifier's own reporter (statuses
named ``identifier: ...``, as nodes/identifier.py does), the cycle events and (``imu``) the tool accelerometer,
serves the controller's FollowJointTrajectory action (recording each goal it receives; ``hold``: a goal runs until
the test releases it), sends goals to the learner's proxy, and keeps the learner's reports, log lines and
statuses. :meth:`Peer.kill_during_move` kills the learner (its own process) with SIGKILL while a goal of a move runs
through its proxy at the controller and starts it again (the speed, LIST payback and MRILC per-move learners' tests:
tests/test_learning_speed_relearn.py, test_learning_kill_during_move.py).
"""

from __future__ import annotations

import json
import pathlib
import time
from collections.abc import Callable, Sequence
from typing import Any

from action_msgs.msg import GoalStatus
from conftest import ROSOUT
from control_msgs.action import FollowJointTrajectory
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Log
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import Imu
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_nodes.nodes.learner_drift import level_of
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.diagnostics import Diagnostics
from shaper_nodes.ros.lockstep_reader import STREAM_QOS

LEARNER_PROXY = "/learner/follow_joint_trajectory"
WAIT = 120.0  # s of wall time for a state to come (two busy cores)
#: s without an answer after which a restarted learner is asked for a goal's result again: the graph shows its server
#: before both sides of the service have matched (ros/action_client.py), and a request written before its reader
#: matched this client's writer, or an answer written before its writer matched this client's reader, is lost
ASK_AGAIN = 5.0


class Peer:
    """The test's side (module docstring).

    Parameters
    ----------
    ctx : rclpy Context
        The test's context.
    controller : str
        The FollowJointTrajectory action the peer serves as the controller.
    ex : SingleThreadedExecutor, optional
        The executor to spin in (an in-process learner's too); default one of its own, shut down by
        :meth:`destroy`.
    imu : bool
        Publish the accelerometer on ``/tip_imu`` (RELIABLE, deep: the learner's ``topics.imu_reliable``).
    proxy : str
        The FollowJointTrajectory action the peer sends its goals to: the learner's (default), or the shaper node's
        when the learner is not in the goals' path (LIST per move without the payback rule).
    """

    def __init__(self, ctx, controller: str, ex: SingleThreadedExecutor | None = None, imu: bool = False,
                 proxy: str = LEARNER_PROXY) -> None:
        self._own_ex = ex is None
        self.ex = SingleThreadedExecutor(context=ctx) if ex is None else ex
        self.node = Node("identifier", context=ctx)  # statuses named "identifier: ..." as the identifier's
        self.identifier = Diagnostics(self.node)  # one publisher: its statuses arrive in order
        self.events = self.node.create_publisher(CycleEvent, "/cycle_events", 100)
        self.imu = self.node.create_publisher(Imu, "/tip_imu", STREAM_QOS) if imu else None
        self.reports: list[CycleReport] = []
        self.logs: list[str] = []
        self.statuses: list[DiagnosticStatus] = []
        self.goals: list[JointTrajectory] = []  # what reached the controller
        self.running = 0  # goals the controller is executing now
        self._held: Future | None = None  # while set, the controller's goals run until it is done
        self.node.create_subscription(CycleReport, "/learner/reports", self.reports.append, 100)
        # /rosout's own QoS (transient local, 10 s lifespan): a line the learner logged before this subscription
        # matched its publisher (a restarted learner's first lines) still arrives
        self.node.create_subscription(Log, "/rosout", lambda m: self.logs.append(m.msg) if m.name == "learner"
                                      else None, ROSOUT)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.statuses.extend(m.status), 100)
        self.server = ActionServer(self.node, FollowJointTrajectory, controller, execute_callback=self._execute)
        self.client = ActionClient(self.node, FollowJointTrajectory, proxy)
        self.through_learner = proxy == LEARNER_PROXY
        self.ex.add_node(self.node)

    def hold(self) -> None:
        """Keep the controller's next goals running (as a robot's moving) until :meth:`release`."""
        self._held = Future()

    def release(self) -> None:
        """End the goals held."""
        held, self._held = self._held, None
        if held is not None and not held.done():
            held.set_result(True)

    async def _execute(self, handle) -> FollowJointTrajectory.Result:
        self.goals.append(handle.request.trajectory)
        self.running += 1
        if self._held is not None:  # (the executor goes on with the other callbacks meanwhile)
            await self._held
        self.running -= 1
        handle.succeed()
        return FollowJointTrajectory.Result()

    def spin_until(self, done: Callable[[], bool], what: str, timeout: float = WAIT) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out after {timeout:g} s waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def event(self, kind: int, cycle: int, t: float, names: Sequence[str], start: Sequence[float],
              goal: Sequence[float], task: str = "per_move") -> None:
        """A cycle event stamped ``t`` s naming the move by its start and goal."""
        msg = CycleEvent(event=kind, cycle=cycle, task=task, joint_names=list(names),
                         start_positions=[float(x) for x in start], goal_positions=[float(x) for x in goal])
        msg.header.stamp = sec_to_time(t)
        self.events.publish(msg)

    def send(self, trajectory: JointTrajectory, what: str = "the goal"):
        """Send ``trajectory`` to the learner's proxy and wait until the learner accepted it and the controller
        received what the learner sent on; returns the goal's handle (its result not waited for)."""
        before = len(self.goals)
        sent = self.client.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory))
        self.spin_until(sent.done, f"the learner's answer to {what}")
        assert sent.result().accepted
        self.spin_until(lambda: len(self.goals) > before, f"{what} at the controller")
        assert len(self.goals) == before + 1
        return sent.result()

    def run_goal(self, trajectory: JointTrajectory, what: str = "the goal") -> JointTrajectory:
        """:meth:`send`, then the goal's result; what the controller received."""
        result = self.send(trajectory, what).get_result_async()
        self.spin_until(result.done, f"the result of {what}")
        return self.goals[-1]

    def report(self, cycle: int) -> dict[str, float]:
        """The learner's report of ``cycle`` (name -> value), waited for."""
        self.spin_until(lambda: any(r.cycle == cycle for r in self.reports), f"the learner's report of cycle {cycle}")
        got = next(r for r in self.reports if r.cycle == cycle)
        return dict(zip(got.metric_names, got.metric_values, strict=True))

    def status(self, name: str, level: int, words: str) -> DiagnosticStatus | None:
        """The first status seen of ``name`` at ``level`` whose message holds ``words``."""
        return next((s for s in self.statuses if s.name == name and level_of(s.level) == level
                     and words in s.message), None)

    def learner_subscriptions(self, inputs: Sequence[str]) -> set[bytes]:
        """The endpoint GIDs of the learner's subscriptions of ``inputs`` on the graph now."""
        return {bytes(i.endpoint_gid) for topic in inputs for i in self.node.get_subscriptions_info_by_topic(topic)
                if i.node_name == "learner"}

    def learner_up(self, inputs: Sequence[str], before: set[bytes]) -> bool:
        """The learner's subscriptions of each of ``inputs`` (new ones, not among ``before``) on the graph, and its
        action server (a restarted learner is up)."""
        return all(any(i.node_name == "learner" and bytes(i.endpoint_gid) not in before
                       for i in self.node.get_subscriptions_info_by_topic(topic))
                   for topic in inputs) and self.client.server_is_ready()

    def kill_during_move(self, learner, restart: Callable[[], Any], inputs: Sequence[str],
                         trajectory: JointTrajectory, measure: Callable[[JointTrajectory], object],
                         state: pathlib.Path, what: str = "the goal", gone: bool = False) -> JointTrajectory:
        """Kill the learner (``learner``: a NodeProcess) with SIGKILL during a move and start it again.

        The move's START must have been sent. ``trajectory`` goes to the proxy (the learner's, or the shaper node's when
        the learner is not in the goals' path: then the goal's result comes as usual, succeeded, and the checks of the
        client below are moot); once the controller received it and runs it (held), ``measure(sent)`` publishes part of
        the move's residual window, and the learner is killed. Shown on the way: the controller still runs the goal
        after the kill and finishes it (a robot's controller does not need the learner); the state file is byte for byte
        as when the goal reached the controller (nothing written since, nothing half written: saves are atomic) and
        parses; the client (the robot program) never gets the result it asked the killed server for (with ``gone``: it
        sees the server gone from its graph first, once DDS's lease of the killed process ran out: 20 s, Fast DDS's
        default); then ``restart()`` starts the learner on the same state file (and returns its NodeProcess) and, once
        its subscriptions of ``inputs`` and its action server are up, the goal's result asked again is answered
        ``STATUS_UNKNOWN`` (the restarted learner knows no goal of the killed one): a clear end, no hang. Returns what
        the controller received."""
        self.hold()
        handle = self.send(trajectory, what)
        result = handle.get_result_async()
        sent, saved = self.goals[-1], state.read_bytes()
        assert self.running == 1
        measure(sent)
        before = self.learner_subscriptions(inputs)
        assert learner.proc is not None
        learner.proc.kill()
        assert learner.proc.wait(timeout=30) == -9
        assert self.running == 1  # killed during the move
        self.release()
        self.spin_until(lambda: self.running == 0, f"the end of {what} at the controller")
        assert state.read_bytes() == saved and isinstance(json.loads(saved), dict)
        if not self.through_learner:  # the learner is not in the goal's path: the goal ends as usual
            self.spin_until(result.done, f"the result of {what}")
            assert result.result().status == GoalStatus.STATUS_SUCCEEDED, result.result()
            restart()
            self.spin_until(lambda: self.learner_up(inputs, before), "the restarted learner's subscriptions")
            return sent
        if gone:
            try:
                self.spin_until(lambda: not self.client.server_is_ready(), "the killed learner's action server gone"
                                " from the client's graph")
            except AssertionError as err:  # (seen twice under two hogs in session 13: say what the graph still has)
                raise AssertionError(f"{err}; on the graph still: {self.server_endpoints()}") from None
        assert not result.done(), result.result()  # the killed server's answer never comes
        restarted = restart()
        self.spin_until(lambda: self.learner_up(inputs, before), "the restarted learner's subscriptions and server")
        try:
            again = self.result_again(handle, f"the restarted learner's answer to the result of {what}")
        except AssertionError as err:  # say whether the learner still runs, and what it logged (CI, stop 49)
            raise AssertionError(f"{err}; the restarted learner running: {restarted.running()}; its log ends:\n"
                                 f"{restarted.log_path.read_text()[-3000:]}") from None
        assert again.status == GoalStatus.STATUS_UNKNOWN, again
        return sent

    def server_endpoints(self) -> list[str]:
        """The endpoints of the learner's action server this peer's graph holds now: its status publishers and
        send_goal request readers (node, GID)."""
        action = self.client._action_name.rstrip("/") + "/_action"
        return [f"{kind} {i.node_namespace.rstrip('/')}/{i.node_name} {bytes(i.endpoint_gid).hex()[:24]}"
                for kind, infos in (("status writer", self.node.get_publishers_info_by_topic(f"{action}/status")),
                                    ("goal request reader", self.node.get_subscriptions_info_by_topic(
                                        f"rq{action}/send_goalRequest", no_mangle=True)))
                for i in infos]

    def result_again(self, handle, what: str):
        """The result of ``handle``'s goal asked of its (restarted) server, again every :data:`ASK_AGAIN` s until it
        answers (up to :data:`WAIT` s): the answer."""
        deadline = time.monotonic() + WAIT
        while True:
            asked, ask_again = handle.get_result_async(), min(time.monotonic() + ASK_AGAIN, deadline)
            self.spin_until(lambda a=asked, t=ask_again: a.done() or time.monotonic() >= t, what)
            if asked.done():
                return asked.result()
            assert time.monotonic() < deadline, f"timed out after {WAIT:g} s waiting for {what}"

    def destroy(self) -> None:
        self.release()
        if self._own_ex:
            self.ex.shutdown()
        self.server.destroy()
        self.client.destroy()
        self.node.destroy_node()
