"""A storm of service calls: every request is answered, none vanishes in the middleware's queue.

Before, the suite's services had rclpy's default KEEP_LAST 10: of 2000 ``~/shaper_at`` calls sent at
once, 20 were answered and the other callers waited for ever. The suite's services are now KEEP_ALL
(``ros/qos.py``, SERVICE_QOS); here four callers send 500 requests each at once to the scheduler's
``~/shaper_at`` (each client holding its burst: a client's depth is the caller's part) and every one
gets its answer, the right one for its pose. (With KEEP_LAST 1000 instead, none of 1500 was answered.)
"""

from __future__ import annotations

import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from shaper_msgs.srv import ShaperAt
from shaper_nodes.nodes.scheduler import SchedulerNode
from shaper_nodes.ros.qos import SERVICE_DEPTH

pytestmark = pytest.mark.integration
CALLERS, EACH = 4, 500


def scheduler(ctx) -> SchedulerNode:
    rule = {"membership": ["triangular"], "frequency_hz": [10.0], "damping_ratio": [0.05]}
    overrides = [Parameter(k, value=v) for k, v in {"premises": ["joint_1"], "rule_names": ["low", "high"],
                                                    "interpolation": "modes", "stale_timeout": 3600.0}.items()]
    for name, peak, hz in (("low", 0.0, 10.0), ("high", 1.0, 20.0)):
        overrides += [Parameter(f"rules.{name}.{k}", value=v) for k, v in rule.items()]
        overrides += [Parameter(f"rules.{name}.membership_params", value=[peak - 1.0, peak, peak + 1.0]),
                      Parameter(f"rules.{name}.frequency_hz", value=[hz])]
    return SchedulerNode(context=ctx, parameter_overrides=overrides)


def test_a_storm_of_shaper_at_calls_is_answered_every_one(ros_context):
    assert CALLERS * EACH > SERVICE_DEPTH  # more than one service's queue holds: they drain as they are served
    node = scheduler(ros_context)
    probe = Node("storm", context=ros_context)
    clients = [probe.create_client(ShaperAt, "/scheduler/shaper_at", qos_profile=QoSProfile(depth=EACH))
               for _ in range(CALLERS)]
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(probe)

    def spin_until(cond, what, timeout=120.0):
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            ex.spin_once(timeout_sec=0.02)

    try:
        spin_until(lambda: all(c.service_is_ready() for c in clients), "the service")
        poses = [((k % 11) / 10.0) for k in range(EACH)]
        futures = [(x, c.call_async(ShaperAt.Request(pose=JointState(name=["joint_1"], position=[x]))))
                   for c in clients for x in poses]
        spin_until(lambda: all(f.done() for _, f in futures),
                   f"every answer ({sum(f.done() for _, f in futures)} of {len(futures)} so far)")
        answers = [(x, f.result()) for x, f in futures]
        assert all(r.success for _, r in answers), next(r.message for _, r in answers if not r.success)
        # each answer is its own pose's: the schedule's shaper at x, as the scheduler's core gives it
        want = {x: node.core.at([x])[1] for x in set(poses)}
        assert len({tuple(s.times) for s in want.values()}) > 3  # the poses ask for different shapers
        for x, r in answers:
            assert list(r.shaper.times) == pytest.approx(list(want[x].times), rel=1e-12)
    finally:
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()
