"""A shaper node that takes set_shaper requests but never answers: no client of it hangs.

The identifier (in test_identifier_node.py), the learner in both modes and the scheduler each run
in-process with a peer that plays the shaper node and swallows every request (``SilentShaper`` in
conftest.py: a lost reply, or a stuck node). Each must report the timeout (its log and
``/diagnostics``), keep serving its own interfaces, and retry where that is its policy.
"""

from __future__ import annotations

import time

import pytest
import rclpy
from conftest import Diagnosed, SilentShaper
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool

from shaper_msgs.msg import ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper
from shaper_nodes.nodes.learner import LearnerNode
from shaper_nodes.nodes.scheduler import SchedulerNode

pytestmark = pytest.mark.integration
TIMEOUT = 0.5  # s, the nodes' service_timeout
WAIT = 60.0    # s, the longest this test waits for anything (a loaded machine)


class Graph:
    """The node under test, the silent shaper and a probe in one executor."""

    def __init__(self, ctx, node, feedforward: bool = False) -> None:
        self.node = node
        self.peer = SilentShaper(ctx, feedforward=feedforward)
        self.probe = rclpy.create_node("probe", context=ctx)
        self.diag = Diagnosed(self.probe)
        self.ex = SingleThreadedExecutor(context=ctx)
        for n in (self.node, self.peer, self.probe):
            self.ex.add_node(n)

    def spin_until(self, cond, what: str, timeout: float = WAIT) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def call(self, srv_type, name: str, request):
        cli = self.probe.create_client(srv_type, name)
        self.spin_until(cli.service_is_ready, name)
        future = cli.call_async(request)
        self.spin_until(future.done, f"the answer of {name}")
        return future.result()

    def timeout_reported(self, node_name: str):
        self.spin_until(lambda: self.diag.find(node_name, "did not answer within"), f"{node_name}'s timeout report")
        return self.diag.find(node_name, "did not answer within")

    def close(self) -> None:
        self.ex.shutdown()
        for n in (self.node, self.peer, self.probe):
            n.destroy_node()


@pytest.fixture
def graphs():
    made: list[Graph] = []
    yield lambda *a, **k: made.append(Graph(*a, **k)) or made[-1]
    for g in made:
        g.close()


def params(**values) -> list[Parameter]:
    return [Parameter(k.replace("__", "."), value=v) for k, v in values.items()]


def test_list_learner_reports_the_timeout_retries_and_keeps_serving(ros_context, graphs):
    node = LearnerNode(context=ros_context, parameter_overrides=params(service_timeout=TIMEOUT))
    g = graphs(ros_context, node)
    g.spin_until(lambda: g.peer.requests, "the learner's start-up request (the identity shaper)")
    assert g.peer.requests[0].shaper.family == "none" and g.peer.requests[0].shaper.source == "learner"
    status = g.timeout_reported("learner")
    assert "/shaper/set_shaper" in status.message
    g.spin_until(lambda: len(g.peer.requests) >= 2, "the start-up request sent again")
    resp = g.call(SetBool, "/learner/hold", SetBool.Request(data=False))  # it still serves
    assert resp.success and resp.message == "learning resumed"


def test_mrilc_learner_reports_the_timeout_and_still_installs_its_profile(ros_context, graphs):
    node = LearnerNode(context=ros_context, parameter_overrides=params(
        mode="mrilc", service_timeout=TIMEOUT, joint_names=["joint_1"], mrilc__injection_target="/sim_plant"))
    g = graphs(ros_context, node, feedforward=True)
    g.spin_until(lambda: g.peer.requests, "the ZVD shaper designed on the reference model")
    assert g.peer.requests[0].shaper.family == "custom" and len(g.peer.requests[0].shaper.amplitudes) == 3
    g.timeout_reported("learner")
    g.spin_until(lambda: g.peer.feedforward, "the profile installed at the injection point")
    g.spin_until(lambda: len(g.peer.requests) >= 2, "the shaper sent again")
    resp = g.call(SetBool, "/learner/hold", SetBool.Request(data=True))
    assert resp.success and "holding" in resp.message


def test_scheduler_reports_the_timeout_sends_again_and_answers_the_learner(ros_context, graphs):
    rule = {"membership": ["triangular"], "frequency_hz": [10.0], "damping_ratio": [0.05]}
    overrides = params(premises=["joint_1"], rule_names=["low", "high"], interpolation="modes", period=0.02,
                       min_interval=0.0, stale_timeout=3600.0, error_throttle=0.0, service_timeout=TIMEOUT)
    for name, peak, hz in (("low", 0.0, 10.0), ("high", 1.0, 20.0)):
        overrides += params(**{f"rules__{name}__{k}": v for k, v in rule.items()})
        overrides += params(**{f"rules__{name}__membership_params": [peak - 1.0, peak, peak + 1.0],
                               f"rules__{name}__frequency_hz": [hz]})
    node = SchedulerNode(context=ros_context, parameter_overrides=overrides)
    g = graphs(ros_context, node)
    modes: list[ModeEstimate] = []
    g.probe.create_subscription(ModeEstimate, "/scheduler/mode_estimate", modes.append, 10)
    joints = g.probe.create_publisher(JointState, "/joint_states", 10)

    def pose() -> bool:
        joints.publish(JointState(name=["joint_1"], position=[0.5]))
        return True

    g.spin_until(lambda: pose() and g.peer.requests, "the scheduled shaper")
    assert g.peer.requests[0].shaper.source == "scheduler"
    g.timeout_reported("scheduler")
    g.spin_until(lambda: pose() and len(g.peer.requests) >= 2, "the scheduled shaper sent again")
    # the learner's side: a forwarded request that is never answered is answered to the learner
    learned = ShaperMsg(family="custom", amplitudes=[0.5, 0.5], times=[0.0, 0.034], source="learner")
    resp = g.call(SetShaper, "/scheduler/set_shaper", SetShaper.Request(shaper=learned))
    assert not resp.success and "did not answer within" in resp.message
    seen = len(modes)
    g.spin_until(lambda: pose() and len(modes) > seen + 3, "the schedule still evaluated")
    assert modes[-1].modes[0].frequency_hz == pytest.approx(15.0)  # between the rules' 10 and 20 Hz
