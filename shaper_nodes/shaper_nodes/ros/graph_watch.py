"""The ROS graph around a node's command path, watched: who else is there, and what they offer.

Whatever the shaper forwards reaches the robot's controller, so the graph around it must be the
one its integrator drew. :class:`GraphWatch` looks at the graph every ``period`` seconds of wall
time and reports each of these as a *finding*:

``duplicate_name`` (ERROR)
    another node with this node's fully qualified name (a second shaper process: every command
    may then be shaped and forwarded twice, with different filter states).
``publishers`` (WARN)
    more than one publisher on a command input: their commands interleave in one shaped stream.
``other_publisher`` (ERROR)
    another node publishing on one of this node's output topics: the controller gets commands
    that were not shaped (or were shaped twice).
``wrong_type`` (ERROR)
    a publisher on an input, or a subscriber of an output, with another message type than this
    node's: nothing passes between them.
``qos`` (ERROR)
    a publisher on an input, or a subscriber of an output, whose QoS cannot match this node's
    (``rclpy.qos.qos_check_compatible`` says ERROR, e.g. a best-effort publisher against a
    reliable subscription): nothing passes between them. The middleware's own
    ``incompatible_qos`` and ``incompatible_type`` events on the watched endpoints are recorded
    too; one the graph does not explain within :data:`GRACE` looks is reported as it is.

A finding that names an endpoint the graph has not tied to a node (yet: DDS discovers a new node's
endpoints before its name) is reported only once it has held :data:`GRACE` looks in a row.

Most looks are cheap. A full look asks rclpy for every endpoint of every watched topic with its QoS (50-80 us
a topic on the 2-core machine, in C that holds the interpreter: the shaper's stream waits meanwhile, which
read as +100-200 us on the hop's quiet p99 with a 1 s period, docs/results/benchmarks.md, session 16). A
look first takes the graph's *signature*: the node names and, per watched topic, the publisher and
subscriber counts (about 15 us a topic). While the signature is the last full look's, no middleware event
waits to be explained and fewer than :data:`FULL_EVERY` looks went by since it, the look reuses the last
full look's findings. A change the signature does not show (a publisher replaced within one period by
another with other QoS; the middleware's incompatible-QoS event then reports it at once) is seen within
:data:`FULL_EVERY` looks.

Each finding is logged once, when it appears (again only if it clears and comes back), and a
status ``<node>: graph`` goes to ``/diagnostics`` at every look: the findings (worst level, their
messages, key values naming the topic, the nodes, the types or the QoS), or OK. The decisions are
the pure functions :func:`~.graph_rules.graph_findings` and :func:`~.graph_rules.summary` and the
:class:`~.graph_rules.Latch` (:mod:`.graph_rules`), testable without a graph; :class:`GraphWatch` feeds them from
rclpy's graph queries.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks, qos_policy_name_from_kind
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSCompatibility, QoSProfile, qos_check_compatible
from rclpy.subscription import Subscription
from rclpy.topic_endpoint_info import TopicEndpointInfo

from .diagnostics import ERROR, Diagnostics
from .graph_rules import (
    GRACE,
    IN,
    OUT,
    Endpoint,
    Finding,
    Latch,
    Watched,
    event_finding,
    fqn,
    graph_findings,
    summary,
    type_name,
)

#: looks between two full looks while the graph's signature holds (see the module docstring)
FULL_EVERY = 10


def _qos_problem(pub_qos: QoSProfile, sub_qos: QoSProfile) -> str:
    """rclpy's reason when a publisher with ``pub_qos`` cannot match a subscription with ``sub_qos``."""
    compat, reason = qos_check_compatible(pub_qos, sub_qos)
    if compat != QoSCompatibility.ERROR:
        return ""
    # "ERROR: a;WARNING: b;ERROR: c;": the errors
    errors = [r.strip().removeprefix("ERROR:").strip() for r in reason.split(";") if r.strip().startswith("ERROR:")]
    return "; ".join(errors) or reason.strip()


def _policy(status: Any) -> str:
    """The QoS policy an incompatible-QoS event names (its last incompatible one)."""
    return str(qos_policy_name_from_kind(status.last_policy_kind))


