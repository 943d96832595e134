"""Who may talk to whom on the suite's DDS domain: the SROS2 access policy, written once.

The shaper node's update policy (:mod:`.shaping.policy`) decides by the ``source`` a
``SetShaper`` request names: that is a label any caller can write, not an identity. On a plain
DDS domain anyone may call ``/shaper/set_shaper`` or publish on the shaper's command inputs.
Identity comes from SROS2: each process runs in an *enclave* (``--ros-args --enclave PATH``)
with a certificate whose subject is ``CN=<enclave path>`` and a signed ``permissions.xml`` that
DDS access control enforces (``ROS_SECURITY_ENABLE=true``, ``ROS_SECURITY_STRATEGY=Enforce``).

This module holds the policy table (:func:`suite_policy`: which enclave publishes and subscribes
which topic, serves and calls which service and action), the ROS-to-DDS name mangling, and the
governance and permissions documents of OMG DDS-Security 1.1 (the builtin access control plugin's
XML). It does no I/O and no cryptography: ``shaper_nodes.cli.keystore`` writes the keystore and
signs these documents with ``openssl``.

Name mangling (rmw's, for DDS topics): a topic ``/a/b`` is ``rt/a/b``; a service ``/a/s`` is the
request topic ``rq/a/sRequest`` and the reply topic ``rr/a/sReply``; an action ``/a/x`` is the
services ``/a/x/_action/{send_goal,cancel_goal,get_result}`` and the topics
``/a/x/_action/{feedback,status}``. A server subscribes to requests and publishes replies; a
client publishes requests and subscribes to replies.

Every permissions document has, for its subject, one ``allow_rule`` (the grants), one
``deny_rule`` naming every other DDS topic of the suite (so the denials are explicit, and stay so
even if a later allow rule is widened) and ``<default>DENY</default>``; the builtin plugin takes
the first rule that matches, in document order.
"""

from __future__ import annotations

import fnmatch
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Literal
from xml.sax.saxutils import escape

#: the enclave folder the suite's enclaves live under
DEFAULT_ROOT = "/shaper_suite"
#: ROS domain ids covered by the governance and the permissions (inclusive); ROS 2 uses 0-232
DEFAULT_DOMAINS = (0, 232)
#: the services every rclpy/rclcpp node serves for its parameters, and Jazzy's type description
PARAMETER_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
                      "set_parameters", "set_parameters_atomically", "get_type_description")
#: the services and topics an action is made of (below ``<action>/_action/``)
ACTION_SERVICES = ("send_goal", "cancel_goal", "get_result")
ACTION_TOPICS = ("feedback", "status")
#: DDS topic of rmw's graph information, published and read by every participant
DISCOVERY_TOPIC = "ros_discovery_info"

#: The suite's node names, topics and services that the table refers to, with their defaults (the
#: nodes' own parameter defaults: ``topics.*`` of nodes/shaper.py, ``action.*``, ``shaper``,
#: ``mrilc.*`` ...). ``node.*`` are node names (in ``namespace``); the other values are ROS names,
#: ``~/x`` being relative to the node that owns them.
DEFAULT_NAMES: dict[str, str] = {
    "namespace": "/",
    "node.shaper": "shaper",
    "node.learner": "learner",
    "node.scheduler": "scheduler",
    "node.identifier": "identifier",
    "node.calibrate": "calibrate",
    "node.recorder": "recorder",
    "node.motion_source": "motion_source",
    # the controller side (ros2_control): the controller manager and its controllers are nodes
    "node.controller": "controller_manager,joint_trajectory_controller,forward_position_controller,"
                       "joint_state_broadcaster,imu_sensor_broadcaster",
    # the shaper node's topics.* (nodes/shaper.py TOPICS)
    "topics.array_in": "~/commands",
    "topics.array_out": "/forward_position_controller/commands",
    "topics.stream_in": "~/joint_trajectory_stream",
    "topics.stream_out": "/joint_trajectory_controller/joint_trajectory",
    "topics.trajectory_in": "~/joint_trajectory",
    "topics.trajectory_out": "/joint_trajectory_controller/joint_trajectory",
    # the shaper node's action.*: its FollowJointTrajectory server and the controller's
    "action.server_name": "~/follow_joint_trajectory",
    "action.controller": "/joint_trajectory_controller/follow_joint_trajectory",
    # what the learners, the identifier, the scheduler and calibrate read (their topics.* defaults)
    "topics.joint_states": "/joint_states",
    "topics.imu": "/tip_imu",
    "topics.cycle_events": "/cycle_events",
    "topics.reference": "/sim_plant/reference",
    "topics.diagnostics": "/diagnostics",
    # MRILC's injection point: the node that serves ~/set_feedforward (controller side)
    "mrilc.injection_target": "/sim_plant",
}

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


