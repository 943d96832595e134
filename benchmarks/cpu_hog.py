"""Outside load for the latency bench: a busy-loop child process taking one core (the ``+ hog`` rows of
:mod:`benchmarks.latency_suite`, :mod:`benchmarks.latency_executors` and :mod:`benchmarks.callback_parts`).
"""

from __future__ import annotations

import contextlib
import os
import sys

from shaper_nodes.ros.launching import ChildProcess

from .proc_cpu import proc_cpu_seconds

__all__ = ["HOG_CODE", "CpuHog"]

#: the busy loop of :class:`CpuHog` (pure Python: one core at 100 %, no memory traffic to speak of)
HOG_CODE = "while True:\n    pass\n"


class CpuHog:
    """A busy-loop child process taking one core, pinned to ``cpu`` where the OS allows it.

    Used as a context manager around a measurement, so that the echo node and the shaper node are
    measured under the same load; :attr:`cpu_seconds` is what the hog got (utime + stime, s).

    Parameters
    ----------
    cpu : int or None
        The CPU to pin the hog to (default the last one); None: not pinned.
    """

    def __init__(self, cpu: int | None = -1) -> None:
        count = os.cpu_count() or 1
        self.cpu = None if cpu is None else cpu % count
        self.proc: ChildProcess | None = None
        self.cpu_seconds = 0.0

    def __enter__(self) -> CpuHog:
        self.proc = ChildProcess([sys.executable, "-S", "-c", HOG_CODE]).start()
        assert self.proc.proc is not None
        if self.cpu is not None and hasattr(os, "sched_setaffinity"):
            try:
                os.sched_setaffinity(self.proc.proc.pid, {self.cpu})
            except OSError:  # a restricted cpuset: the hog floats
                self.cpu = None
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None and self.proc.proc is not None:
            with contextlib.suppress(OSError):
                self.cpu_seconds = proc_cpu_seconds(self.proc.proc.pid)
            self.proc.proc.kill()
            self.proc.proc.wait()
            self.proc = None