@dataclass
class _Topic:
    watched: Watched
    qos: QoSProfile  # the node's endpoint's, as rclpy made it
    owner: str  # the node that owns the endpoint (the side node for a side subscription)


class GraphWatch:
    """The graph around ``node``'s command path, looked at every ``period`` s (see the module docstring).

    Create the command path's subscriptions and publishers through :meth:`subscription` and
    :meth:`publisher` (they then carry the QoS event callbacks and are watched), then :meth:`start`.

    Parameters
    ----------
    node : Node
        The watching node: its name, logger (child ``graph``) and namespace.
    diagnostics : Diagnostics
        Where the ``graph`` status goes.
    period : float
        s of wall (steady) time between two looks; 0 disables the watch (no timer, no event callbacks:
        rclpy's default ones log incompatible QoS).
    looker : Node, optional
        The node whose executor runs the looks and whose graph queries are used (the shaper's side
        node, so that the stream never waits for them); ``node`` if not given.
    """

    def __init__(self, node: Node, diagnostics: Diagnostics, period: float, looker: Node | None = None) -> None:
        self.node = node
        self.diagnostics = diagnostics
        self.period = float(period)
        self._looker = looker or node
        self._log = node.get_logger().get_child("graph")
        self._topics: dict[str, _Topic] = {}
        self._latch = Latch()
        self._lock = threading.Lock()
        self._events: dict[tuple[str, str], tuple[str, int]] = {}  # (topic, qos|type) -> (detail, look seen)
        self._looks = 0
        self._signature: tuple[Any, ...] | None = None  # the graph's at the last full look
        self._graph_found: list[Finding] = []  # the findings of the last full look, from the graph
        self._since_full = 0  # looks since the last full look
        #: full looks so far (the rest reused the last one's findings)
        self.full_looks = 0
        self.findings: list[Finding] = []
        #: middleware events seen, per ``incompatible_qos@<topic>`` / ``incompatible_type@<topic>``
        self.events: Counter[str] = Counter()

    @property
    def enabled(self) -> bool:
        return self.period > 0.0

    def subscription(self, msg_type: Any, topic: str, callback: Callable[..., None], qos: QoSProfile | int,
                     on: Node | None = None, **kwargs: Any) -> Subscription:
        """``on`` (default the node) ``.create_subscription(...)`` with the event callbacks, watched as an input."""
        where: list[str] = []
        events = None
        if self.enabled:
            events = SubscriptionEventCallbacks(
                incompatible_qos=lambda s: self._event(where[0], "qos", _policy(s)),
                incompatible_type=lambda s: self._event(where[0], "type", ""))
        owner = on or self.node
        sub = owner.create_subscription(msg_type, topic, callback, qos, event_callbacks=events, **kwargs)
        where.append(sub.topic_name)
        self._topics[sub.topic_name] = _Topic(Watched(sub.topic_name, IN, type_name(msg_type)), sub.qos_profile,
                                              owner.get_fully_qualified_name())
        return sub

    def publisher(self, msg_type: Any, topic: str, qos: QoSProfile | int, on: Node | None = None) -> Publisher:
        """``on`` (default the node) ``.create_publisher(...)`` with the event callbacks, watched as an output."""
        where: list[str] = []
        events = None
        if self.enabled:
            events = PublisherEventCallbacks(
                incompatible_qos=lambda s: self._event(where[0], "qos", _policy(s)),
                incompatible_type=lambda s: self._event(where[0], "type", ""))
        owner = on or self.node
        pub = owner.create_publisher(msg_type, topic, qos, event_callbacks=events)
        where.append(pub.topic_name)
        old = self._topics.get(pub.topic_name)
        own = 1 + (old.watched.own_publishers if old else 0)
        self._topics[pub.topic_name] = _Topic(Watched(pub.topic_name, OUT, type_name(msg_type), own),
                                              pub.qos_profile, owner.get_fully_qualified_name())
        return pub

    def _event(self, topic: str, what: str, detail: str) -> None:
        with self._lock:
            self._events[(topic, what)] = (detail, self._looks)
            self.events[f"incompatible_{what}@{topic}"] += 1

    def start(self) -> None:
        """Look every ``period`` s on a steady clock (the node may run on simulated time)."""
        if self.enabled:
            self._looker.create_timer(self.period, self.look, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @staticmethod
    def _endpoints(infos: Sequence[TopicEndpointInfo], ours: QoSProfile, direction: str) -> list[Endpoint]:
        """``infos`` (the peers of the node's endpoint, whose QoS is ``ours``) as Endpoints."""
        out = []
        for i in infos:
            pub_qos, sub_qos = (i.qos_profile, ours) if direction == IN else (ours, i.qos_profile)
            out.append(Endpoint(fqn(i.node_name, i.node_namespace), i.topic_type, _qos_problem(pub_qos, sub_qos)))
        return out

    def signature(self) -> tuple[Any, ...]:
        """The graph as the cheap queries show it: node names, and the publisher and subscriber counts of
        every watched topic."""
        g = self._looker
        return (tuple(sorted(g.get_node_names_and_namespaces())),
                tuple((g.count_publishers(name), g.count_subscribers(name)) for name in self._topics))

    def look(self) -> list[Finding]:
        """One look at the graph: the findings, new ones logged, cleared ones noted, the status published. The
        graph is looked at in full only when its signature changed, an event waits or every FULL_EVERY looks."""
        signature = self.signature()
        with self._lock:
            waiting = bool(self._events)
        if waiting or signature != self._signature or self._since_full + 1 >= FULL_EVERY:
            self._graph_found = self._full_look()
            self._signature, self._since_full = signature, 0
            self.full_looks += 1
        else:
            self._since_full += 1
        found = list(self._graph_found)
        found += self._unexplained(found)
        self.report(found)
        return self.findings

    def _full_look(self) -> list[Finding]:
        """The findings from every endpoint of the watched topics, with their QoS."""
        g = self._looker
        nodes = [fqn(n, ns) for n, ns in g.get_node_names_and_namespaces()]
        pubs: dict[str, list[Endpoint]] = {}
        subs: dict[str, list[Endpoint]] = {}
        for name, t in self._topics.items():
            p_infos, s_infos = g.get_publishers_info_by_topic(name), g.get_subscriptions_info_by_topic(name)
            mine, peers = (s_infos, p_infos) if t.watched.direction == IN else (p_infos, s_infos)
            # QoS compared as the graph reports both sides (rclpy's own profile leaves deadline and lease at
            # "default", which the check takes for "none" against a discovered "infinite")
            ours = next((i.qos_profile for i in mine if fqn(i.node_name, i.node_namespace) == t.owner), t.qos)
            peer_eps = self._endpoints(peers, ours, t.watched.direction)
            mine_eps = [Endpoint(fqn(i.node_name, i.node_namespace), i.topic_type) for i in mine]
            pubs[name], subs[name] = (peer_eps, mine_eps) if t.watched.direction == IN else (mine_eps, peer_eps)
        me = self.node.get_fully_qualified_name()
        return graph_findings(me, nodes, [t.watched for t in self._topics.values()], pubs, subs)

    def _unexplained(self, found: Sequence[Finding]) -> list[Finding]:
        """Middleware events that the graph has not explained within GRACE looks (reported once each)."""
        explains = {"qos": {"qos"}, "type": {"wrong_type"}}
        out = []
        with self._lock:
            self._looks += 1
            for (topic, what), (detail, seen) in list(self._events.items()):
                if any(f.topic == topic and f.kind in explains[what] for f in found):
                    del self._events[(topic, what)]
                elif self._looks - seen > GRACE:
                    del self._events[(topic, what)]
                    out.append(event_finding(topic, what, self._topics[topic].watched.direction, detail))
        return out

    def report(self, found: list[Finding]) -> None:
        """Log the findings that are new, note the cleared ones, publish the ``graph`` status (the
        findings that hold: see :class:`Latch`); ``findings`` is then the list of those."""
        found, new, cleared = self._latch.update(found)
        self.findings = found
        for f in new:
            if f.level >= ERROR:  # one call site per severity, as rclpy's logger wants
                self._log.error(f.message)
            else:
                self._log.warning(f.message)
        for f in cleared:
            self._log.info(f"cleared: {f.kind}{' on ' + f.topic if f.topic else ''}"
                           f"{' (' + ', '.join(f.nodes) + ')' if f.nodes else ''}")
        self.diagnostics.publish("graph", *summary(found))


__all__ = ["FULL_EVERY", "GraphWatch"]
