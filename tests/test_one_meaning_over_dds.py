"""One meaning per parameter and per path, over DDS (issue 32, finding 5): the shaper node's parameter
services and ``~/set_shaper`` as ``ros2 param set`` and a client call them, and the graph as ``ros2 node
info`` reads it. See docs/guide/shaper_node.md, "Who sets the shaper".
"""

from __future__ import annotations

import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.action import get_action_server_names_and_types_by_node
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper
from shaper_nodes.nodes.shaper import ShaperNode
from shaper_nodes.ros.conversions import mode_msg, msg_hz
from shaper_nodes.ros.qos import LATCHED

pytestmark = pytest.mark.integration
TIMEOUT = 60.0


def double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value))


def doubles(name: str, values: list[float]) -> ParameterMsg:
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY,
                                                        double_array_value=values))


class Rig:
    """A shaper node at 500 Hz and a probe that calls its services and reads /diagnostics and ~/active_shaper."""

    def __init__(self, ctx, **params) -> None:
        overrides = {"joint_names": ["a", "b"], "command_rate": 500.0, "shaper.family": "zv", **params}
        self.node = ShaperNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node("probe", context=ctx)
        self.statuses: list[DiagnosticStatus] = []
        self.active: list[ShaperMsg] = []
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.statuses.extend(m.status), 100)
        self.probe.create_subscription(ShaperMsg, "/shaper/active_shaper", self.active.append, LATCHED)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.probe)
        self.spin_until(lambda: self.active, "the active shaper")

    def spin_until(self, cond, what: str) -> None:
        end = time.monotonic() + TIMEOUT
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.05)

    def call(self, srv_type, name: str, request):
        cli = self.probe.create_client(srv_type, name)
        self.spin_until(cli.service_is_ready, name)
        fut = cli.call_async(request)
        self.spin_until(fut.done, f"the answer of {name}")
        self.probe.destroy_client(cli)
        return fut.result()

    def set(self, *params: ParameterMsg):
        """`ros2 param set /shaper NAME VALUE` (one parameter each), the results."""
        request = SetParameters.Request(parameters=list(params))
        return self.call(SetParameters, "/shaper/set_parameters", request).results

    def set_atomically(self, *params: ParameterMsg):
        return self.call(SetParametersAtomically, "/shaper/set_parameters_atomically",
                         SetParametersAtomically.Request(parameters=list(params))).result

    def set_shaper(self, family: str, hz: float, zeta: float = 0.05, source: str = "user", **extra):
        req = SetShaper.Request(shaper=ShaperMsg(family=family, design_modes=[mode_msg(hz, zeta)], source=source,
                                                 **extra))
        return self.call(SetShaper, "/shaper/set_shaper", req)

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()


@pytest.fixture
def rig(ros_context):
    r = Rig(ros_context, **{"shaper.frequencies_hz": [5.0, 8.0], "shaper.damping_ratios": [0.05, 0.02]})
    yield r
    r.close()


def active_hz(rig: Rig) -> list[float]:
    return [msg_hz(m) for m in rig.active[-1].design_modes]


def test_frequency_hz_while_frequencies_hz_is_set_is_refused_with_the_reason(rig):
    """The issue's case: `ros2 param set /shaper shaper.frequency_hz 9` said "Set parameter successful"
    while 9 Hz was not used."""
    revision = rig.active[-1].revision
    (result,) = rig.set(double("shaper.frequency_hz", 9.0))
    assert not result.successful
    assert result.reason.startswith("shaper.frequency_hz 9 cannot take effect: shaper.frequencies_hz is set")
    (result,) = rig.set(double("shaper.damping_ratio", 0.2))
    assert not result.successful and "shaper.damping_ratio 0.2 cannot take effect" in result.reason
    assert rig.node.get_parameter("shaper.frequency_hz").value == 10.0  # unchanged
    assert active_hz(rig) == [pytest.approx(5.0), pytest.approx(8.0)] and rig.active[-1].revision == revision
    # the same value again is no change (`ros2 param load` of a dump sends it)
    (same,) = rig.set(double("shaper.frequency_hz", 10.0))
    assert same.successful, same.reason


