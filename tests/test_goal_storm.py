"""A storm of FollowJointTrajectory goals through the shaper's proxy: every goal answered, resends bounded.

Before, 100 goals/s for 3 s made the proxy resend goal requests to the controller 2826 times (one goal
at "attempt 34", 17 s of resending against a 2 s ``action.server_timeout``) and 93 of 299 goals got no
response at all (the proxy's goal service kept rclpy's KEEP_LAST 10). Now the action servers hold every
request (``ros/qos.py`` ACTION_QOS), the proxy holds at most ``MAX_LIVE`` goals and rejects one more at
once with the reason, and it resends a goal request to the controller only within its server timeout
(``ResilientActionClient(give_up_after=...)``). The sim arm (real time) plays the controller.
"""

from __future__ import annotations

import time

import pytest
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.nodes.trajectory_action import MAX_LIVE
from shaper_nodes.ros.conversions import sec_to_duration
from shaper_nodes.ros.qos import ACTION_CLIENT_QOS
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME

pytestmark = pytest.mark.integration
GOALS, RATE_HZ = 300, 100.0
TIMEOUT = 300.0


def test_a_storm_of_goals_is_answered_goal_by_goal_and_resends_stay_bounded(start_node, ros_context):
    start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME.tolist(), "rate": 500.0})
    shaper = start_node("shaper_nodes", "shaper_node", {"joint_names": list(JOINT_NAMES), "command_rate": 500.0,
                                                        "shaper.family": "zv", "shaper.frequency_hz": 10.0})
    node = Node("storm", context=ros_context)
    client = ActionClient(node, FollowJointTrajectory, "/shaper/follow_joint_trajectory", **ACTION_CLIENT_QOS)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)

    def spin_until(cond, what) -> None:
        end = time.monotonic() + TIMEOUT
        while not cond():
            assert shaper.running(), shaper.log_path.read_text()[-3000:]
            # (what: a text, or a callable giving one when it is needed: which goals are still unanswered)
            assert time.monotonic() < end, f"timed out waiting for {what() if callable(what) else what}" + (
                f"; the shaper's log ends:\n{shaper.log_path.read_text()[-3000:]}")
            ex.spin_once(timeout_sec=0.01)

    try:
        spin_until(client.server_is_ready, "the shaper's action server")
        sends = []
        for k in range(GOALS):
            goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES), points=[
                JointTrajectoryPoint(positions=(HOME + 0.001 * (k % 5)).tolist(), velocities=[0.0] * 6,
                                     time_from_start=sec_to_duration(0.5))]))
            sends.append(client.send_goal_async(goal))
            end = time.monotonic() + 1.0 / RATE_HZ
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=max(0.0, end - time.monotonic()))
        spin_until(lambda: all(f.done() for f in sends),  # (session 16's suite: one unanswered once)
                   lambda: f"an answer to every goal ({sum(f.done() for f in sends)} of {GOALS}; unanswered: goals"
                           f" {[k for k, f in enumerate(sends) if not f.done()]} of those sent 1/{RATE_HZ:g} s apart)")
        handles = [f.result() for f in sends]
        accepted = [h for h in handles if h.accepted]
        results = [h.get_result_async() for h in accepted]
        spin_until(lambda: all(r.done() for r in results),
                   lambda: f"the result of every accepted goal ({sum(r.done() for r in results)} of {len(results)})")
        log = shaper.log_path.read_text()
        resends = log.count("sending it again with the same goal id")
        print(f"{GOALS} goals at {RATE_HZ:g}/s: {len(accepted)} accepted (every one with a result),"
              f" {GOALS - len(accepted)} rejected at once, {resends} goal requests resent to the controller")
        assert len(accepted) >= 1
        if len(accepted) < GOALS:  # the reason, in the log (throttled: once per error_throttle)
            assert f"(at most {MAX_LIVE}); this one is rejected at once" in log
        # each goal request is resent at most give_up_after / resend_period = 4 times, and at most MAX_LIVE
        # goals are held: the resends are bounded whatever the storm
        assert resends <= 4 * (len(accepted) + MAX_LIVE)
    finally:
        ex.shutdown()
        client.destroy()
        node.destroy_node()
