"""Huge whole trajectories against the installed shaper node, and its trajectory worker after ``kill -9``.

Before, a 10^6-point FollowJointTrajectory goal took 57 s to reject and left the shaper at 242 MiB (688 MiB at
the peak); a goal of 10^5 points was converted point by point before its span was found too long. Now the size
is checked first, from the number of points and joints and two points' times (``WholeShaping.check_size``):
a goal too large is refused with the sizes and the limit before any work on its points. What is left of a huge
goal's cost is rclpy's conversion of the request into Python objects (docs/guide/shaper_node.md, "Goal size").

The trajectory topic's worker process gets ``die_with_parent`` (core/lifetime.py) as its pool's initializer:
a shaper killed with ``kill -9`` leaves no worker behind.
"""

from __future__ import annotations

import os
import signal
import time

import pytest
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.ros.conversions import sec_to_duration
from shaper_nodes.ros.qos import ACTION_CLIENT_QOS
from shaper_nodes.ros.whole_trajectory import MAX_TRAJECTORY_VALUES

pytestmark = pytest.mark.integration
JOINTS = [f"j{k}" for k in range(6)]
TIMEOUT = 300.0  # s, generous: a loaded 2-core machine converts a 10^5-point message in tens of seconds
PARAMS = {"joint_names": JOINTS, "command_rate": 500.0, "shaper.family": "zv", "shaper.frequency_hz": 10.0,
          "error_throttle": 0.0}


class Peer:
    """An in-process node with the shaper's action client, spun by the test."""

    def __init__(self, ctx, shaper) -> None:
        self.shaper = shaper
        self.node = Node("big_goal_peer", context=ctx)
        self.client = ActionClient(self.node, FollowJointTrajectory, "/shaper/follow_joint_trajectory",
                                   **ACTION_CLIENT_QOS)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)

    def spin_until(self, cond, what: str) -> None:
        end = time.monotonic() + TIMEOUT
        while not cond():
            assert self.shaper.running(), self.shaper.log_path.read_text()[-3000:]
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def refused(self, goal: FollowJointTrajectory.Goal, words: str) -> str:
        """Send ``goal``; it must be rejected and the shaper's log must give ``words`` as the reason."""
        self.spin_until(self.client.server_is_ready, "the shaper's action server")
        sent = self.client.send_goal_async(goal)
        self.spin_until(sent.done, "the answer to the goal")
        assert not sent.result().accepted
        self.spin_until(lambda: words in self.shaper.log_path.read_text(), f"the reason in the log: {words!r}")
        return self.shaper.log_path.read_text()

    def close(self) -> None:
        self.ex.shutdown()
        self.client.destroy()
        self.node.destroy_node()


def point(t: float, values: int = 6) -> JointTrajectoryPoint:
    return JointTrajectoryPoint(positions=[0.0] * values, time_from_start=sec_to_duration(t))


def test_a_huge_goal_is_refused_by_its_size_before_any_work_on_its_points(start_node, ros_context):
    shaper = start_node("shaper_nodes", "shaper_node", PARAMS)
    peer = Peer(ros_context, shaper)
    try:
        # 20,000 points over 20 s: the span gives 10,000 samples at 500 Hz, above limits.max_trajectory_samples
        # (5000). Every point between the first and the last is malformed (2 positions for 6 joints): the
        # refusal names the span, so no point was read but the first and the last.
        bad = point(0.5, values=2)
        points = [point(0.0), *([bad] * 19_998), point(20.0)]
        log = peer.refused(FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=JOINTS, points=points)),
                           "the trajectory spans 20 s")
        assert "exceed the limit of 5000" in log and "expected 6" not in log
        # points x joints above the stated limit: refused with both sizes and the limits
        names = [f"n{k}" for k in range(100)]
        many = MAX_TRAJECTORY_VALUES // len(names) + 1
        peer.refused(FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=names,
                                                                           points=[JointTrajectoryPoint()] * many)),
                     f"{many} points x 100 joints exceed the limits of 100000 points and {MAX_TRAJECTORY_VALUES}"
                     " values (points x joints)")
        # a tolerance list longer than the joints: refused by its length
        goal = FollowJointTrajectory.Goal(
            trajectory=JointTrajectory(joint_names=JOINTS, points=[point(0.0), point(1.0)]),
            path_tolerance=[JointTolerance(name=JOINTS[0], position=0.1)] * 7)
        peer.refused(goal, "path_tolerance has 7 entries, more than the trajectory's 6 joints")
        assert shaper.running()
    finally:
        peer.close()


def _children(pid: int) -> dict[int, str]:
    """The live processes whose parent is ``pid``, with their command lines."""
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out[int(entry)] = cmd
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie (ended, not yet reaped) counts as gone
    except OSError:
        return False


@pytest.mark.skipif(not os.path.exists("/proc"), reason="reads processes from /proc (Linux)")
def test_the_trajectory_worker_ends_when_the_shaper_is_killed(start_node, ros_context):
    shaper = start_node("shaper_nodes", "shaper_node", PARAMS)
    node = Node("worker_peer", context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    shaped: list[JointTrajectory] = []
    node.create_subscription(JointTrajectory, "/joint_trajectory_controller/joint_trajectory", shaped.append, 10)
    pub = node.create_publisher(JointTrajectory, "/shaper/joint_trajectory", 10)
    workers: list[int] = []
    try:
        end = time.monotonic() + TIMEOUT
        # the worker exists once a trajectory sent on the topic has come back shaped
        while not shaped:
            assert shaper.running() and time.monotonic() < end, shaper.log_path.read_text()[-3000:]
            if pub.get_subscription_count():
                pub.publish(JointTrajectory(joint_names=JOINTS, points=[point(0.0), point(1.0)]))
            ex.spin_once(timeout_sec=0.5)
        pid = shaper.proc.pid
        workers = [p for p, cmd in _children(pid).items() if "spawn_main" in cmd]
        assert workers, _children(pid)
        os.kill(pid, signal.SIGKILL)
        shaper.proc.wait()
        deadline = time.monotonic() + 60.0  # generous: the kernel signals at once, a loaded machine runs it late
        while any(map(_alive, workers)):
            assert time.monotonic() < deadline, f"worker {workers} outlived the killed shaper"
            time.sleep(0.05)
    finally:
        for p in workers:
            if _alive(p):
                os.kill(p, signal.SIGKILL)
        ex.shutdown()
        node.destroy_node()
