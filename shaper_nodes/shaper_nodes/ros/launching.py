"""Start installed node executables as subprocesses, as ``ros2 run`` would (no launch needed).

The executable is looked up in the installed layout ``<prefix>/lib/<package>/<executable>`` of
the package's ament index prefix, which is exactly where ``ros2 run`` looks.

A started process ends with the process that started it: it gets SIGTERM (a clean stop for the suite's
nodes, ros/node_main.py) when its parent ends, even by ``kill -9`` (core/lifetime.py ``die_with_parent``,
Linux). The kernel sends it when the *thread* that started the child ends: start children from the main
thread (or one that lives as long as they should). A parent with several threads (an rclpy context has DDS
threads) killed with ``kill -9`` may deliver it more than once, as the child passes from thread to thread of
the dying parent (measured: two SIGTERMs); the suite's nodes take a repeated SIGTERM as the same stop.
"""

from __future__ import annotations

import functools
import json
import os
import pathlib
import signal
import subprocess
from collections.abc import Mapping, Sequence
from typing import IO

from shaper_nodes.core.lifetime import die_with_parent


def executable(package: str, name: str) -> pathlib.Path:
    """Path of an installed node executable, as ``ros2 run package name`` finds it."""
    from ament_index_python.packages import get_package_prefix

    path = pathlib.Path(get_package_prefix(package)) / "lib" / package / name
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise FileNotFoundError(f"no executable {name!r} in package {package!r} (looked for {path})")
    return path


def ros_args(params: Mapping[str, object], remaps: Mapping[str, str] | None = None,
             params_file: str | pathlib.Path | None = None) -> list[str]:
    """``--ros-args [--params-file FILE] -p name:=value ...``; values are written as YAML (JSON), floats keep a
    point; ``-p`` values override the file's."""
    args = ["--ros-args"] + (["--params-file", str(params_file)] if params_file else [])
    for key, value in params.items():
        args += ["-p", f"{key}:={json.dumps(value)}"]
    for src, dst in (remaps or {}).items():
        args += ["-r", f"{src}:={dst}"]
    return args


class ChildProcess:
    """A command running in its own process, output to a log file; stop() sends SIGINT like Ctrl-C.

    The process gets SIGTERM when the process that started it ends, however it ends (see the module
    docstring).
    """

    def __init__(self, cmd: list[str], log_path: str | pathlib.Path | None = None,
                 env: Mapping[str, str] | None = None, cwd: str | pathlib.Path | None = None) -> None:
        self.cmd = list(cmd)
        self.log_path = pathlib.Path(log_path) if log_path else None
        self.env = {**os.environ, **(env or {})}
        self.cwd = cwd
        self.proc: subprocess.Popen | None = None
        self._log: IO[str] | None = None

    def start(self) -> ChildProcess:
        self._log = open(self.log_path, "w") if self.log_path else None  # noqa: SIM115
        out = self._log if self._log else subprocess.DEVNULL
        self.proc = subprocess.Popen(self.cmd, stdout=out, stderr=subprocess.STDOUT, env=self.env, cwd=self.cwd,
                                     preexec_fn=functools.partial(die_with_parent, signal.SIGTERM, os.getpid()))
        return self

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGINT, wait up to ``timeout`` s, then SIGKILL; returns the exit code."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self._log is not None:
            self._log.close()
            self._log = None
        return self.proc.returncode

    def __enter__(self) -> ChildProcess:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class NodeProcess(ChildProcess):
    """An installed node executable (found as ``ros2 run`` finds it) in its own process."""

    def __init__(self, package: str, name: str, params: Mapping[str, object] | None = None,
                 log_path: str | pathlib.Path | None = None, env: Mapping[str, str] | None = None,
                 remaps: Mapping[str, str] | None = None, params_file: str | pathlib.Path | None = None,
                 args: Sequence[str] = ()) -> None:
        super().__init__([str(executable(package, name)), *args, *ros_args(params or {}, remaps, params_file)],
                         log_path, env)
