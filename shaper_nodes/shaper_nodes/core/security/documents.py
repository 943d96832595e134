"""The governance and permissions documents of OMG DDS-Security 1.1 (the builtin access control plugin's
XML) for the suite's enclaves, and permissions read back (:func:`parse_permissions`)."""

from __future__ import annotations

import fnmatch
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import datetime
from xml.sax.saxutils import escape

from .names import Access, Verb, _clean
from .policy import suite_policy

__all__ = ["DEFAULT_DOMAINS", "DEFAULT_ROOT", "Decision", "ParsedGrant", "Validity", "enclave_path", "governance_xml",
           "parse_permissions", "permissions_xml", "subject_name", "suite_permissions"]


#: the enclave folder the suite's enclaves live under
DEFAULT_ROOT = "/shaper_suite"


#: ROS domain ids covered by the governance and the permissions (inclusive); ROS 2 uses 0-232
DEFAULT_DOMAINS = (0, 232)


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
