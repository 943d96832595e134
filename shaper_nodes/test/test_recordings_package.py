"""The recordings package stands alone: no rclpy, nothing of ``ros/`` or ``nodes/``; nor does ``analysis/``.

Each check imports the package (every module of it) in a fresh interpreter and looks at ``sys.modules``.
"""

from __future__ import annotations

import json
import pkgutil
import subprocess
import sys

import pytest

import shaper_nodes.analysis
import shaper_nodes.recordings

FORBIDDEN = ("rclpy", "shaper_nodes.ros", "shaper_nodes.nodes")


def _modules(package) -> list[str]:
    return [package.__name__] + [f"{package.__name__}.{m.name}" for m in pkgutil.iter_modules(package.__path__)]


def _imported_after(modules: list[str], also: str = "") -> list[str]:
    """The modules in ``sys.modules`` of a fresh interpreter after importing ``modules`` (and running ``also``)."""
    code = ("import importlib, json, sys\n"
            f"for m in {modules!r}:\n    importlib.import_module(m)\n{also}\n"
            "print(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, timeout=120)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _forbidden(names: list[str]) -> list[str]:
    return [n for n in names if any(n == f or n.startswith(f + ".") for f in FORBIDDEN)]


@pytest.mark.parametrize("package", [shaper_nodes.recordings, shaper_nodes.analysis], ids=lambda p: p.__name__)
def test_package_imports_no_rclpy_nor_ros_nor_nodes(package):
    modules = _modules(package)
    assert len(modules) > 5
    loaded = _imported_after(modules)
    assert set(modules) <= set(loaded)
    assert _forbidden(loaded) == []


def test_every_exported_name_of_recordings_resolves_without_rclpy():
    """Every name of ``shaper_nodes.recordings.__all__`` resolves (from the module that defines it), and the
    type store is built, all without rclpy and without message types."""
    from shaper_nodes import recordings

    assert sorted(recordings.__all__) == sorted(recordings._HOME) == sorted(set(recordings.__all__))
    for name in recordings.__all__:
        assert getattr(recordings, name) is not None, name
    loaded = _imported_after(["shaper_nodes.recordings"], "import shaper_nodes.recordings as r\n"
                             "[getattr(r, n) for n in r.__all__]\nr.default_typestore()")
    assert _forbidden(loaded) == []
    assert not [n for n in loaded if n.split(".")[0] in ("sensor_msgs", "std_msgs", "shaper_msgs", "diagnostic_msgs")]


def test_the_cdr_module_alone_stays_light():
    """The sim plant imports ``shaper_nodes.recordings.cdr``: neither rosbags nor the reader come with it."""
    loaded = _imported_after(["shaper_nodes.recordings.cdr"])
    assert not [n for n in loaded if n.startswith(("rosbags", "mcap", "yaml", "shaper_nodes.recordings.reader",
                                                   "shaper_nodes.recordings.writer"))]
