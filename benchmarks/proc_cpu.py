"""CPU time from the kernel's accounting: of a process (``/proc/<pid>/stat``), of this process
(:func:`os.times`) and of the whole machine (``/proc/stat``), in seconds.

The latency bench (:mod:`benchmarks.latency`) reads them around each turn; the scheduler bench and the hog
(:mod:`benchmarks.cpu_hog`) read a child's share with :func:`proc_cpu_seconds`.
"""

from __future__ import annotations

import os

__all__ = ["machine_busy_seconds", "proc_cpu_seconds", "self_cpu_seconds"]

_CLK_TCK = os.sysconf("SC_CLK_TCK")


def proc_cpu_seconds(pid: int) -> float:
    """utime + stime of process ``pid`` (all its threads), s, from ``/proc/<pid>/stat``."""
    with open(f"/proc/{pid}/stat") as f:
        rest = f.read().rsplit(")", 1)[1].split()
    # rest[0] is field 3 (state); utime and stime are fields 14 and 15
    return (int(rest[11]) + int(rest[12])) / _CLK_TCK


def machine_busy_seconds() -> float:
    """Busy CPU time of the whole machine (all CPUs; not idle, not iowait), s, from ``/proc/stat``."""
    with open("/proc/stat") as f:
        ticks = [int(v) for v in f.readline().split()[1:]]
    # user nice system idle iowait irq softirq steal [guest guest_nice, already counted in user]
    return (sum(ticks[:8]) - ticks[3] - ticks[4]) / _CLK_TCK


def self_cpu_seconds() -> float:
    """User + system CPU time of this process (all threads), s."""
    t = os.times()
    return t.user + t.system
