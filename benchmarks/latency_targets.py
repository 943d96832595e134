"""The nodes the latency bench drives (:mod:`benchmarks.latency`): what a target is, and the two kinds, the bare
echo node (:mod:`benchmarks.echo_node`; on the take loop, the floor, and the floor doing the ZVD shaper's work
alone) and the real shaper node, each with the FIR it applies (for decoding and
checking its replies, :mod:`benchmarks.latency_replies`).
"""

from __future__ import annotations

import pathlib
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.shaping import SparseFir
from shaper_nodes.ros.launching import ChildProcess

from .work_timing import LEAN, work_env

__all__ = ["REPO_ROOT", "Target", "echo_target", "identity_fir", "lean_zvd_target", "shaper_target"]

#: the repository root (the parent of this package), the working directory of the echo node
REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent


@dataclass
class Target:
    """A node under test.

    Attributes
    ----------
    label : str
        Name in the report.
    make_process : callable
        ``make_process(log_path)`` returns an unstarted process object with ``start()``,
        ``stop()``, ``running()`` and a ``proc`` attribute (a :class:`subprocess.Popen` once
        started); :class:`ChildProcess` and :class:`shaper_nodes.ros.launching.NodeProcess` fit.
    in_topic, out_topic : str
        The node's input and output topics.
    fir : SparseFir
        The filter the node applies to the data (for decoding and checking the replies).
    argv : list of str
        The node's command line after the interpreter, where the target has one to share (the shaper's:
        executable and ROS arguments), for a driver that starts the node its own way (profile_node).
    """

    label: str
    make_process: Callable[[pathlib.Path], ChildProcess]
    in_topic: str
    out_topic: str
    fir: SparseFir
    argv: list[str] = field(default_factory=list)


def identity_fir() -> SparseFir:
    """The one-tap unit FIR (what the echo node and shaper family ``none`` do)."""
    return SparseFir(delays=np.array([0]), gains=np.array([1.0]))


def echo_target(in_topic: str = "/bench/echo_in", out_topic: str = "/bench/echo_out", take: bool = False,
                timed: bool = False) -> Target:
    """The bare echo node (:mod:`benchmarks.echo_node`) run with this interpreter; ``take``: its raw
    echo on the take loop (the floor of the shaper's path), labelled ``echo, take loop``; ``timed`` (with
    ``take``): its callback timed in the node (:mod:`benchmarks.work_timing`)."""

    def make(log_path: pathlib.Path) -> ChildProcess:
        cmd = [sys.executable, "-m", "benchmarks.echo_node", "--in", in_topic, "--out", out_topic]
        return ChildProcess(cmd + (["--take"] if take else []), log_path, cwd=REPO_ROOT,
                            env=work_env(log_path) if timed else None)

    return Target("echo, take loop" if take else "echo (baseline)", make, in_topic, out_topic, identity_fir())


def shaper_target(label: str, joints: int, rate: float, params: Mapping[str, Any] | None = None,
                  timed: bool = False) -> Target:
    """The real shaper node (``shaper_nodes shaper_node``) with ``joints`` joints at ``rate``.

    ``params`` are extra node parameters (``shaper.*``, ``discretization``); the FIR used for
    decoding is designed from them exactly as the node does. ``timed``: the array callback, its work and
    its publish timed in the node (:mod:`benchmarks.work_timing`).
    """
    from shaper_nodes.core.shaping import Mode, design, discretize
    from shaper_nodes.ros.launching import NodeProcess, executable, ros_args

    params = dict(params or {})
    family = str(params.get("shaper.family", "none"))
    mode = Mode.from_hz(float(params.get("shaper.frequency_hz", 10.0)), float(params.get("shaper.damping_ratio", 0.05)))
    shaper = design(family, [mode], derivative_order=int(params.get("shaper.derivative_order", 2)),
                    vibration_tolerance=float(params.get("shaper.vibration_tolerance", 0.05)))
    fir = discretize(shaper, rate, str(params.get("discretization", "split")))
    # a node name and topics of its own, so that several targets can run at once (measure_interleaved)
    name = "bench_" + "".join(c if c.isalnum() else "_" for c in label).strip("_")
    in_topic, out_topic = f"/{name}/commands", f"/{name}/shaped"
    node_params = {"joint_names": [f"joint_{i + 1}" for i in range(joints)], "command_rate": float(rate),
                   "topics.array_in": in_topic, "topics.array_out": out_topic, **params}

    remaps = {"__node": name}

    def make(log_path: pathlib.Path) -> NodeProcess:
        return NodeProcess("shaper_nodes", "shaper_node", node_params, log_path=log_path, remaps=remaps,
                           env=work_env(log_path) if timed else None)

    return Target(label, make, in_topic, out_topic, fir,
                  [str(executable("shaper_nodes", "shaper_node")), *ros_args(node_params, remaps)])


def lean_zvd_target(joints: int, rate: float, zvd: Mapping[str, Any], timed: bool = False) -> Target:
    """The floor doing the ZVD shaper's work and nothing else (``benchmarks.echo_node --take --shape zvd``): the
    core's array path over the same FIR as the ``zvd`` shaper target's, on the floor's take loop."""
    from shaper_nodes.core.shaping import Mode, design, discretize

    freq, damping = float(zvd["shaper.frequency_hz"]), float(zvd["shaper.damping_ratio"])
    in_topic, out_topic = "/bench/lean_zvd_in", "/bench/lean_zvd_out"
    cmd = [sys.executable, "-m", "benchmarks.echo_node", "--in", in_topic, "--out", out_topic, "--take",
           "--shape", str(zvd["shaper.family"]), "--frequency", repr(freq), "--damping", repr(damping),
           "--joints", str(joints), "--rate", repr(float(rate))]

    def make(log_path: pathlib.Path) -> ChildProcess:
        return ChildProcess(cmd, log_path, cwd=REPO_ROOT, env=work_env(log_path) if timed else None)

    fir = discretize(design(str(zvd["shaper.family"]), [Mode.from_hz(freq, damping)]), rate, "split")
    return Target(LEAN, make, in_topic, out_topic, fir)
