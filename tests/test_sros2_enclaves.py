"""rclpy with SROS2 switched on, pointed at a keystore from ``shaper_keystore``.

rcl finds an enclave at ``$ROS_SECURITY_KEYSTORE/enclaves/<enclave>`` and hands its files to the
RMW. This checks that the keystore's layout is where rcl looks: with the enclave present, node
creation gets past rcl to the DDS security plugins, and with Enforce and the enclave absent rcl
refuses it, naming the folder. The Fast DDS of the PyPI wheels is built without those plugins and
says so; a DDS with them (apt's, on a robot) creates the node with the keystore's documents.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import sys

import pytest

from shaper_nodes.cli import keystore

SCRIPT = """
import sys
import rclpy
rclpy.init(args=['--ros-args', '--enclave', sys.argv[1]])
node = rclpy.create_node(sys.argv[2])
print('NODE CREATED', node.get_fully_qualified_name(), flush=True)
node.destroy_node()
rclpy.shutdown()
"""
NO_PLUGINS = "doesn't have the security libraries"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    if shutil.which("openssl") is None:
        pytest.skip("openssl executable not found")
    path = tmp_path_factory.mktemp("sros2") / "keystore"
    assert keystore.main(["create", str(path)]) == 0
    return path


def create_node(store: pathlib.Path, enclave: str, node: str, domain_id: int) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": str(store)}
    return subprocess.run([sys.executable, "-c", SCRIPT, enclave, node], env=env, capture_output=True, text=True,
                          timeout=120, check=False)


@pytest.mark.parametrize("role", ["shaper", "learner", "motion_source"])
def test_rcl_finds_each_enclave_and_hands_it_to_dds(store: pathlib.Path, role: str, domain_id: int) -> None:
    proc = create_node(store, f"/shaper_suite/{role}", role, domain_id)
    output = proc.stdout + proc.stderr
    if proc.returncode == 0:  # a DDS with the security plugins accepted the certificate and the documents
        assert f"NODE CREATED /{role}" in proc.stdout
    else:  # the PyPI Fast DDS: rcl found the enclave, the RMW has no plugins to enforce it
        assert NO_PLUGINS in output, output
        assert "does not exist" not in output


def test_enforce_refuses_a_missing_enclave(store: pathlib.Path, domain_id: int) -> None:
    proc = create_node(store, "/shaper_suite/intruder", "intruder", domain_id)
    output = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "NODE CREATED" not in output
    assert f"{store}/enclaves/shaper_suite/intruder" in output and "does not exist" in output
