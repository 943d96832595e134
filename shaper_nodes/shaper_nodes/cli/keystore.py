"""``shaper_keystore``: the suite's SROS2 keystore, made with ``openssl`` (no sros2 needed).

``shaper_keystore create KEYSTORE`` writes the layout that ``ros2 security create_keystore`` and
``create_enclave`` write in Jazzy::

    KEYSTORE/public/ca.cert.pem                 the CA certificate (EC prime256v1, self-signed)
    KEYSTORE/public/{identity,permissions}_ca.cert.pem -> ca.cert.pem
    KEYSTORE/private/ca.key.pem                 the CA key (mode 0600; keep it off the robot)
    KEYSTORE/private/{identity,permissions}_ca.key.pem -> ca.key.pem
    KEYSTORE/enclaves/governance.xml, governance.p7s
    KEYSTORE/enclaves/<root>/<role>/            one enclave per role of the policy:
        cert.pem, key.pem                       identity (subject CN=<enclave path>, signed by the CA)
        identity_ca.cert.pem, permissions_ca.cert.pem, governance.p7s
        permissions.xml, permissions.p7s        the role's grants (core/security.py), signed

Documents are signed as S/MIME in text mode (``openssl smime -sign -text``, SHA-256, detached),
as sros2 signs them. An existing CA and existing enclave identities are kept (so enclaves can be
re-issued with a new policy without re-keying); the governance and the permissions are always
written anew. ``shaper_keystore policy`` prints the policy table and writes nothing.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import secrets
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime, timedelta
from typing import cast

from shaper_nodes.core.security import (
    DEFAULT_DOMAINS,
    DEFAULT_NAMES,
    DEFAULT_ROOT,
    Access,
    Validity,
    Verb,
    enclave_path,
    governance_xml,
    suite_permissions,
    suite_policy,
    with_grants,
)

from .common import Parser, UsageError, run, text_table

PROG = "shaper_keystore"
CA_SUBJECT = "sros2CA"
#: openssl configuration: the CA's and the enclaves' certificate extensions
_CONFIG = """\
[req]
distinguished_name = dn
prompt = no
[dn]
CN = {cn}
[ca_ext]
basicConstraints = critical, CA:TRUE
keyUsage = critical, keyCertSign, cRLSign, digitalSignature
subjectKeyIdentifier = hash
[enclave_ext]
basicConstraints = critical, CA:FALSE
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid
"""


class KeystoreError(ValueError):
    """openssl failed or the keystore is not usable; the message says which step and why."""


def openssl_path() -> str:
    """The openssl executable (``OPENSSL`` environment variable, else on PATH)."""
    given = os.environ.get("OPENSSL")
    exe = shutil.which(given) if given else shutil.which("openssl")
    if not exe:
        raise KeystoreError(f"openssl not found ({'OPENSSL=' + given if given else 'not on PATH'}): install it"
                            " (apt install openssl) or set OPENSSL to its path")
    return exe


def openssl(*args: str | pathlib.Path, stdin: str | None = None) -> str:
    """Run ``openssl ARGS``; return its stdout or raise :class:`KeystoreError` with its stderr."""
    cmd = [openssl_path(), *map(str, args)]
    proc = subprocess.run(cmd, input=stdin, capture_output=True, text=True, check=False, timeout=60)
    if proc.returncode != 0:
        raise KeystoreError(f"`openssl {' '.join(map(str, args[:2]))} ...` failed ({proc.returncode}): "
                            f"{proc.stderr.strip() or proc.stdout.strip()}")
    return proc.stdout


def _config(tmp: pathlib.Path, cn: str) -> pathlib.Path:
    if any(c in cn for c in "\n\r$"):
        raise KeystoreError(f"subject {cn!r} has a character openssl's configuration cannot hold")
    path = tmp / f"{secrets.token_hex(4)}.cnf"
    path.write_text(_CONFIG.format(cn=cn))
    return path


def _new_key(path: pathlib.Path) -> None:
    openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-out", path)
    path.chmod(0o600)


def _serial() -> str:
    return "0x" + secrets.token_hex(16)


def _days(validity: Validity) -> str:
    return str(max(1, (validity.not_after - validity.not_before).days))


def make_ca(keystore: pathlib.Path, validity: Validity, tmp: pathlib.Path) -> bool:
    """Create the CA in ``keystore/public`` and ``keystore/private`` unless it exists; True if made."""
    public, private = keystore / "public", keystore / "private"
    cert, key = public / "ca.cert.pem", private / "ca.key.pem"
    if cert.exists() != key.exists():
        raise KeystoreError(f"{cert} and {key} must both exist or both be absent (a half keystore)")
    made = False
    if not cert.exists():
        public.mkdir(parents=True, exist_ok=True)
        private.mkdir(parents=True, exist_ok=True)
        private.chmod(0o700)
        _new_key(key)
        openssl("req", "-x509", "-new", "-key", key, "-config", _config(tmp, CA_SUBJECT), "-extensions", "ca_ext",
                "-days", _days(validity), "-sha256", "-set_serial", _serial(), "-out", cert)
        made = True
    for folder, target in ((public, "ca.cert.pem"), (private, "ca.key.pem")):
        for kind in ("identity_ca", "permissions_ca"):
            link = folder / target.replace("ca", kind, 1)
            if not link.exists() and not link.is_symlink():
                link.symlink_to(target)
    return made


def sign(keystore: pathlib.Path, document: pathlib.Path, out: pathlib.Path) -> None:
    """Sign ``document`` with the permissions CA: S/MIME, text mode, SHA-256 (as sros2 does)."""
    openssl("smime", "-sign", "-text", "-md", "sha256", "-in", document, "-out", out,
            "-signer", keystore / "public" / "permissions_ca.cert.pem",
            "-inkey", keystore / "private" / "permissions_ca.key.pem")


def make_identity(keystore: pathlib.Path, folder: pathlib.Path, enclave: str, validity: Validity,
                  tmp: pathlib.Path) -> bool:
    """The enclave's key and certificate (subject ``CN=<enclave>``, signed by the identity CA),
    unless both exist; True if made."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    if cert.exists() and key.exists():
        return False
    _new_key(key)
    conf = _config(tmp, enclave)
    csr = tmp / "request.csr"
    openssl("req", "-new", "-key", key, "-config", conf, "-out", csr)
    openssl("x509", "-req", "-in", csr, "-CA", keystore / "public" / "identity_ca.cert.pem",
            "-CAkey", keystore / "private" / "identity_ca.key.pem", "-set_serial", _serial(),
            "-days", _days(validity), "-sha256", "-extfile", conf, "-extensions", "enclave_ext", "-out", cert)
    return True