def names_with(overrides: Mapping[str, str] | None = None) -> dict[str, str]:
    """:data:`DEFAULT_NAMES` with ``overrides``; an unknown key is an error naming the known ones."""
    names = dict(DEFAULT_NAMES)
    for key, value in (overrides or {}).items():
        if key not in names:
            raise ValueError(f"unknown name {key!r}; known: {', '.join(sorted(names))}")
        names[key] = value
    return names


def suite_policy(overrides: Mapping[str, str] | None = None) -> dict[str, Access]:
    """The suite's access policy: enclave role -> :class:`Access` (the table of docs/guide/security.md).

    - ``shaper``: serves ``~/set_shaper``, ``~/get_shaper``, ``~/shape_trajectory`` and its
      FollowJointTrajectory action, reads the command inputs, publishes the shaped commands,
      ``~/active_shaper`` and diagnostics, calls the controller's action and (``action.scheduler``)
      the scheduler's ``~/shaper_at``.
    - ``learner``, ``scheduler``, ``identifier``, ``calibrate``: the only callers of the shaper's
      ``~/set_shaper`` (the learner also of the scheduler's, when it is pointed at it, and, learning per
      move, of its ``~/set_move_shaper`` and ``~/shaper_at``).
    - ``motion_source``: the only publisher of the shaper's command inputs, the only client of its
      action and ``~/shape_trajectory``; it marks the cycles (``/cycle_events``).
    - ``recorder``: reads every topic of the table, publishes none of them.
    - ``controller``: ros2_control: reads the shaped commands, serves the controller's action,
      publishes joint states and the accelerometer, serves MRILC's ``~/set_feedforward`` and
      publishes the applied reference; its controller manager's services (and the spawner's
      calls to them) as patterns.

    Parameters
    ----------
    overrides : mapping of str to str, optional
        Keys of :data:`DEFAULT_NAMES` (node names, namespace, topics) to change.
    """
    n = names_with(overrides)
    ns = n["namespace"]

    def fqn(role: str) -> str:
        return node_fqn(ns, n[f"node.{role}"])

    shaper = fqn("shaper")
    scheduler = fqn("scheduler")

    def of_shaper(key: str) -> str:
        return resolve(n[key], ns, n["node.shaper"])

    commands_in = frozenset(of_shaper(f"topics.{k}") for k in ("array_in", "stream_in", "trajectory_in"))
    commands_out = frozenset(of_shaper(f"topics.{k}") for k in ("array_out", "stream_out", "trajectory_out"))
    shaper_action = of_shaper("action.server_name")
    controller_action = resolve(n["action.controller"], ns, "")
    joint_states, imu, events, reference, diagnostics = (
        resolve(n[f"topics.{k}"], ns, "") for k in ("joint_states", "imu", "cycle_events", "reference", "diagnostics"))
    set_get = frozenset({f"{shaper}/set_shaper", f"{shaper}/get_shaper"})
    feedforward = f"{resolve(n['mrilc.injection_target'], ns, '')}/set_feedforward"
    controller_nodes = tuple(node_fqn(ns, x) for x in n["node.controller"].split(",") if x.strip())
    if not controller_nodes:
        raise ValueError("node.controller must name at least one node")
    manager = controller_nodes[0]

    policy = {
        "shaper": Access(
            nodes=(shaper, f"{shaper}_trajectories"),
            publish=commands_out | {f"{shaper}/active_shaper", diagnostics},
            subscribe=commands_in,
            serve=set_get | {f"{shaper}/shape_trajectory"},
            call=frozenset({f"{scheduler}/shaper_at"}),
            serve_actions=frozenset({shaper_action}),
            call_actions=frozenset({controller_action})),
        "learner": Access(
            nodes=(fqn("learner"),),
            publish=frozenset({f"{fqn('learner')}/reports", diagnostics}),
            subscribe=frozenset({imu, events, joint_states, reference, f"{shaper}/active_shaper",
                                 f"{scheduler}/active_shaper"}),
            serve=frozenset({f"{fqn('learner')}/hold"}),
            call=set_get | {f"{scheduler}/set_shaper", f"{scheduler}/get_shaper", feedforward,
                            f"{scheduler}/set_move_shaper", f"{scheduler}/shaper_at"}),  # (list.per_move)
        "scheduler": Access(
            nodes=(scheduler,),
            publish=frozenset({f"{scheduler}/active_shaper", f"{scheduler}/mode_estimate", diagnostics}),
            subscribe=frozenset({joint_states, f"{shaper}/active_shaper"}),
            serve=frozenset({f"{scheduler}/set_shaper", f"{scheduler}/get_shaper", f"{scheduler}/shaper_at",
                             f"{scheduler}/set_move_shaper"}),
            call=set_get),
        "identifier": Access(
            nodes=(fqn("identifier"),),
            publish=frozenset({f"{fqn('identifier')}/mode_estimate", diagnostics}),
            subscribe=frozenset({imu, joint_states, events}),
            serve=frozenset({f"{fqn('identifier')}/identify"}),
            call=set_get),
        "calibrate": Access(
            nodes=(fqn("calibrate"),),
            subscribe=frozenset({imu, joint_states}),
            call=set_get,
            call_actions=frozenset({controller_action})),
        "motion_source": Access(
            nodes=(fqn("motion_source"),),
            publish=commands_in | {events},
            subscribe=frozenset({f"{shaper}/active_shaper"}),
            call=frozenset({f"{shaper}/shape_trajectory"}),
            call_actions=frozenset({shaper_action})),
        "controller": Access(
            nodes=controller_nodes,
            publish=frozenset({joint_states, imu, reference}),
            subscribe=commands_out,
            serve=frozenset({feedforward}),
            serve_actions=frozenset({controller_action}),
            # the controller manager's own services, served and called (by the spawner) in this enclave
            dds_publish=frozenset({f"rr{manager}/*", f"rq{manager}/*"}),
            dds_subscribe=frozenset({f"rq{manager}/*", f"rr{manager}/*"})),
    }
    every_topic: set[str] = set()
    for access in policy.values():
        every_topic |= access.publish | access.subscribe
    policy["recorder"] = Access(nodes=(fqn("recorder"),), subscribe=frozenset(every_topic),
                                serve=frozenset({f"{fqn('recorder')}/stop"}))
    return policy


