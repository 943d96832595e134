"""How ``shaper_keystore create`` writes its files: modes whatever the umask, no link followed, repairs.

A keystore holds private keys: folders must be 0700 and keys 0600 even under ``umask 000``; a
symbolic link planted where the keystore writes (to make it overwrite the link's target) is refused,
naming it, and the target is left as it was; a key an operator left readable is repaired and the
repair reported.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import stat
from collections.abc import Iterator

import pytest

from shaper_nodes.cli import keystore as cli

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl executable not found")

ENCLAVE = pathlib.Path("enclaves/shaper_suite/shaper")


@pytest.fixture
def umask_000() -> Iterator[None]:
    old = os.umask(0)
    try:
        yield
    finally:
        os.umask(old)


def _modes(root: pathlib.Path) -> dict[str, int]:
    return {str(p.relative_to(root)): stat.S_IMODE(p.lstat().st_mode)
            for p in [root, *root.rglob("*")] if not p.is_symlink()}


def test_modes_under_umask_000(tmp_path: pathlib.Path, umask_000: None) -> None:
    ks = tmp_path / "ks"
    cli.create(ks)
    modes = _modes(ks)
    folders = {k: m for k, m in modes.items() if (ks / k).is_dir()}
    keys = {k: m for k, m in modes.items() if k.endswith("key.pem")}
    others = {k: m for k, m in modes.items() if k not in folders and k not in keys}
    assert folders and set(folders.values()) == {0o700}, folders
    assert len(keys) == 9 and set(keys.values()) == {0o600}, keys  # the CA's and eight enclaves'
    assert others and set(others.values()) == {0o644}, {k: oct(m) for k, m in others.items() if m != 0o644}
    assert not [p for p in ks.rglob("*.tmp")], "no scratch file left"


@pytest.mark.parametrize("where", ["enclaves/shaper_suite/shaper/permissions.xml", "enclaves/governance.xml",
                                   "enclaves/shaper_suite/shaper/key.pem", "public/ca.cert.pem"])
def test_a_planted_file_link_is_refused_and_its_target_kept(tmp_path: pathlib.Path, where: str) -> None:
    ks = tmp_path / "ks"
    cli.create(ks)
    target = tmp_path / "victim.txt"
    target.write_text("precious\n")
    link = ks / where
    link.unlink()
    link.symlink_to(target)
    with pytest.raises(cli.KeystoreError, match=re.escape(f"{link} is a symbolic link") + ".*follows no link"):
        cli.create(ks)
    assert target.read_text() == "precious\n"
    assert link.is_symlink()


def test_a_planted_folder_link_is_refused(tmp_path: pathlib.Path) -> None:
    ks = tmp_path / "ks"
    cli.create(ks)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.rmtree(ks / ENCLAVE)
    (ks / ENCLAVE).symlink_to(elsewhere)
    with pytest.raises(cli.KeystoreError, match="shaper_suite/shaper is a symbolic link"):
        cli.create(ks)
    assert list(elsewhere.iterdir()) == []


def test_a_keystore_that_is_a_link_is_refused(tmp_path: pathlib.Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "ks").symlink_to(real)
    assert cli.main(["create", str(tmp_path / "ks")]) == 2
    assert list(real.iterdir()) == []


def test_a_ca_alias_leading_elsewhere_is_refused(tmp_path: pathlib.Path) -> None:
    ks = tmp_path / "ks"
    cli.create(ks)
    alias = ks / "private" / "permissions_ca.key.pem"
    alias.unlink()
    alias.symlink_to(tmp_path / "attacker.key.pem")
    with pytest.raises(cli.KeystoreError, match=r"points at .*attacker\.key\.pem, not ca\.key\.pem"):
        cli.create(ks)


def test_wide_modes_on_an_existing_keystore_are_repaired_and_reported(tmp_path: pathlib.Path) -> None:
    ks = tmp_path / "ks"
    cli.create(ks)
    key = ks / ENCLAVE / "key.pem"
    key.chmod(0o644)
    (ks / "private").chmod(0o755)
    before = key.read_bytes()
    done = cli.create(ks)
    assert f"repaired mode of {key}: 0644 -> 0600" in done
    assert f"repaired mode of {ks / 'private'}: 0755 -> 0700" in done
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    assert key.read_bytes() == before, "an existing identity is kept, not re-keyed"
    assert not [line for line in cli.create(ks) if line.startswith("repaired")], "nothing left to repair"