def create(keystore: pathlib.Path, root: str = DEFAULT_ROOT, policy: Mapping[str, Access] | None = None,
           domains: tuple[int, int] = DEFAULT_DOMAINS, days: int = 3650, now: datetime | None = None) -> list[str]:
    """Write (or update) the keystore; returns what was done, one line each.

    Parameters
    ----------
    keystore : Path
        The keystore folder (created if absent).
    root : str
        Enclave folder of the suite (``/shaper_suite``).
    policy : mapping of role to Access, optional
        The access policy (default: :func:`~shaper_nodes.core.security.suite_policy` with the default names).
    domains : (int, int)
        ROS domain ids covered (inclusive).
    days : int
        Validity of new certificates and of the permissions, days from ``now`` (the permissions hold
        from a day before ``now``, whatever the robot's time zone).
    now : datetime, optional
        Start of the validity (UTC; default: now).
    """
    if days < 1:
        raise KeystoreError(f"--days must be at least 1, got {days}")
    start = (now or datetime.now(UTC)).replace(microsecond=0, tzinfo=None)
    # The permissions' times have no zone, and DDS implementations read them as local time (Fast DDS:
    # mktime): a robot west of UTC would see a grant starting "now" in UTC as starting hours ahead.
    # So the grant starts a day early; the certificates' times are UTC and start now.
    validity = Validity(start - timedelta(days=1), start + timedelta(days=days))
    permissions = suite_permissions(root, validity, policy, domains)  # checks the names before any file
    openssl_path()
    done = []
    keystore.mkdir(parents=True, exist_ok=True)
    enclaves = keystore / "enclaves"
    enclaves.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="shaper_keystore_") as tmp_name:
        tmp = pathlib.Path(tmp_name)
        done.append(("created" if make_ca(keystore, validity, tmp) else "kept") + f" CA {keystore / 'public'}")
        gov = enclaves / "governance.xml"
        gov.write_text(governance_xml(domains))
        sign(keystore, gov, enclaves / "governance.p7s")
        done.append(f"signed {gov}")
        for enclave, text in permissions.items():
            folder = enclaves / enclave.strip("/")
            folder.mkdir(parents=True, exist_ok=True)
            made = make_identity(keystore, folder, enclave, validity, tmp)
            for name in ("identity_ca.cert.pem", "permissions_ca.cert.pem"):
                shutil.copyfile(keystore / "public" / name, folder / name)
            shutil.copyfile(enclaves / "governance.p7s", folder / "governance.p7s")
            (folder / "permissions.xml").write_text(text)
            sign(keystore, folder / "permissions.xml", folder / "permissions.p7s")
            done.append(f"{'created' if made else 'kept'} identity and signed permissions of {enclave}")
    return done


