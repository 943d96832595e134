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
        permissions.xml, permissions.p7s        the role's grants (core/security/), signed

Documents are signed as S/MIME in text mode (``openssl smime -sign -text``, SHA-256, detached),
as sros2 signs them. An existing CA and existing enclave identities are kept (so enclaves can be
re-issued with a new policy without re-keying); the governance and the permissions are always
written anew. ``shaper_keystore policy`` prints the policy table and writes nothing.

The keystore holds private keys, so it is written as such whatever the umask: every folder 0700,
every key 0600, certificates and documents 0644. Nothing inside it is followed through a symbolic
link (a planted link would make ``create`` overwrite its target): a link where a file or folder is
expected is refused, naming it; only the CA's alias links ``{identity,permissions}_ca.*.pem`` are
links, and they must point at ``ca.cert.pem`` / ``ca.key.pem`` beside them. Files are written to a new
name in their folder and renamed into place (a rename replaces a path, it never writes through it).
An existing keystore whose folders or keys have wider modes is repaired, and each repair is listed
in what ``create`` prints.
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


DIR_MODE = 0o700   # every folder of the keystore
KEY_MODE = 0o600   # private keys
FILE_MODE = 0o644  # certificates, governance, permissions and their signatures


class _Tree:
    """Writes inside the keystore without following links, with set modes; collects the repairs made."""

    def __init__(self) -> None:
        self.repaired: list[str] = []

    @staticmethod
    def no_link(path: pathlib.Path) -> None:
        if path.is_symlink():
            raise KeystoreError(f"{path} is a symbolic link (to {os.readlink(path)}): the keystore follows no link;"
                                " remove it (or pass the real folder) and run again")

    def mode(self, path: pathlib.Path, mode: int) -> None:
        """Check ``path`` is no link and set its mode, noting a repair when it was other."""
        self.no_link(path)
        old = path.lstat().st_mode & 0o777
        if old != mode:
            try:
                path.chmod(mode)
            except OSError as exc:
                raise KeystoreError(f"{path} has mode {old:04o} and cannot be set to {mode:04o}:"
                                    f" {exc.strerror}") from None
            self.repaired.append(f"repaired mode of {path}: {old:04o} -> {mode:04o}")

    def folder(self, path: pathlib.Path) -> None:
        """Make ``path`` (and missing parents inside the keystore) a folder of mode 0700."""
        self.no_link(path)
        if not path.exists():
            if path.parent != path and not path.parent.exists():
                self.folder(path.parent)
            path.mkdir(mode=DIR_MODE)
            path.chmod(DIR_MODE)  # the umask may have taken bits away; never adds any here
        elif not path.is_dir():
            raise KeystoreError(f"{path} is not a folder")
        self.mode(path, DIR_MODE)

    @staticmethod
    def scratch(dst: pathlib.Path) -> pathlib.Path:
        """A new, unused path beside ``dst`` for a file to be renamed onto it."""
        return dst.parent / f".{dst.name}.{secrets.token_hex(6)}.tmp"

    def install(self, tmp: pathlib.Path, dst: pathlib.Path, mode: int) -> None:
        """Give ``tmp`` (beside ``dst``) its mode and rename it onto ``dst``."""
        self.no_link(dst)
        tmp.chmod(mode)
        os.replace(tmp, dst)

    def write(self, dst: pathlib.Path, data: bytes, mode: int = FILE_MODE) -> None:
        tmp = self.scratch(dst)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            self.install(tmp, dst, mode)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise

    def openssl_out(self, dst: pathlib.Path, mode: int, *args: str | pathlib.Path) -> None:
        """Run ``openssl ARGS -out <new path>`` and install what it wrote as ``dst``."""
        self.no_link(dst)
        tmp = self.scratch(dst)
        try:
            openssl(*args, "-out", tmp)
            self.install(tmp, dst, mode)
        finally:
            tmp.unlink(missing_ok=True)

    def alias(self, link: pathlib.Path, target: str) -> None:
        """The CA alias ``link`` -> ``target`` (a name in the same folder): made, or checked."""
        if link.is_symlink():
            if os.readlink(link) != target:
                raise KeystoreError(f"{link} points at {os.readlink(link)}, not {target}: refusing a CA alias that"
                                    " leads elsewhere; remove it and run again")
        elif link.exists():
            raise KeystoreError(f"{link} should be a link to {target} and is a file; remove it and run again")
        else:
            link.symlink_to(target)


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


def _new_key(tree: _Tree, path: pathlib.Path) -> None:
    tree.openssl_out(path, KEY_MODE, "genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:prime256v1")