def enclave_path(root: str, role: str) -> str:
    """The enclave path of ``role`` under ``root`` (``/shaper_suite/shaper``)."""
    root = "/" + _clean(root).strip("/")
    if root == "/":
        raise ValueError("the enclave root must not be '/'")
    if not role or "/" in role:
        raise ValueError(f"role {role!r} must be a non-empty name without '/'")
    return f"{root}/{role}"


def subject_name(enclave: str) -> str:
    """Certificate subject of an enclave, as the permissions name it (RFC 2253): ``CN=<path>``."""
    if any(c in enclave for c in ',+"\\<>;='):
        raise ValueError(f"enclave path {enclave!r} has a character that needs escaping in a subject name")
    return f"CN={enclave}"


def _domains(domains: tuple[int, int]) -> str:
    lo, hi = domains
    if not 0 <= lo <= hi <= 232:
        raise ValueError(f"domain range must be within 0..232 with min <= max, got {lo}..{hi}")
    return f"<domains><id_range><min>{lo}</min><max>{hi}</max></id_range></domains>"


def governance_xml(domains: tuple[int, int] = DEFAULT_DOMAINS) -> str:
    """Governance document: authenticated participants only, join and read/write access control on
    every topic, discovery and liveliness encrypted, RTPS messages signed, data encrypted."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      {_domains(domains)}
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"""


def _criteria(verb: Verb, topics: Iterable[str]) -> str:
    items = sorted(topics)
    if not items:
        return ""
    body = "\n".join(f"            <topic>{escape(t)}</topic>" for t in items)
    return f"        <{verb}>\n          <topics>\n{body}\n          </topics>\n        </{verb}>\n"


@dataclass(frozen=True)
class Validity:
    """When a grant holds (UTC, whole seconds)."""

    not_before: datetime
    not_after: datetime

    def __post_init__(self) -> None:
        if self.not_after <= self.not_before:
            raise ValueError(f"validity ends ({self.not_after}) before it begins ({self.not_before})")

    @staticmethod
    def text(t: datetime) -> str:
        return t.strftime("%Y-%m-%dT%H:%M:%S")


@dataclass(frozen=True)
class Decision:
    """How a permissions document answers one request: allowed or not, and which rule said so."""

    allowed: bool
    rule: str  # "allow_rule", "deny_rule" or "default"


def permissions_xml(enclave: str, access: Access, validity: Validity, denied: tuple[frozenset[str], frozenset[str]],
                    domains: tuple[int, int] = DEFAULT_DOMAINS) -> str:
    """Permissions document of ``enclave``: its grants (``access``), an explicit deny rule for
    ``denied`` (DDS topics to publish, to subscribe) and ``<default>DENY</default>``."""
    pub, sub = access.dds()

    def not_granted(candidates: frozenset[str], granted: frozenset[str]) -> frozenset[str]:
        return frozenset(t for t in candidates - granted if not any(fnmatch.fnmatchcase(t, p) for p in granted))

    deny_pub, deny_sub = not_granted(denied[0], pub), not_granted(denied[1], sub)
    deny = ""
    if deny_pub or deny_sub:
        deny = (f"      <deny_rule>\n        {_domains(domains)}\n"
                f"{_criteria('publish', deny_pub)}{_criteria('subscribe', deny_sub)}      </deny_rule>\n")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{escape(enclave)}">
      <subject_name>{escape(subject_name(enclave))}</subject_name>
      <validity>
        <not_before>{Validity.text(validity.not_before)}</not_before>
        <not_after>{Validity.text(validity.not_after)}</not_after>
      </validity>
      <allow_rule>
        {_domains(domains)}
{_criteria('publish', pub)}{_criteria('subscribe', sub)}      </allow_rule>
{deny}      <default>DENY</default>
    </grant>
  </permissions>
