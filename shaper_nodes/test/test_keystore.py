"""The SROS2 keystore that ``shaper_keystore`` writes, checked with openssl and by reading its XML.

Enforcement itself needs a DDS built with the security plugins (apt's ROS 2 on a robot, the Docker
image); the Fast DDS of the PyPI wheels here has none. So these tests check everything short of
it: the layout ``ros2 security`` writes, every signature (``openssl smime -verify``,
``openssl verify``), that the signed content is the XML file, that a tampered document fails,
that subjects match the certificates, and that each permissions document grants and denies exactly
what the policy says, the expectations written out by hand below.
"""

from __future__ import annotations

import fnmatch
import pathlib
import shutil
import subprocess
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta

import pytest

from shaper_nodes.cli import keystore as cli
from shaper_nodes.core import security
from shaper_nodes.core.learning.mrilc import DEFAULTS as MRILC_DEFAULTS
from shaper_nodes.core.security import parse_permissions, suite_policy

OPENSSL = shutil.which("openssl")
pytestmark = pytest.mark.skipif(OPENSSL is None, reason="openssl executable not found")

ROLES = ("shaper", "learner", "scheduler", "identifier", "calibrate", "motion_source", "controller", "recorder")
ENCLAVE_FILES = {"cert.pem", "key.pem", "identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s",
                 "permissions.xml", "permissions.p7s"}
SET_SHAPER_CALLERS = {"learner", "scheduler", "identifier", "calibrate"}
COMMAND_INPUTS = ("rt/shaper/commands", "rt/shaper/joint_trajectory_stream", "rt/shaper/joint_trajectory")


def ssl(*args: str | pathlib.Path) -> subprocess.CompletedProcess[str]:
    assert OPENSSL is not None
    return subprocess.run([OPENSSL, *map(str, args)], capture_output=True, text=True, check=False, timeout=60)


