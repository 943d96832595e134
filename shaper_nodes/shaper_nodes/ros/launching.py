"""Start installed node executables as subprocesses, as ``ros2 run`` would (no launch needed).

The executable is looked up in the installed layout ``<prefix>/lib/<package>/<executable>`` of
the package's ament index prefix, which is exactly where ``ros2 run`` looks.

A started process ends with the process that started it: it gets SIGTERM (a clean stop for the suite's
nodes, ros/node_main.py) when its parent ends, even by ``kill -9`` (core/lifetime.py ``die_with_parent``,
Linux). The kernel sends it when the *thread* that started the child ends: start children from the main
thread (or one that lives as long as they should). A parent with several threads (an rclpy context has DDS
threads) killed with ``kill -9`` may deliver it more than once, as the child passes from thread to thread of
the dying parent (measured: two SIGTERMs); the suite's nodes take a repeated SIGTERM as the same stop.

Every process started here is reaped with ``os.wait4`` (:class:`UsagePopen`): its CPU time is kept
(:attr:`ChildProcess.cpu`), and with :data:`CPU_LOG_ENV` set each reaped process is logged to that file (the test
suite's CPU report, docs/results/testing.md).
"""

from __future__ import annotations

import functools
import json
import os
import pathlib
import resource
import signal
import subprocess
import time
from collections.abc import Mapping, Sequence
from typing import IO, Any

from shaper_nodes.core.lifetime import die_with_parent


def executable(package: str, name: str) -> pathlib.Path:
    """Path of an installed node executable, as ``ros2 run package name`` finds it."""
    from ament_index_python.packages import get_package_prefix

    path = pathlib.Path(get_package_prefix(package)) / "lib" / package / name
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise FileNotFoundError(f"no executable {name!r} in package {package!r} (looked for {path})")
    return path


#: environment variable naming a file to which every reaped :class:`UsagePopen` appends a JSON line (off when unset)
CPU_LOG_ENV = "SHAPER_CPU_LOG"


def command_name(args: Sequence[str]) -> str:
    """A short name for a command line: the executable's file name, or for ``python -m MOD`` / ``python FILE``
    the module or the file's name."""
    words = [str(a) for a in args]
    if not words:
        return "?"
    name = os.path.basename(words[0])
    if name.startswith("python") and len(words) > 1:
        rest = words[1:]
        if rest[0] == "-m" and len(rest) > 1:
            return f"python -m {rest[1]}"
        if rest[0] == "-c":
            return "python -c"
        return f"python {os.path.basename(rest[0])}"
    return name


def log_usage(path: str, args: Sequence[str], pid: int, usage: resource.struct_rusage, seconds: float) -> None:
    """Append one reaped process to the CPU log ``path`` (one JSON line, one ``write`` of an ``O_APPEND`` file, so
    the lines of processes that log at once do not mix): its name, pid, parent, CPU (user, system, s; its own and
    that of the processes it reaped), wall time since its start (s) and the test it ran for (pytest's
    ``PYTEST_CURRENT_TEST``, inherited)."""
    line = json.dumps({"kind": "process", "name": command_name(args), "pid": pid, "parent": os.getpid(),
                       "user": round(usage.ru_utime, 4), "sys": round(usage.ru_stime, 4), "wall": round(seconds, 3),
                       "test": os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" (", 1)[0]})
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, (line + "\n").encode())
    finally:
        os.close(fd)


class UsagePopen(subprocess.Popen):
    """``subprocess.Popen`` that reaps its child with ``os.wait4`` and keeps the child's resource usage.

    :attr:`usage` is the child's ``struct_rusage`` (with the processes it reaped) once it has been reaped by
    ``wait()`` or ``poll()``, None before. With :data:`CPU_LOG_ENV` set in this process's environment, the reap
    also appends a line to that file (:func:`log_usage`). CPython's POSIX ``Popen`` reaps in two private methods,
    ``_try_wait`` (``wait``) and ``_internal_poll`` (``poll``, ``__del__``), which this overrides; on another
    platform it is a plain ``Popen``.
    """

    usage: resource.struct_rusage | None = None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._began = time.monotonic()
        super().__init__(*args, **kwargs)

    def _reaped(self, pid: int, status: int, usage: resource.struct_rusage) -> tuple[int, int]:
        if pid == self.pid and pid != 0:
            self.usage = usage
            path = os.environ.get(CPU_LOG_ENV)
            if path:
                cmd = [self.args] if isinstance(self.args, (str, bytes, os.PathLike)) else list(self.args)
                log_usage(path, [os.fsdecode(a) for a in cmd], pid, usage, time.monotonic() - self._began)
        return pid, status

    def _wait4(self, pid: int, flags: int) -> tuple[int, int]:
        return self._reaped(*os.wait4(pid, flags))

    def _try_wait(self, wait_flags: int) -> tuple[int, int]:
        try:
            return self._wait4(self.pid, wait_flags)
        except ChildProcessError:  # as CPython's: reaping disabled (SIGCHLD ignored); the status is lost
            return self.pid, 0

    def _internal_poll(self, _deadstate: Any = None, **kwargs: Any) -> int | None:
        return super()._internal_poll(_deadstate, _waitpid=self._wait4)  # type: ignore[misc]


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
        self.proc: UsagePopen | None = None
        self._log: IO[str] | None = None
        self.stopped = False  # stop() was called: an exit after it is not a death

    def start(self) -> ChildProcess:
        self._log = open(self.log_path, "w") if self.log_path else None  # noqa: SIM115
        out = self._log if self._log else subprocess.DEVNULL
        self.proc = UsagePopen(self.cmd, stdout=out, stderr=subprocess.STDOUT, env=self.env, cwd=self.cwd,
                                     preexec_fn=functools.partial(die_with_parent, signal.SIGTERM, os.getpid()))
        return self

    @property
    def cpu(self) -> float | None:
        """CPU time (user + system, s) of the process and of the processes it reaped, once it has ended and been
        reaped (``stop()``, ``proc.wait()``, ``proc.poll()``); None before."""
        usage = self.proc.usage if self.proc is not None else None
        return None if usage is None else usage.ru_utime + usage.ru_stime

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGINT, wait up to ``timeout`` s, then SIGKILL; returns the exit code."""
        self.stopped = True
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