def _serial() -> str:
    return "0x" + secrets.token_hex(16)


def _days(validity: Validity) -> str:
    return str(max(1, (validity.not_after - validity.not_before).days))


def make_ca(tree: _Tree, keystore: pathlib.Path, validity: Validity, tmp: pathlib.Path) -> bool:
    """Create the CA in ``keystore/public`` and ``keystore/private`` unless it exists; True if made."""
    public, private = keystore / "public", keystore / "private"
    tree.folder(public)
    tree.folder(private)
    cert, key = public / "ca.cert.pem", private / "ca.key.pem"
    tree.no_link(cert)
    tree.no_link(key)
    if cert.exists() != key.exists():
        raise KeystoreError(f"{cert} and {key} must both exist or both be absent (a half keystore)")
    made = False
    if not cert.exists():
        _new_key(tree, key)
        tree.openssl_out(cert, FILE_MODE, "req", "-x509", "-new", "-key", key, "-config", _config(tmp, CA_SUBJECT),
                         "-extensions", "ca_ext", "-days", _days(validity), "-sha256", "-set_serial", _serial())
        made = True
    tree.mode(cert, FILE_MODE)
    tree.mode(key, KEY_MODE)
    for folder, target in ((public, "ca.cert.pem"), (private, "ca.key.pem")):
        for kind in ("identity_ca", "permissions_ca"):
            tree.alias(folder / target.replace("ca", kind, 1), target)
    return made


def sign(tree: _Tree, keystore: pathlib.Path, document: pathlib.Path, out: pathlib.Path) -> None:
    """Sign ``document`` with the permissions CA: S/MIME, text mode, SHA-256 (as sros2 does)."""
    tree.no_link(document)
    tree.openssl_out(out, FILE_MODE, "smime", "-sign", "-text", "-md", "sha256", "-in", document,
                     "-signer", keystore / "public" / "permissions_ca.cert.pem",
                     "-inkey", keystore / "private" / "permissions_ca.key.pem")


def make_identity(tree: _Tree, keystore: pathlib.Path, folder: pathlib.Path, enclave: str, validity: Validity,
                  tmp: pathlib.Path) -> bool:
    """The enclave's key and certificate (subject ``CN=<enclave>``, signed by the identity CA),
    unless both exist; True if made."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    tree.no_link(cert)
    tree.no_link(key)
    if cert.exists() and key.exists():
        tree.mode(cert, FILE_MODE)
        tree.mode(key, KEY_MODE)
        return False
    _new_key(tree, key)
    conf = _config(tmp, enclave)
    csr = tmp / "request.csr"
    openssl("req", "-new", "-key", key, "-config", conf, "-out", csr)
    tree.openssl_out(cert, FILE_MODE, "x509", "-req", "-in", csr, "-CA", keystore / "public" / "identity_ca.cert.pem",
                     "-CAkey", keystore / "private" / "identity_ca.key.pem", "-set_serial", _serial(),
                     "-days", _days(validity), "-sha256", "-extfile", conf, "-extensions", "enclave_ext")
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
    tree = _Tree()
    tree.folder(keystore)
    enclaves = keystore / "enclaves"
    tree.folder(enclaves)
    with tempfile.TemporaryDirectory(prefix="shaper_keystore_") as tmp_name:
        tmp = pathlib.Path(tmp_name)
        done.append(("created" if make_ca(tree, keystore, validity, tmp) else "kept") + f" CA {keystore / 'public'}")
        gov = enclaves / "governance.xml"
        tree.write(gov, governance_xml(domains).encode())
        sign(tree, keystore, gov, enclaves / "governance.p7s")
        done.append(f"signed {gov}")
        ca_cert = (keystore / "public" / "ca.cert.pem").read_bytes()
        for enclave, text in permissions.items():
            folder = enclaves / enclave.strip("/")
            for part in reversed(folder.relative_to(enclaves).parents):  # every level checked and set
                tree.folder(enclaves / part)
            tree.folder(folder)
            made = make_identity(tree, keystore, folder, enclave, validity, tmp)
            for name in ("identity_ca.cert.pem", "permissions_ca.cert.pem"):
                tree.write(folder / name, ca_cert)
            tree.write(folder / "governance.p7s", (enclaves / "governance.p7s").read_bytes())
            tree.write(folder / "permissions.xml", text.encode())
            sign(tree, keystore, folder / "permissions.xml", folder / "permissions.p7s")
            done.append(f"{'created' if made else 'kept'} identity and signed permissions of {enclave}")
    return [*tree.repaired, *done]


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
