"""The graph watch's decisions, testable without a graph (:mod:`.graph_watch` feeds them from rclpy's graph
queries): the endpoints around a node's command path (:class:`Endpoint`, :class:`Watched`), what is wrong with
them (:func:`graph_findings`, :func:`event_finding`: :class:`Finding`), the ``graph`` status of the findings
(:func:`summary`), and which of them hold and are logged once (:class:`Latch`). The findings and what they
mean are in :mod:`.graph_watch`'s docstring."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .diagnostics import ERROR, OK, WARN

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


__all__ = ["GRACE", "IN", "OUT", "UNKNOWN_NODE", "Endpoint", "Finding", "Latch", "Watched", "event_finding", "fqn",
           "graph_findings", "summary", "type_name"]
