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

Each finding is logged once, when it appears (again only if it clears and comes back), and a
status ``<node>: graph`` goes to ``/diagnostics`` at every look: the findings (worst level, their
messages, key values naming the topic, the nodes, the types or the QoS), or OK. The decisions are
the pure functions :func:`graph_findings` and :func:`summary` and the :class:`Latch`, testable
without a graph; :class:`GraphWatch` feeds them from rclpy's graph queries.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks, qos_policy_name_from_kind
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSCompatibility, QoSProfile, qos_check_compatible
from rclpy.subscription import Subscription
from rclpy.topic_endpoint_info import TopicEndpointInfo

from .diagnostics import ERROR, OK, WARN, Diagnostics

#: looks at the graph within which a middleware event (incompatible QoS or type) must be explained by
#: an endpoint in the graph before it is reported without one
GRACE = 3
#: how the graph names an endpoint whose participant is not a ROS node
UNKNOWN_NODE = "(not a ROS node)"
IN, OUT = "in", "out"


def fqn(name: str, namespace: str) -> str:
    """A node's fully qualified name from its name and namespace (``/ns`` + ``name``)."""
    if name.startswith("_NODE_NAME_UNKNOWN_"):
        return UNKNOWN_NODE
    return f"{namespace.rstrip('/')}/{name}"


@dataclass(frozen=True)
class Endpoint:
    """One publisher or subscriber in the graph, as the decisions need it.

    Attributes
    ----------
    node : str
        Fully qualified name of its node (:data:`UNKNOWN_NODE` if the graph does not know it).
    type : str
        Its message type, ``pkg/msg/Name``.
    qos_problem : str
        Why its QoS cannot match the watching node's endpoint on the topic ("" if it can, or if it
        is on the same side as the watching node's).
    """

    node: str
    type: str
    qos_problem: str = ""


@dataclass(frozen=True)
class Watched:
    """A topic of the command path.

    Attributes
    ----------
    topic : str
        Fully qualified topic name.
    direction : str
        ``"in"``: the node subscribes to it (a command input); ``"out"``: it publishes (an output).
    type : str
        The node's message type on it, ``pkg/msg/Name``.
    own_publishers : int
        How many publishers the node itself has on it (graph entries of its name beyond these are
        another node's).
    """

    topic: str
    direction: str
    type: str
    own_publishers: int = 0


@dataclass(frozen=True)
class Finding:
    """One thing wrong with the graph.

    Attributes
    ----------
    kind : str
        ``duplicate_name``, ``publishers``, ``other_publisher``, ``wrong_type``, ``qos`` or
        ``event`` (a middleware event no endpoint of the graph explains).
    topic : str
        The topic concerned ("" for ``duplicate_name``).
    nodes : tuple of str
        The other nodes involved (fully qualified, sorted).
    level : int
        WARN or ERROR (``diagnostic_msgs/DiagnosticStatus`` levels).
    message : str
        What it is and what it does to the commands, one sentence.
    values : tuple of (str, str)
        Key values for the status (keys without the finding's prefix).
    """

    kind: str
    topic: str
    nodes: tuple[str, ...]
    level: int
    message: str
    values: tuple[tuple[str, str], ...] = field(default=())

    @property
    def key(self) -> tuple[str, str, tuple[str, ...]]:
        """What makes a finding distinct: its kind, topic and nodes (not the wording)."""
        return self.kind, self.topic, self.nodes

    @property
    def label(self) -> str:
        """The prefix of its keys in the status: ``kind`` or ``kind@topic``."""
        return f"{self.kind}@{self.topic}" if self.topic else self.kind


def _counted(nodes: Iterable[str]) -> tuple[tuple[str, ...], str]:
    """The distinct names sorted, and a text listing them with their counts when more than one."""
    counts = Counter(nodes)
    names = tuple(sorted(counts))
    return names, ", ".join(f"{n} ({counts[n]})" if counts[n] > 1 else n for n in names)