def test_frequency_hz_takes_effect_with_the_lists_emptied_in_the_same_request(rig):
    result = rig.set_atomically(double("shaper.frequency_hz", 9.0), doubles("shaper.frequencies_hz", []),
                                doubles("shaper.damping_ratios", []))
    assert result.successful, result.reason
    rig.spin_until(lambda: active_hz(rig) == [pytest.approx(9.0)], "the 9 Hz shaper")
    (now,) = rig.set(double("shaper.frequency_hz", 7.0))  # and now a single frequency takes effect alone
    assert now.successful, now.reason
    rig.spin_until(lambda: active_hz(rig) == [pytest.approx(7.0)], "the 7 Hz shaper")


@pytest.mark.parametrize(("hz", "words"), [
    (159.0, "159 Hz is too high for command_rate 500 Hz (must be below rate / 4 = 125 Hz)"),
    (0.009, "0.009 Hz is outside [0.01, 1000] Hz"),
])
def test_set_shaper_refuses_what_the_parameters_refuse_with_the_same_words(rig, hz, words):
    """The issue's case: `set_shaper` accepted 159 Hz at 500 Hz, which the parameters refuse."""
    revision = rig.active[-1].revision
    resp = rig.set_shaper("zv", hz, 0.0)
    assert not resp.success and resp.message == f"design mode {words}", resp.message
    (param,) = rig.set(doubles("shaper.frequencies_hz", [hz]))  # the parameters: one list alone is refused ...
    both = rig.set_atomically(doubles("shaper.frequencies_hz", [hz]), doubles("shaper.damping_ratios", [0.0]))
    assert not param.successful and not both.successful
    assert both.reason == f"shaper.frequencies_hz {words}", both.reason  # ... and a whole one for the same reason
    assert rig.active[-1].revision == revision and resp.active.revision == revision


def test_set_shaper_refuses_an_si_insensitivity_the_parameter_range_refuses(rig):
    resp = rig.set_shaper("si", 10.0, 0.05, insensitivity=0.005)
    assert not resp.success and "insensitivity 0.005 is outside [0.01, 1.5]" in resp.message, resp.message
    (param,) = rig.set(double("shaper.insensitivity", 0.005))
    assert not param.successful and "0.01" in param.reason  # the descriptor's range, the same bounds


def test_a_change_that_displaces_another_sources_shaper_is_reported(rig):
    """The issue's case: a parameter change replaced the scheduler's shaper without a word."""
    resp = rig.set_shaper("zv", 6.0, source="scheduler")
    assert resp.success and "replaces the shaper set by parameters" in resp.message, resp.message
    scheduled = resp.active.revision
    # a user's set_shaper: the answer says whose shaper it replaced
    resp = rig.set_shaper("zvd", 6.5, source="user")
    assert resp.success and resp.message.endswith(f"replaces the shaper set by scheduler (revision {scheduled})")
    # the parameters: their answer cannot carry a note (rclpy drops a successful result's reason), so the
    # log and /diagnostics say it
    result = rig.set_atomically(doubles("shaper.frequencies_hz", [4.0]), doubles("shaper.damping_ratios", [0.05]))
    assert result.successful, result.reason

    def displaced() -> list[DiagnosticStatus]:
        return [s for s in rig.statuses if s.name == "shaper: source" and s.message.startswith("parameters ")]

    rig.spin_until(displaced, "a /diagnostics status on the displaced shaper")
    (status,) = displaced()
    assert status.level == DiagnosticStatus.WARN
    assert f"parameters replaces the shaper set by user (revision {scheduled + 1})" in status.message
    values = {kv.key: kv.value for kv in status.values}
    assert values["displaced"] == "user" and values["by"] == "parameters"
    assert rig.active[-1].source == "parameters" and active_hz(rig) == [pytest.approx(4.0)]


