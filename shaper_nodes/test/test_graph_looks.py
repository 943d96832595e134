"""The graph watch's full and cheap looks, on a fake graph: the findings are the graph's whichever look ran.

A full look asks for every endpoint with its QoS; a cheap one only for the node names and the counts, and reuses
the last full look's findings while those hold (ros/graph_watch.py). The fake graph counts the queries, so the
tests see which look ran, and what it reported.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

from rclpy.qos import QoSProfile, ReliabilityPolicy

from shaper_nodes.ros.diagnostics import ERROR, OK, WARN
from shaper_nodes.ros.graph_watch import FULL_EVERY, GraphWatch

ARRAY = "std_msgs/msg/Float64MultiArray"
IN_T, OUT_T = "/shaper/commands", "/forward_position_controller/commands"
RELIABLE = QoSProfile(depth=10)
BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


def info(node: str, qos: QoSProfile = RELIABLE, typ: str = ARRAY) -> Any:
    """A TopicEndpointInfo as rclpy gives it (the fields the watch reads)."""
    return SimpleNamespace(node_name=node, node_namespace="/", topic_type=typ, qos_profile=qos)


@dataclass
class FakeGraph:
    """The looker node: the graph's queries over ``pubs`` and ``subs`` (topic -> endpoint infos), counted."""

    nodes: list[str] = field(default_factory=lambda: ["shaper", "source", "controller"])
    pubs: dict[str, list[Any]] = field(default_factory=lambda: {IN_T: [info("source")], OUT_T: [info("shaper")]})
    subs: dict[str, list[Any]] = field(default_factory=lambda: {IN_T: [info("shaper")], OUT_T: [info("controller")]})
    calls: Counter[str] = field(default_factory=Counter)

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        self.calls["names"] += 1
        return [(n, "/") for n in self.nodes]

    def count_publishers(self, topic: str) -> int:
        self.calls["count"] += 1
        return len(self.pubs.get(topic, []))

    def count_subscribers(self, topic: str) -> int:
        self.calls["count"] += 1
        return len(self.subs.get(topic, []))

    def get_publishers_info_by_topic(self, topic: str) -> list[Any]:
        self.calls["info"] += 1
        return list(self.pubs.get(topic, []))

    def get_subscriptions_info_by_topic(self, topic: str) -> list[Any]:
        self.calls["info"] += 1
        return list(self.subs.get(topic, []))


class FakeNode:
    """The watching node: its name, a logger, and endpoints made as rclpy makes them."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.logger = SimpleNamespace(get_child=lambda _: self.logger, error=self.lines.append,
                                      warning=self.lines.append, info=self.lines.append)

    def get_logger(self) -> Any:
        return self.logger

    def get_fully_qualified_name(self) -> str:
        return "/shaper"

    def create_subscription(self, msg_type: Any, topic: str, *_: Any, **__: Any) -> Any:
        return SimpleNamespace(topic_name=topic, qos_profile=RELIABLE)

    def create_publisher(self, msg_type: Any, topic: str, *_: Any, **__: Any) -> Any:
        return SimpleNamespace(topic_name=topic, qos_profile=RELIABLE)


class Statuses:
    """The Diagnostics stand-in: every ``graph`` status published."""

    def __init__(self) -> None:
        self.published: list[tuple[int, str]] = []

    def publish(self, name: str, level: int, message: str, values: Any = ()) -> None:
        self.published.append((level, message))


def watch() -> tuple[GraphWatch, FakeGraph, Statuses]:
    from std_msgs.msg import Float64MultiArray

    graph, statuses = FakeGraph(), Statuses()
    w = GraphWatch(FakeNode(), statuses, 1.0, looker=graph)
    w.subscription(Float64MultiArray, IN_T, lambda _: None, 10)
    w.publisher(Float64MultiArray, OUT_T, 10)
    return w, graph, statuses


def test_a_steady_graph_is_looked_at_in_full_once_every_full_every_looks_and_reported_every_look():
    w, graph, statuses = watch()
    for _ in range(2 * FULL_EVERY):
        assert w.look() == []
    assert w.full_looks == 2
    assert graph.calls["info"] == 2 * 4  # two full looks, a publisher and a subscriber query per topic each
    assert [level for level, _ in statuses.published] == [OK] * (2 * FULL_EVERY)


def test_a_second_publisher_on_an_input_is_seen_at_the_next_look_and_its_leaving_too():
    w, graph, statuses = watch()
    w.look()
    graph.nodes.append("intruder")
    graph.pubs[IN_T].append(info("intruder"))
    assert [f.kind for f in w.look()] == ["publishers"] and w.full_looks == 2
    assert statuses.published[-1][0] == WARN
    w.look()  # the same graph: the findings reused, the status published again
    assert w.full_looks == 2 and statuses.published[-1][0] == WARN
    graph.nodes.pop()
    graph.pubs[IN_T].pop()
    assert w.look() == [] and w.full_looks == 3 and statuses.published[-1][0] == OK


def test_an_endpoint_replaced_by_one_of_incompatible_qos_behind_the_same_counts_is_seen_within_full_every_looks():
    """The case the signature cannot show: the same node, the same counts, another QoS."""
    w, graph, statuses = watch()
    w.look()
    graph.pubs[IN_T] = [info("source", BEST_EFFORT)]
    looks = 1
    while not w.findings:
        w.look()
        looks += 1
        assert looks <= FULL_EVERY + 1
    assert [f.kind for f in w.findings] == ["qos"] and statuses.published[-1][0] == ERROR


def test_a_middleware_event_brings_a_full_look_at_once():
    w, graph, _ = watch()
    w.look()
    graph.pubs[IN_T] = [info("source", BEST_EFFORT)]  # the counts unchanged; the middleware tells of it
    w._event(IN_T, "qos", "RELIABILITY")
    assert [f.kind for f in w.look()] == ["qos"] and w.full_looks == 2
