"""Who may talk to whom on the suite's DDS domain: the SROS2 access policy, written once.

The shaper node's update policy (:mod:`.shaping.policy`) decides by the ``source`` a
``SetShaper`` request names: that is a label any caller can write, not an identity. On a plain
DDS domain anyone may call ``/shaper/set_shaper`` or publish on the shaper's command inputs.
Identity comes from SROS2: each process runs in an *enclave* (``--ros-args --enclave PATH``)
with a certificate whose subject is ``CN=<enclave path>`` and a signed ``permissions.xml`` that
DDS access control enforces (``ROS_SECURITY_ENABLE=true``, ``ROS_SECURITY_STRATEGY=Enforce``).

This package holds the policy table (:func:`suite_policy`: which enclave publishes and subscribes
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

Modules
-------
names
    ROS names and their DDS topics (the mangling below); :class:`Access`, what one enclave may do.
policy
    The policy table (:func:`suite_policy`) from the suite's names (:data:`DEFAULT_NAMES`), and extra grants
    (:func:`with_grants`).
documents
    The governance and permissions documents (:func:`governance_xml`, :func:`permissions_xml`,
    :func:`suite_permissions`) and permissions read back (:func:`parse_permissions`).
"""

from __future__ import annotations

from .documents import (
    DEFAULT_DOMAINS,
    DEFAULT_ROOT,
    Decision,
    ParsedGrant,
    Validity,
    enclave_path,
    governance_xml,
    parse_permissions,
    permissions_xml,
    subject_name,
    suite_permissions,
)
from .names import (
    ACTION_SERVICES,
    ACTION_TOPICS,
    DISCOVERY_TOPIC,
    PARAMETER_SERVICES,
    Access,
    Verb,
    node_fqn,
    resolve,
    service_dds,
    topic_dds,
)
from .policy import DEFAULT_NAMES, names_with, suite_policy, with_grants

__all__ = ["ACTION_SERVICES", "ACTION_TOPICS", "DEFAULT_DOMAINS", "DEFAULT_NAMES", "DEFAULT_ROOT", "DISCOVERY_TOPIC",
           "PARAMETER_SERVICES", "Access", "Decision", "ParsedGrant", "Validity", "Verb", "enclave_path",
           "governance_xml", "names_with", "node_fqn", "parse_permissions", "permissions_xml", "resolve",
           "service_dds", "subject_name", "suite_permissions", "suite_policy", "topic_dds", "with_grants"]