def graph_findings(me: str, nodes: Sequence[str], watched: Iterable[Watched],
                   publishers: Mapping[str, Sequence[Endpoint]],
                   subscribers: Mapping[str, Sequence[Endpoint]]) -> list[Finding]:
    """What is wrong with the graph around the node ``me``.

    Parameters
    ----------
    me : str
        The watching node's fully qualified name.
    nodes : sequence of str
        Fully qualified names of every node in the graph, once per node (``me`` included; twice if
        two nodes share it).
    watched : iterable of Watched
        The node's command-path topics.
    publishers, subscribers : mapping of topic to sequence of Endpoint
        Every publisher and subscriber in the graph on each watched topic, the node's own included.

    Returns
    -------
    list of Finding
        In a stable order: the name first, then per topic as ``watched`` gives them.
    """
    out: list[Finding] = []
    watched = list(watched)
    twins = sum(1 for n in nodes if n == me)
    twin_outputs: list[str] = []  # outputs the other node of this name publishes on
    for w in watched:
        if w.direction == OUT:
            mine = sum(1 for e in publishers.get(w.topic, ()) if e.node == me)
            if twins > 1 and mine > w.own_publishers:
                twin_outputs.append(w.topic)
    if twins > 1:
        values = [("node", me), ("count", str(twins))]
        also = f"; it publishes on {', '.join(twin_outputs)} too" if twin_outputs else ""
        if twin_outputs:
            values.append(("also_publishes", ", ".join(twin_outputs)))
        out.append(Finding("duplicate_name", "", (me,), ERROR,
                           f"{twins} nodes named {me} in the graph: another process runs a node of this name, so"
                           f" commands may be shaped and forwarded twice{also} (stop one, or rename it with"
                           " --ros-args -r __node:=<name>)", tuple(values)))
    for w in watched:
        pubs, subs = list(publishers.get(w.topic, ())), list(subscribers.get(w.topic, ()))
        if w.direction == IN:
            peers, side = pubs, "publisher"
            if len(pubs) > 1:
                names, text = _counted(e.node for e in pubs)
                out.append(Finding("publishers", w.topic, names, WARN,
                                   f"{len(pubs)} publishers on {w.topic}: {text}; their commands interleave in the"
                                   " one shaped stream", (("topic", w.topic), ("publishers", text),
                                                          ("count", str(len(pubs))))))
        else:
            peers, side = subs, "subscriber"
            others = _others(pubs, me, w.own_publishers)
            if twins > 1:  # the other node of this name is reported above
                others = [e for e in others if e.node != me]
            if others:
                names, text = _counted(e.node for e in others)
                types = ", ".join(sorted({e.type for e in others}))
                out.append(Finding("other_publisher", w.topic, names, ERROR,
                                   f"{text} also publish{'es' if len(others) == 1 else ''} on {w.topic}, an output of"
                                   f" {me}: the controller gets commands that this node did not shape",
                                   (("topic", w.topic), ("publishers", text), ("types", types))))
        wrong = [e for e in peers if e.type != w.type]
        if wrong:
            names, text = _counted(e.node for e in wrong)
            types = ", ".join(sorted({e.type for e in wrong}))
            effect = ("its messages never reach" if side == "publisher" else "it gets nothing from") + f" {me}"
            out.append(Finding("wrong_type", w.topic, names, ERROR,
                               f"a {side} of {types} on {w.topic}, which carries {w.type}: {text}; {effect}",
                               (("topic", w.topic), (f"{side}s", text), ("type", types), ("expected", w.type))))
        bad_qos = [e for e in peers if e.qos_problem]
        if bad_qos:
            names, text = _counted(e.node for e in bad_qos)
            reasons = "; ".join(sorted({e.qos_problem for e in bad_qos}))
            out.append(Finding("qos", w.topic, names, ERROR,
                               f"a {side} on {w.topic} with QoS incompatible with {me}'s: {text} ({reasons});"
                               " no message passes between them",
                               (("topic", w.topic), (f"{side}s", text), ("reason", reasons))))
    return out


def _others(pubs: Sequence[Endpoint], me: str, own: int) -> list[Endpoint]:
    """``pubs`` without the node's own ``own`` publishers (entries of its name beyond them stay)."""
    left, rest = own, []
    for e in pubs:
        if e.node == me and left > 0:
            left -= 1
        else:
            rest.append(e)
    return rest


def event_finding(topic: str, what: str, direction: str, detail: str) -> Finding:
    """A middleware event on ``topic`` that no endpoint of the graph explains (``what``: ``qos`` or
    ``type``; ``detail``: the QoS policy the event names)."""
    side = "publisher" if direction == IN else "subscriber"
    about = f"QoS (policy {detail})" if what == "qos" else "message type"
    return Finding("event", topic, (), ERROR,
                   f"the middleware reports a {side} on {topic} with an incompatible {about}; its node is not"
                   " in the graph", (("topic", topic), ("event", f"incompatible_{what}"),
                                     *((("policy", detail),) if what == "qos" else ())))


def summary(findings: Sequence[Finding]) -> tuple[int, str, list[tuple[str, str]]]:
    """The ``graph`` status of ``findings``: level (the worst), message and key values (each finding's
    values with its label as prefix)."""
    if not findings:
        return OK, "no other node of this name; inputs with at most one publisher each, of this node's type and" \
                   " compatible QoS; outputs published by this node only", []
    level = max(f.level for f in findings)
    message = findings[0].message if len(findings) == 1 else \
        f"{len(findings)} problems in the graph: " + " | ".join(f.message for f in findings)
    values = [(f"{f.label}.{k}", v) for f in findings for k, v in f.values]
    return level, message, values


class Latch:
    """Which findings hold: :meth:`update` tells the ones that hold, the new ones (to log) and the
    cleared ones.

    A finding that names an endpoint of :data:`UNKNOWN_NODE` holds only once it has been found in
    ``settle`` looks in a row: DDS discovers a new node's endpoints before the graph learns which node
    they belong to, so for a moment a new publisher has no node (measured: one look at 0.5 s).
    """

    def __init__(self, settle: int = GRACE) -> None:
        self.settle = settle
        self._active: dict[tuple[str, str, tuple[str, ...]], Finding] = {}
        self._streak: dict[tuple[str, str, tuple[str, ...]], int] = {}

    def update(self, findings: Iterable[Finding]) -> tuple[list[Finding], list[Finding], list[Finding]]:
        """Take the findings of one look; returns (those that hold, appeared since the last look, cleared
        since)."""
        found = {f.key: f for f in findings}
        self._streak = {k: self._streak.get(k, 0) + 1 for k in found}
        now = {k: f for k, f in found.items() if UNKNOWN_NODE not in f.nodes or self._streak[k] >= self.settle}
        new = [f for k, f in now.items() if k not in self._active]
        cleared = [f for k, f in self._active.items() if k not in now]
        self._active = now
        return list(now.values()), new, cleared


def type_name(msg_type: Any) -> str:
    """``pkg/msg/Name`` of a generated message class, as the graph names types."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


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

    def look(self) -> list[Finding]:
        """One look at the graph: the findings, new ones logged, cleared ones noted, the status published."""
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
        found = graph_findings(me, nodes, [t.watched for t in self._topics.values()], pubs, subs)
        found += self._unexplained(found)
        self.report(found)
        return self.findings

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


__all__ = ["GRACE", "UNKNOWN_NODE", "Endpoint", "Finding", "GraphWatch", "Latch", "Watched", "event_finding",
           "fqn", "graph_findings", "summary", "type_name"]