def _pairs(values: Sequence[str] | None, what: str) -> dict[str, str]:
    out = {}
    for item in values or ():
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"{what} takes KEY=VALUE, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def _overrides(args: argparse.Namespace) -> dict[str, str]:
    names = {f"node.{k}": v for k, v in _pairs(args.node, "--node").items()}
    names.update(_pairs(args.name, "--name"))
    if args.namespace is not None:
        names["namespace"] = args.namespace
    if args.shaper_name is not None:
        names["node.shaper"] = args.shaper_name
    return names


def _policy(args: argparse.Namespace) -> dict[str, Access]:
    grants = []
    for item in args.grant or ():
        role, verb, topic = [*item.split(":", 2), "", ""][:3]
        if not topic:
            raise UsageError(f"--grant takes ROLE:VERB:DDS_TOPIC, got {item!r}")
        grants.append((role, cast(Verb, verb), topic))  # with_grants checks the verb
    return with_grants(suite_policy(_overrides(args)), grants)


def _cmd_create(args: argparse.Namespace) -> str:
    lo, _, hi = args.domains.partition("-")
    try:
        domains = (int(lo), int(hi or lo))
    except ValueError:
        raise UsageError(f"--domains takes MIN-MAX or ID, got {args.domains!r}") from None
    lines = create(pathlib.Path(args.keystore), args.root, _policy(args), domains, args.days)
    return "\n".join([*lines, f"export ROS_SECURITY_KEYSTORE={pathlib.Path(args.keystore).resolve()}"])


def _cmd_policy(args: argparse.Namespace) -> str:
    rows = []
    for role, access in _policy(args).items():
        enclave = enclave_path(args.root, role)
        for what, items in (("publish", access.publish), ("subscribe", access.subscribe),
                            ("serve", access.serve), ("call", access.call),
                            ("serve action", access.serve_actions), ("call action", access.call_actions),
                            ("dds publish", access.dds_publish), ("dds subscribe", access.dds_subscribe)):
            rows += [(enclave, what, name) for name in sorted(items)]
    note = ("Every enclave also publishes /rosout and /parameter_events, reads /parameter_events and /clock, "
            "and serves its own nodes' parameter services; everything else is denied.")
    return text_table(("enclave", "may", "name"), rows, (False, False, False)) + "\n" + note


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog=PROG, description="The suite's SROS2 keystore: a CA, one enclave per node with signed "
                    "permissions from the policy table (docs/guide/security.md), made with openssl.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    def names(p: argparse.ArgumentParser) -> None:
        p.add_argument("--root", default=DEFAULT_ROOT, help="enclave folder of the suite (default %(default)s)")
        p.add_argument("--namespace", default=None, help="ROS namespace of the suite's nodes (default /)")
        p.add_argument("--shaper-name", default=None, help="the shaper node's name (default shaper)")
        p.add_argument("--node", action="append", metavar="ROLE=NAME",
                       help="another role's node name, e.g. scheduler=arm_scheduler (controller: a comma list, the "
                            "controller manager first); repeatable")
        p.add_argument("--name", action="append", metavar="KEY=VALUE",
                       help="any name of the table, e.g. topics.array_in=/arm/commands; keys: "
                            + ", ".join(k for k in DEFAULT_NAMES if not k.startswith("node.")) + "; repeatable")
        p.add_argument("--grant", action="append", metavar="ROLE:VERB:DDS_TOPIC",
                       help="grant a role an interface outside the suite, as a DDS topic or fnmatch pattern, e.g. "
                            "motion_source:publish:rt/move_group/* (VERB: publish or subscribe); repeatable")

    create_p = sub.add_parser("create", help="write or update the keystore")
    create_p.add_argument("keystore", help="keystore folder (ROS_SECURITY_KEYSTORE), created if absent")
    names(create_p)
    create_p.add_argument("--domains", default=f"{DEFAULT_DOMAINS[0]}-{DEFAULT_DOMAINS[1]}",
                          help="ROS domain ids covered, MIN-MAX or one ID (default %(default)s)")
    create_p.add_argument("--days", type=int, default=3650,
                          help="validity of new certificates and of the permissions, days (default %(default)s)")
    policy_p = sub.add_parser("policy", help="print the policy table, write nothing")
    names(policy_p)
    return parser


COMMANDS = {"create": _cmd_create, "policy": _cmd_policy}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (0 ok, 2 bad input or openssl failure)."""
    return run(PROG, build_parser(), COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