</dds>
"""


def with_grants(policy: Mapping[str, Access], grants: Iterable[tuple[str, Verb, str]]) -> dict[str, Access]:
    """``policy`` with extra DDS topics or patterns granted: ``(role, verb, dds_topic)`` each, for
    interfaces outside the suite (MoveIt's, a driver's). A pattern (``rt/move_group/*``) also
    lifts the role's explicit denials that it matches."""
    out = dict(policy)
    for role, verb, topic in grants:
        if role not in out:
            raise ValueError(f"unknown role {role!r}; roles: {', '.join(out)}")
        if verb not in ("publish", "subscribe"):
            raise ValueError(f"verb must be publish or subscribe, got {verb!r}")
        topic = topic.strip()
        if not topic or any(c.isspace() or c in "<>&" for c in topic):
            raise ValueError(f"{topic!r} is not a DDS topic name or pattern")
        a = out[role]
        if verb == "publish":
            out[role] = replace(a, dds_publish=a.dds_publish | {topic})
        else:
            out[role] = replace(a, dds_subscribe=a.dds_subscribe | {topic})
    return out


def suite_permissions(root: str, validity: Validity, policy: Mapping[str, Access] | None = None,
                      domains: tuple[int, int] = DEFAULT_DOMAINS) -> dict[str, str]:
    """Enclave path -> permissions document, for every role of ``policy`` (default
    :func:`suite_policy`) under ``root``. Each enclave's deny rule names every DDS topic the policy
    grants anyone (in either direction) that the enclave is not granted."""
    policy = suite_policy() if policy is None else policy
    grants = {role: access.dds() for role, access in policy.items()}
    every = frozenset().union(*(pub | sub for pub, sub in grants.values()))
    return {enclave_path(root, role): permissions_xml(enclave_path(root, role), access, validity, (every, every),
                                                      domains)
            for role, access in policy.items()}


@dataclass(frozen=True)
class ParsedGrant:
    """A grant read back from a permissions document (for checks and tests).

    ``rules`` lists, in document order, ``(kind, publish patterns, subscribe patterns, domains)``
    with kind ``"allow_rule"`` or ``"deny_rule"``.
    """

    name: str
    subject: str
    not_before: str
    not_after: str
    rules: tuple[tuple[str, frozenset[str], frozenset[str], tuple[int, int]], ...]
    default: str

    def decide(self, verb: Verb, topic: str, domain: int = 0) -> Decision:
        """What the builtin access control answers for ``verb`` on DDS ``topic``: the first rule
        whose domains hold ``domain`` and one of whose patterns (fnmatch) matches, else the default."""
        for kind, pub, sub, (lo, hi) in self.rules:
            patterns = pub if verb == "publish" else sub
            if lo <= domain <= hi and any(fnmatch.fnmatchcase(topic, p) for p in patterns):
                return Decision(kind == "allow_rule", kind)
        return Decision(self.default == "ALLOW", "default")


def parse_permissions(text: str) -> list[ParsedGrant]:
    """The grants of a permissions document; raises ``ValueError`` naming what is malformed."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"permissions document is not well-formed XML: {exc}") from None
    perms = root.find("permissions")
    if root.tag != "dds" or perms is None:
        raise ValueError("permissions document must be <dds><permissions>...")
    grants = []
    for g in perms.findall("grant"):
        def req(path: str, g: ET.Element = g) -> str:
            el = g.find(path)
            if el is None or el.text is None:
                raise ValueError(f"grant {g.get('name')!r} lacks <{path}>")
            return el.text.strip()

        rules = []
        for rule in g:
            if rule.tag not in ("allow_rule", "deny_rule"):
                continue
            lo = int(rule.findtext("domains/id_range/min", "0"))
            hi = int(rule.findtext("domains/id_range/max", str(lo)))
            pats = {v: frozenset((t.text or "").strip() for t in rule.findall(f"{v}/topics/topic"))
                    for v in ("publish", "subscribe")}
            rules.append((rule.tag, pats["publish"], pats["subscribe"], (lo, hi)))
        grants.append(ParsedGrant(name=g.get("name", ""), subject=req("subject_name"),
                                  not_before=req("validity/not_before"), not_after=req("validity/not_after"),
                                  rules=tuple(rules), default=req("default")))
    return grants