@pytest.fixture(scope="module")
def keystore(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    path = tmp_path_factory.mktemp("sros2") / "keystore"
    assert cli.main(["create", str(path)]) == 0
    return path


def enclave_dir(keystore: pathlib.Path, role: str) -> pathlib.Path:
    return keystore / "enclaves" / "shaper_suite" / role


def grant_of(keystore: pathlib.Path, role: str) -> security.ParsedGrant:
    (grant,) = parse_permissions((enclave_dir(keystore, role) / "permissions.xml").read_text())
    return grant


def signed_content(p7s: pathlib.Path, ca: pathlib.Path, out: pathlib.Path) -> subprocess.CompletedProcess[str]:
    """``openssl smime -verify`` of ``p7s`` against ``ca``; the signed text (text mode) goes to ``out``."""
    return ssl("smime", "-verify", "-text", "-in", p7s, "-CAfile", ca, "-out", out)


def crlf_to_lf(data: bytes) -> bytes:
    """S/MIME text mode signs the canonical form of the text, with CRLF line ends."""
    return data.replace(b"\r\n", b"\n")


# --- layout -----------------------------------------------------------------------------------

def test_layout_is_the_sros2_keystore(keystore: pathlib.Path) -> None:
    for folder, kind in (("public", "cert"), ("private", "key")):
        names = {p.name for p in (keystore / folder).iterdir()}
        assert names == {f"ca.{kind}.pem", f"identity_ca.{kind}.pem", f"permissions_ca.{kind}.pem"}
    assert {p.name for p in (keystore / "enclaves").iterdir()} == {"governance.xml", "governance.p7s", "shaper_suite"}
    assert {p.name for p in (keystore / "enclaves" / "shaper_suite").iterdir()} == set(ROLES)
    for role in ROLES:
        assert {p.name for p in enclave_dir(keystore, role).iterdir()} == ENCLAVE_FILES, role
    # private keys are readable by their owner only
    assert (keystore / "private" / "ca.key.pem").stat().st_mode & 0o077 == 0
    assert (enclave_dir(keystore, "shaper") / "key.pem").stat().st_mode & 0o077 == 0


def test_keys_are_ec_prime256v1(keystore: pathlib.Path) -> None:
    for key in (keystore / "private" / "ca.key.pem", enclave_dir(keystore, "learner") / "key.pem"):
        text = ssl("pkey", "-in", key, "-noout", "-text").stdout
        assert "prime256v1" in text or "P-256" in text, key


# --- signatures -------------------------------------------------------------------------------

@pytest.mark.parametrize("role", ROLES)
def test_every_signature_verifies_and_covers_the_file(keystore: pathlib.Path, role: str, tmp_path: pathlib.Path
                                                      ) -> None:
    folder = enclave_dir(keystore, role)
    perm_ca, id_ca = folder / "permissions_ca.cert.pem", folder / "identity_ca.cert.pem"
    for signed, plain in (("permissions.p7s", folder / "permissions.xml"),
                          ("governance.p7s", keystore / "enclaves" / "governance.xml")):
        proc = signed_content(folder / signed, perm_ca, tmp_path / "content")
        assert proc.returncode == 0, f"{role}/{signed}: {proc.stderr}"
        assert crlf_to_lf((tmp_path / "content").read_bytes()) == plain.read_bytes(), f"{role}/{signed}"
    proc = ssl("verify", "-CAfile", id_ca, folder / "cert.pem")
    assert proc.returncode == 0 and ": OK" in proc.stdout, proc.stdout + proc.stderr
    # the enclave's copies are the keystore's, and the shared governance signature is the same file
    assert (folder / "governance.p7s").read_bytes() == (keystore / "enclaves" / "governance.p7s").read_bytes()
    assert perm_ca.read_bytes() == (keystore / "public" / "ca.cert.pem").read_bytes()


def test_the_identity_certificate_is_not_a_ca(keystore: pathlib.Path) -> None:
    text = ssl("x509", "-in", enclave_dir(keystore, "shaper") / "cert.pem", "-noout", "-text").stdout
    assert "CA:FALSE" in text
    ca_text = ssl("x509", "-in", keystore / "public" / "ca.cert.pem", "-noout", "-text").stdout
    assert "CA:TRUE" in ca_text


def test_a_tampered_permissions_document_fails(keystore: pathlib.Path, tmp_path: pathlib.Path) -> None:
    folder = enclave_dir(keystore, "recorder")
    ca = folder / "permissions_ca.cert.pem"
    original = (folder / "permissions.p7s").read_text()
    # the recorder grants itself the shaper's command input inside the signed message
    marker = "<topic>rt/rosout</topic>"
    assert marker in original
    forged = tmp_path / "permissions.p7s"
    forged.write_text(original.replace(marker, marker + "\r\n            <topic>rt/shaper/commands</topic>", 1))
    proc = signed_content(forged, ca, tmp_path / "out")
    assert proc.returncode != 0
    assert "verif" in (proc.stderr + proc.stdout).lower()
    # an edited permissions.xml next to an intact signature: the signature no longer covers the file
    edited = (folder / "permissions.xml").read_text().replace(marker, marker + "<topic>rt/shaper/commands</topic>")
    assert signed_content(folder / "permissions.p7s", ca, tmp_path / "content").returncode == 0
    assert crlf_to_lf((tmp_path / "content").read_bytes()) != edited.encode()
    # and a document signed by another CA does not verify against the keystore's
    other = tmp_path / "other"
    assert cli.main(["create", str(other)]) == 0
    proc = signed_content(other / "enclaves" / "shaper_suite" / "recorder" / "permissions.p7s", ca, tmp_path / "o")
    assert proc.returncode != 0


# --- subjects and XML ---------------------------------------------------------------------------

@pytest.mark.parametrize("role", ROLES)
def test_subject_names_match_the_certificates(keystore: pathlib.Path, role: str) -> None:
    folder = enclave_dir(keystore, role)
    subject = ssl("x509", "-in", folder / "cert.pem", "-noout", "-subject", "-nameopt", "RFC2253").stdout.strip()
    grant = grant_of(keystore, role)
    assert subject == f"subject=CN=/shaper_suite/{role}"
    assert grant.subject == subject.removeprefix("subject=")
    assert grant.name == f"/shaper_suite/{role}"
    assert grant.default == "DENY"
    issuer = ssl("x509", "-in", folder / "cert.pem", "-noout", "-issuer", "-nameopt", "RFC2253").stdout.strip()
    assert issuer == "issuer=CN=sros2CA"
    # the grant holds from a day back (zone-less times read as local time) for the ten years of the certificate
    begin, end = datetime.fromisoformat(grant.not_before), datetime.fromisoformat(grant.not_after)
    assert timedelta(hours=14) < datetime.now(UTC).replace(tzinfo=None) - begin < timedelta(days=2)
    assert timedelta(days=3650) < end - begin < timedelta(days=3652)
    assert [r[0] for r in grant.rules] == ["allow_rule", "deny_rule"]
    assert all(r[3] == (0, 232) for r in grant.rules)


def test_documents_are_well_formed_dds_security_xml(keystore: pathlib.Path) -> None:
    gov = ET.parse(keystore / "enclaves" / "governance.xml").getroot()
    assert gov.tag == "dds"
    rule = gov.find("domain_access_rules/domain_rule")
    assert rule is not None
    assert rule.findtext("allow_unauthenticated_participants") == "false"
    assert rule.findtext("enable_join_access_control") == "true"
    # the element order of the DDS-Security schema, which Fast DDS's parsers require
    assert [c.tag for c in rule] == ["domains", "allow_unauthenticated_participants", "enable_join_access_control",
                                     "discovery_protection_kind", "liveliness_protection_kind",
                                     "rtps_protection_kind", "topic_access_rules"]
    topic_rule = rule.find("topic_access_rules/topic_rule")
    assert topic_rule is not None and topic_rule.findtext("topic_expression") == "*"
    assert [c.tag for c in topic_rule] == ["topic_expression", "enable_discovery_protection",
                                           "enable_liveliness_protection", "enable_read_access_control",
                                           "enable_write_access_control", "metadata_protection_kind",
                                           "data_protection_kind"]
    assert topic_rule.findtext("enable_read_access_control") == "true"
    assert topic_rule.findtext("enable_write_access_control") == "true"
    for role in ROLES:
        root = ET.parse(enclave_dir(keystore, role) / "permissions.xml").getroot()
        grants = root.findall("permissions/grant")
        assert len(grants) == 1
        children = [c.tag for c in grants[0]]
        assert children == ["subject_name", "validity", "allow_rule", "deny_rule", "default"], role
        for rule_el in grants[0].findall("allow_rule") + grants[0].findall("deny_rule"):
            assert rule_el[0].tag == "domains"
            assert {c.tag for c in rule_el[1:]} <= {"publish", "subscribe"}


# --- grants and denials -------------------------------------------------------------------------

def allowed(keystore: pathlib.Path, verb: security.Verb, topic: str) -> set[str]:
    return {role for role in ROLES if grant_of(keystore, role).decide(verb, topic).allowed}


def test_only_the_four_updaters_may_call_set_shaper(keystore: pathlib.Path) -> None:
    assert allowed(keystore, "publish", "rq/shaper/set_shaperRequest") == SET_SHAPER_CALLERS
    assert allowed(keystore, "subscribe", "rr/shaper/set_shaperReply") == SET_SHAPER_CALLERS
    assert allowed(keystore, "subscribe", "rq/shaper/set_shaperRequest") == {"shaper"}
    assert allowed(keystore, "publish", "rr/shaper/set_shaperReply") == {"shaper"}
    for role in ("motion_source", "recorder", "controller", "shaper"):
        decision = grant_of(keystore, role).decide("publish", "rq/shaper/set_shaperRequest")
        assert decision == security.Decision(False, "deny_rule"), role


def test_only_the_motion_source_may_publish_commands(keystore: pathlib.Path) -> None:
    for topic in COMMAND_INPUTS:
        assert allowed(keystore, "publish", topic) == {"motion_source"}, topic
        assert allowed(keystore, "subscribe", topic) == {"shaper", "recorder"}, topic
    goal = "rq/shaper/follow_joint_trajectory/_action/send_goalRequest"
    assert allowed(keystore, "publish", goal) == {"motion_source"}
    assert allowed(keystore, "subscribe", goal) == {"shaper"}
    assert allowed(keystore, "publish", "rq/shaper/shape_trajectoryRequest") == {"motion_source"}


def test_only_the_shaper_feeds_the_controller(keystore: pathlib.Path) -> None:
    for topic in ("rt/forward_position_controller/commands", "rt/joint_trajectory_controller/joint_trajectory",
                  "rt/shaper/active_shaper"):
        assert allowed(keystore, "publish", topic) == {"shaper"}, topic
    assert allowed(keystore, "publish", "rq/joint_trajectory_controller/follow_joint_trajectory/_action/"
                                        "send_goalRequest") == {"shaper", "calibrate"}
    assert allowed(keystore, "subscribe", "rt/forward_position_controller/commands") == {"controller", "recorder"}
    assert allowed(keystore, "publish", "rt/joint_states") == {"controller"}


def test_ros_internals_for_everyone_parameters_for_nobody_else(keystore: pathlib.Path) -> None:
    everyone = set(ROLES)
    assert allowed(keystore, "publish", "rt/rosout") == everyone
    assert allowed(keystore, "publish", "rt/parameter_events") == everyone
    assert allowed(keystore, "subscribe", "rt/parameter_events") == everyone
    assert allowed(keystore, "publish", "ros_discovery_info") == everyone
    assert allowed(keystore, "subscribe", "ros_discovery_info") == everyone
    # each node serves its own parameter services; nobody may set the shaper's parameters
    assert allowed(keystore, "subscribe", "rq/shaper/set_parametersRequest") == {"shaper"}
    assert allowed(keystore, "publish", "rr/shaper/set_parametersReply") == {"shaper"}
    assert allowed(keystore, "publish", "rq/shaper/set_parametersRequest") == set()
    assert allowed(keystore, "subscribe", "rq/learner/get_parametersRequest") == {"learner"}
    # nobody in the suite reads the logs, and a topic the table does not name is denied by default
    assert allowed(keystore, "subscribe", "rt/rosout") == set()
    for role in ROLES:
        assert grant_of(keystore, role).decide("publish", "rt/unknown/topic") == security.Decision(False, "default")


def test_the_recorder_reads_everything_and_writes_nothing_of_the_suite(keystore: pathlib.Path) -> None:
    grant = grant_of(keystore, "recorder")
    every_topic = set().union(*(a.publish | a.subscribe for a in suite_policy().values()))
    for topic in every_topic:
        assert grant.decide("subscribe", security.topic_dds(topic)).allowed, topic
        assert not grant.decide("publish", security.topic_dds(topic)).allowed, topic


def test_each_document_is_exactly_the_table(keystore: pathlib.Path) -> None:
    """Every DDS name the table grants a role is allowed by its document; every other name the
    table uses is denied by its explicit deny rule (or, for names another role reaches only
    by a pattern, by the default)."""
    grants = {role: access.dds() for role, access in suite_policy().items()}
    names = set().union(*(pub | sub for pub, sub in grants.values()))
    for role, (pub, sub) in grants.items():
        grant = grant_of(keystore, role)
        for verb, mine in (("publish", pub), ("subscribe", sub)):
            for name in names:
                decision = grant.decide(verb, name)  # type: ignore[arg-type]
                granted = name in mine or any(fnmatch.fnmatchcase(name, p) for p in mine)
                assert decision.allowed == granted, (role, verb, name, decision)


# --- names, options and the CLI ---------------------------------------------------------------

def test_default_names_are_the_nodes_defaults() -> None:
    from shaper_nodes.nodes import calibrate, identifier, learner, learner_list, scheduler, shaper

    def defaults(params: tuple) -> dict[str, object]:  # type: ignore[type-arg]
        return {p.name: p.default for p in params}

    names = security.DEFAULT_NAMES
    for key, value in shaper.TOPICS.items():
        assert names[f"topics.{key}"] == value
    sh = defaults(shaper.PARAMETERS)
    assert names["action.server_name"] == sh["action.server_name"]
    assert names["action.controller"] == sh["action.controller"]
    assert defaults(calibrate.PARAMETERS)["action"] == names["action.controller"]
    ident = defaults(identifier.PARAMETERS)
    for key in ("imu", "joint_states", "cycle_events"):
        assert ident[f"topics.{key}"] == names[f"topics.{key}"]
        assert defaults(calibrate.PARAMETERS).get(f"topics.{key}", names[f"topics.{key}"]) == names[f"topics.{key}"]
    lst = defaults(learner_list.PARAMETERS)
    assert lst["topics.imu"] == names["topics.imu"] and lst["topics.cycle_events"] == names["topics.cycle_events"]
    assert MRILC_DEFAULTS["topics.reference"] == names["topics.reference"]
    assert MRILC_DEFAULTS["topics.joint_states"] == names["topics.joint_states"]
    assert MRILC_DEFAULTS["mrilc.injection_target"] == names["mrilc.injection_target"]
    assert defaults(scheduler.PARAMETERS)["joint_states"] == names["topics.joint_states"]
    for params in (learner.PARAMETERS, scheduler.PARAMETERS, identifier.PARAMETERS):
        assert defaults(params)["shaper"] == "/" + names["node.shaper"]


def test_namespace_and_node_names_follow_the_options(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "ks"
    assert cli.main(["create", str(path), "--root", "/cell7", "--namespace", "/arm", "--shaper-name", "arm_shaper",
                     "--node", "learner=list_learner", "--name", "topics.stream_in=/servo/out",
                     "--domains", "7"]) == 0
    folder = path / "enclaves" / "cell7"
    assert {p.name for p in folder.iterdir()} == set(ROLES)

    def grant(role: str) -> security.ParsedGrant:
        (g,) = parse_permissions((folder / role / "permissions.xml").read_text())
        return g

    assert grant("learner").decide("publish", "rq/arm/arm_shaper/set_shaperRequest", 7).allowed
    assert not grant("learner").decide("publish", "rq/arm/arm_shaper/set_shaperRequest", 8).allowed
    assert not grant("learner").decide("publish", "rq/shaper/set_shaperRequest", 7).allowed
    assert grant("learner").decide("subscribe", "rq/arm/list_learner/holdRequest", 7).allowed
    assert grant("motion_source").decide("publish", "rt/arm/arm_shaper/commands", 7).allowed
    assert grant("motion_source").decide("publish", "rt/servo/out", 7).allowed
    assert grant("shaper").decide("subscribe", "rt/servo/out", 7).allowed
    assert grant("shaper").subject == "CN=/cell7/shaper"
    subject = ssl("x509", "-in", folder / "shaper" / "cert.pem", "-noout", "-subject", "-nameopt", "RFC2253").stdout
    assert subject.strip() == "subject=CN=/cell7/shaper"


def test_extra_grants_for_interfaces_outside_the_suite(tmp_path: pathlib.Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ks"
    assert cli.main(["create", str(path), "--grant", "motion_source:publish:rt/move_group/*",
                     "--grant", "motion_source:subscribe:rt/monitored_planning_scene"]) == 0
    (grant,) = parse_permissions((enclave_dir(path, "motion_source") / "permissions.xml").read_text())
    assert grant.decide("publish", "rt/move_group/display_planned_path").allowed
    assert grant.decide("subscribe", "rt/monitored_planning_scene").allowed
    assert not grant.decide("publish", "rq/shaper/set_shaperRequest").allowed
    (other,) = parse_permissions((enclave_dir(path, "learner") / "permissions.xml").read_text())
    assert not other.decide("publish", "rt/move_group/display_planned_path").allowed
    assert cli.main(["create", str(path), "--grant", "robot:publish:rt/x"]) == 2
    assert "unknown role 'robot'" in capsys.readouterr().err
    assert cli.main(["create", str(path), "--grant", "learner:write:rt/x"]) == 2
    assert "publish or subscribe" in capsys.readouterr().err


def test_a_second_run_keeps_the_ca_and_identities_and_re_signs(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "ks"
    assert cli.main(["create", str(path)]) == 0
    ca = (path / "public" / "ca.cert.pem").read_bytes()
    cert = (enclave_dir(path, "shaper") / "cert.pem").read_bytes()
    (enclave_dir(path, "shaper") / "permissions.xml").write_text("tampered")
    assert cli.main(["create", str(path), "--shaper-name", "shaper"]) == 0
    assert (path / "public" / "ca.cert.pem").read_bytes() == ca
    assert (enclave_dir(path, "shaper") / "cert.pem").read_bytes() == cert
    assert parse_permissions((enclave_dir(path, "shaper") / "permissions.xml").read_text())[0].name


def test_help_and_bad_input_write_nothing(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    for argv in (["--help"], ["create", "--help"], ["policy", "--help"]):
        assert cli.main(argv) == 0
        assert "usage: shaper_keystore" in capsys.readouterr().out
    assert cli.main(["create", "ks", "--name", "topics.nope=/x"]) == 2
    err = capsys.readouterr().err
    assert "unknown name 'topics.nope'" in err and "topics.array_in" in err
    assert cli.main(["create", "ks", "--domains", "300"]) == 2
    assert "0..232" in capsys.readouterr().err
    assert cli.main(["create", "ks", "--shaper-name", "a/b"]) == 2
    assert "must not contain '/'" in capsys.readouterr().err
    # a wildcard in a name would widen the grant: refused
    assert cli.main(["create", "ks", "--name", "topics.array_in=/arm/*"]) == 2
    assert "not a valid ROS name" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert cli.main(["policy"]) == 0
    out = capsys.readouterr().out
    assert "/shaper_suite/learner" in out and "/shaper/set_shaper" in out
    assert list(tmp_path.iterdir()) == []


def test_missing_openssl_is_named(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("OPENSSL", str(tmp_path / "no-openssl"))
    assert cli.main(["create", str(tmp_path / "ks")]) == 2
    assert "openssl" in capsys.readouterr().err
