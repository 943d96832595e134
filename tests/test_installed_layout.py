"""`ros2 run <package> <executable>` works: executables under lib/<package>/, ament index markers.

ros2cli is not on PyPI, so this checks the installed layout that ros2 run relies on and starts
every node from there.
"""

import os
import pathlib
import shutil
import subprocess
import time

import pytest
from ament_index_python.packages import get_package_prefix, get_package_share_directory, get_packages_with_prefixes

from shaper_nodes.ros.launching import NodeProcess, executable

pytestmark = pytest.mark.integration

NODES = [("shaper_nodes", "shaper_node", {"joint_names": ["a"]}), ("shaper_nodes", "recorder", None),
         ("shaper_nodes", "identifier", {}), ("shaper_nodes", "learner", {}), ("sim_plant_node", "sim_plant", {})]


@pytest.mark.parametrize("package", ["shaper_msgs", "shaper_nodes", "sim_plant_node"])
def test_packages_are_in_the_ament_index(package):
    assert package in get_packages_with_prefixes()
    prefix = pathlib.Path(get_package_prefix(package))
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / package).exists()
    assert (pathlib.Path(get_package_share_directory(package)) / "package.xml").exists()


@pytest.mark.parametrize("package, name, params", NODES)
def test_every_node_starts_from_its_installed_executable(package, name, params, tmp_path, domain_id):
    path = executable(package, name)
    assert path.parent == pathlib.Path(get_package_prefix(package)) / "lib" / package
    if params is None:
        params = {"output": str(tmp_path / "bag")}
    log = tmp_path / "node.log"
    proc = NodeProcess(package, name, params, log_path=log, env={"ROS_DOMAIN_ID": str(domain_id)}).start()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and "[INFO]" not in log.read_text():
        assert proc.running(), log.read_text()
        time.sleep(0.1)
    assert proc.running(), log.read_text()
    assert proc.stop() == 0, log.read_text()


def test_demo_executable_help():
    out = subprocess.run([str(executable("sim_plant_node", "demo")), "--help"], capture_output=True, text=True,
                         timeout=60, env=os.environ)
    assert out.returncode == 0 and "--calibration" in out.stdout and "--cases" in out.stdout  # the arm story
    out = subprocess.run([str(executable("sim_plant_node", "demo")), "joint", "--help"], capture_output=True,
                         text=True, timeout=60, env=os.environ)
    assert out.returncode == 0 and "--frequency" in out.stdout  # the one-dimensional demo


def test_calibrate_prints_its_plan_without_moving_anything(tmp_path, domain_id):
    """Without --execute, nothing to talk to is needed: the plan (base and home poses given) and its duration.

    No joint states come on the test's own domain, so calibrate waits ``timeouts.data`` for them before it plans
    from the home pose: 2 s here instead of the installed 30 s (the wait's end, not its length, is the point)."""
    config = pathlib.Path(get_package_share_directory("shaper_nodes")) / "config" / "calibrate.yaml"
    out = subprocess.run([str(executable("shaper_nodes", "calibrate")), "--out", str(tmp_path / "cal"),
                          "--ros-args", "--params-file", str(config), "-p", "timeouts.data:=2.0"],
                         capture_output=True, text=True, timeout=60,
                         env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)}, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "calibration plan: 9 poses" in out.stdout and "add --execute" in out.stdout
    assert "the plan below starts at the home pose" in out.stdout  # it waited for joint states, and none came
    assert not (tmp_path / "cal").exists()


def test_design_cli_runs_from_its_installed_executable():
    out = subprocess.run([str(executable("shaper_nodes", "shaper_design")), "compare", "--frequency", "10",
                          "--damping", "0.02"], capture_output=True, text=True, timeout=120, env=os.environ)
    assert out.returncode == 0, out.stderr
    assert "zvd" in out.stdout and "2hump_ei" in out.stdout


def test_loop_design_cli_runs_from_its_installed_executable():
    out = subprocess.run([str(executable("shaper_nodes", "loop_design")), "tdf-interval", "--omega-a", "3",
                          "--delay", "0.349"], capture_output=True, text=True, timeout=120, env=os.environ)
    assert out.returncode == 0, out.stderr
    assert "stable for 3 <= w_R <= 5.04568 rad/s" in out.stdout


def test_keystore_cli_runs_from_its_installed_executable(tmp_path):
    exe = str(executable("shaper_nodes", "shaper_keystore"))
    out = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=120, env=os.environ, cwd=tmp_path)
    assert out.returncode == 0 and "usage: shaper_keystore" in out.stdout
    assert list(tmp_path.iterdir()) == []  # --help does nothing else
    if shutil.which("openssl") is None:
        return
    out = subprocess.run([exe, "create", str(tmp_path / "ks")], capture_output=True, text=True, timeout=120,
                         env=os.environ)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "ks" / "enclaves" / "shaper_suite" / "shaper" / "permissions.p7s").is_file()


def test_list_replay_names_a_missing_bag(tmp_path):
    out = subprocess.run([str(executable("shaper_nodes", "list_replay")), str(tmp_path / "nope")],
                         capture_output=True, text=True, timeout=120, env=os.environ)
    assert out.returncode == 2 and "list_replay:" in out.stderr and "Traceback" not in out.stderr


def test_bad_configuration_exits_with_a_clear_error(tmp_path, domain_id):
    proc = NodeProcess("shaper_nodes", "shaper_node", {"joint_names": ["a", "a"]}, log_path=tmp_path / "log",
                       env={"ROS_DOMAIN_ID": str(domain_id)}).start()
    proc.proc.wait(timeout=30)
    assert proc.proc.returncode == 1
    proc.stop()
    assert "joint_names must be a non-empty list of distinct names" in (tmp_path / "log").read_text()
