"""ROS names and their DDS topics (rmw's mangling), and what one enclave may do in ROS terms (:class:`Access`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["ACTION_SERVICES", "ACTION_TOPICS", "DISCOVERY_TOPIC", "PARAMETER_SERVICES", "Access", "Verb", "node_fqn",
           "resolve", "service_dds", "topic_dds"]


#: the services every rclpy/rclcpp node serves for its parameters, and Jazzy's type description
PARAMETER_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
                      "set_parameters", "set_parameters_atomically", "get_type_description")


#: the services and topics an action is made of (below ``<action>/_action/``)
ACTION_SERVICES = ("send_goal", "cancel_goal", "get_result")


ACTION_TOPICS = ("feedback", "status")


#: DDS topic of rmw's graph information, published and read by every participant
DISCOVERY_TOPIC = "ros_discovery_info"


Verb = Literal["publish", "subscribe"]


def _clean(name: str) -> str:
    name = name.strip()
    if not name:
        raise ValueError("a ROS name must not be empty")
    bad = sorted({c for c in name if not (c.isascii() and (c.isalnum() or c in "_/~"))})
    if bad or "//" in name:
        # also keeps fnmatch wildcards (* ? [) out of the permissions, where they would widen a grant
        raise ValueError(f"{name!r} is not a valid ROS name: only letters, digits, '_', '/' and '~' "
                         f"({'has ' + ' '.join(map(repr, bad)) if bad else 'has //'})")
    return name


def node_fqn(namespace: str, node: str) -> str:
    """Fully qualified name of ``node`` in ``namespace`` (``'/'`` or ``'/a/b'``)."""
    ns = "/" + _clean(namespace).strip("/") if namespace.strip("/") else ""
    node = _clean(node)
    if "/" in node:
        raise ValueError(f"node name {node!r} must not contain '/' (give the namespace separately)")
    return f"{ns}/{node}"


def resolve(name: str, namespace: str, node: str) -> str:
    """Fully qualified ROS name of ``name`` for ``node`` in ``namespace``: absolute names stay,
    ``~/x`` is below the node, relative names are below the namespace."""
    name = _clean(name)
    if name.startswith("/"):
        return name.rstrip("/")
    if name == "~":
        return node_fqn(namespace, node)
    if name.startswith("~/"):
        return f"{node_fqn(namespace, node)}/{name[2:]}"
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    return f"{ns}/{name}"


def topic_dds(name: str) -> str:
    """DDS topic of the ROS topic ``name`` (fully qualified): ``rt/...``."""
    return "rt" + _fq(name)


def service_dds(name: str) -> tuple[str, str]:
    """DDS request and reply topics of the ROS service ``name`` (fully qualified)."""
    fq = _fq(name)
    return f"rq{fq}Request", f"rr{fq}Reply"


def _fq(name: str) -> str:
    name = _clean(name)
    if not name.startswith("/"):
        raise ValueError(f"{name!r} is not fully qualified (resolve it first)")
    return name.rstrip("/")


@dataclass(frozen=True)
class Access:
    """What one enclave may do, in ROS terms (fully qualified names).

    Attributes
    ----------
    nodes : tuple of str
        Fully qualified names of the nodes run in the enclave: each may publish its log
        (``/rosout``), parameter events and rmw's discovery information, and serve its own
        parameter services; nobody else may call those.
    publish, subscribe : frozenset of str
        Topics.
    serve, call : frozenset of str
        Services.
    serve_actions, call_actions : frozenset of str
        Actions.
    dds_publish, dds_subscribe : frozenset of str
        Extra DDS topic expressions (fnmatch patterns such as ``rq/controller_manager/*``) for
        interfaces the suite does not name one by one.
    """

    nodes: tuple[str, ...]
    publish: frozenset[str] = frozenset()
    subscribe: frozenset[str] = frozenset()
    serve: frozenset[str] = frozenset()
    call: frozenset[str] = frozenset()
    serve_actions: frozenset[str] = frozenset()
    call_actions: frozenset[str] = frozenset()
    dds_publish: frozenset[str] = frozenset()
    dds_subscribe: frozenset[str] = frozenset()

    def dds(self) -> tuple[frozenset[str], frozenset[str]]:
        """The DDS topics (and patterns) this enclave may publish and subscribe."""
        pub: set[str] = {DISCOVERY_TOPIC, "rt/rosout", "rt/parameter_events"}
        sub: set[str] = {DISCOVERY_TOPIC, "rt/parameter_events", "rt/clock"}
        for node in self.nodes:
            for srv in PARAMETER_SERVICES:
                rq, rr = service_dds(f"{node}/{srv}")
                sub.add(rq)
                pub.add(rr)
        pub |= {topic_dds(t) for t in self.publish}
        sub |= {topic_dds(t) for t in self.subscribe}
        served = set(self.serve) | {f"{a}/_action/{s}" for a in self.serve_actions for s in ACTION_SERVICES}
        called = set(self.call) | {f"{a}/_action/{s}" for a in self.call_actions for s in ACTION_SERVICES}
        for srv in served:
            rq, rr = service_dds(srv)
            sub.add(rq)
            pub.add(rr)
        for srv in called:
            rq, rr = service_dds(srv)
            pub.add(rq)
            sub.add(rr)
        pub |= {topic_dds(f"{a}/_action/{t}") for a in self.serve_actions for t in ACTION_TOPICS}
        sub |= {topic_dds(f"{a}/_action/{t}") for a in self.call_actions for t in ACTION_TOPICS}
        return frozenset(pub | self.dds_publish), frozenset(sub | self.dds_subscribe)