def test_ros2_node_info_of_the_shaper_and_its_side_nodes_show_every_input(ros_context):
    """`ros2 node info /shaper` lists this node's own entities; the streamed inputs and the whole-trajectory
    inputs sit on /shaper_stream and /shaper_trajectories (measured for the stream's sake:
    docs/results/benchmarks.md). Together the three show every input a user wires, and the shaper names
    them on its start-up log line and its /diagnostics summary."""
    rig = Rig(ros_context)
    try:
        graph = rig.probe

        def subscriptions(name: str) -> set[str]:
            return {t for t, _ in graph.get_subscriber_names_and_types_by_node(name, "/")}

        def ready() -> bool:
            names = set(graph.get_node_names())
            return {"shaper", "shaper_stream", "shaper_trajectories"} <= names and \
                "/shaper/commands" in subscriptions("shaper_stream") and \
                get_action_server_names_and_types_by_node(graph, "shaper_trajectories", "/")

        rig.spin_until(ready, "the shaper's three nodes in the graph")
        assert "/shaper/commands" not in subscriptions("shaper")  # what `ros2 node info /shaper` alone shows
        together = subscriptions("shaper") | subscriptions("shaper_stream") | subscriptions("shaper_trajectories")
        assert {"/shaper/commands", "/shaper/joint_trajectory_stream", "/shaper/joint_trajectory"} <= together
        actions = [n for n, _ in get_action_server_names_and_types_by_node(graph, "shaper_trajectories", "/")]
        assert actions == ["/shaper/follow_joint_trajectory"]
        services = {n for n, _ in graph.get_service_names_and_types_by_node("shaper_trajectories", "/")}
        assert "/shaper/shape_trajectory" in services
        own = {n for n, _ in graph.get_service_names_and_types_by_node("shaper", "/")}
        assert {"/shaper/set_shaper", "/shaper/get_shaper"} <= own

        def summary() -> list[DiagnosticStatus]:
            return [s for s in rig.statuses if s.name == "shaper: shaper"]

        rig.spin_until(summary, "the shaper's summary on /diagnostics")
        values = {kv.key: kv.value for kv in summary()[-1].values}
        assert values["inputs on /shaper_stream"] == "array_in, stream_in"
        assert values["inputs on /shaper_trajectories"] == "trajectory_in, ~/shape_trajectory, action.server_name"
    finally:
        rig.close()


def test_the_scheduler_takes_its_rules_in_hz_and_refuses_the_old_rad_s_key_by_its_new_name(ros_context):
    """rules.<name>.frequency_hz is Hz (the mode estimate says 15 Hz between rules of 10 and 20 Hz); a
    parameter file of before issue 32 (rules.<name>.natural_frequency, rad/s) is refused with the rename."""
    from shaper_nodes.nodes.scheduler import SchedulerNode

    def overrides(key: str) -> list[Parameter]:
        out = [Parameter(k, value=v) for k, v in {"premises": ["joint_1"], "rule_names": ["low", "high"],
                                                  "interpolation": "modes"}.items()]
        for name, peak, f in (("low", 0.0, 10.0), ("high", 1.0, 20.0)):
            out += [Parameter(f"rules.{name}.membership", value=["triangular"]),
                    Parameter(f"rules.{name}.membership_params", value=[peak - 1.0, peak, peak + 1.0]),
                    Parameter(f"rules.{name}.{key}", value=[f]), Parameter(f"rules.{name}.damping_ratio", value=[0.05])]
        return out

    node = SchedulerNode(context=ros_context, parameter_overrides=overrides("frequency_hz"))
    try:
        _, shaper = node.core.at([0.5])
        assert [m.hz for m in shaper.modes] == pytest.approx([15.0])
    finally:
        node.destroy_node()
    renamed = r"rules\.low\.natural_frequency \(rad/s\) was renamed rules\.low\.frequency_hz"
    with pytest.raises(ValueError, match=renamed):
        SchedulerNode(context=ros_context, parameter_overrides=overrides("natural_frequency"))
