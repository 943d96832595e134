"""A node's busiest thread over the latency bench's turns: its CPU, its wait for a core and its preemptions per message.

The round trip's p50 moves with the machine's load by tens of microseconds from turn to turn; what a node's thread
spends per message moves much less. :class:`ThreadCpu` reads every thread of the node's process from
``/proc/<pid>/task/<tid>/schedstat`` (the time it ran and the time it was runnable but waited for a core, ns) and
``/proc/<pid>/task/<tid>/status`` (its involuntary context switches: preemptions) before and after each of the node's
turns, adds up the differences per thread, and reports the thread that ran most: the take loop of the floor and of the
shaper, the executor's thread of the bare echo. Session 14 (docs/results/benchmarks.md, H5 hop) found the shaper's
loop spending about 11 us of CPU per message beyond its work more than the floor's, which the hog puts on the round
trip; the bench prints these figures beside the decomposition (``benchmarks/work_timing.py``).

Linux only: where ``/proc`` has no ``schedstat`` the figures are NaN.
"""

from __future__ import annotations

import math
import os
from collections import defaultdict

#: per thread: (ns run, ns waited for a core, involuntary switches)
Times = dict[int, tuple[int, int, int]]


def thread_times(pid: int) -> Times:
    """Per thread of process ``pid``: (ns run, ns runnable but waiting, involuntary switches) so far; threads that
    end while they are read are left out."""
    out: Times = {}
    base = f"/proc/{pid}/task"
    try:
        tids = os.listdir(base)
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"{base}/{tid}/schedstat") as f:
                run, wait = (int(v) for v in f.read().split()[:2])
            invol = 0
            with open(f"{base}/{tid}/status") as f:
                for line in f:
                    if line.startswith("nonvoluntary_ctxt_switches"):
                        invol = int(line.split()[1])
        except (OSError, ValueError):
            continue
        out[int(tid)] = (run, wait, invol)
    return out


class ThreadCpu:
    """The per-thread sums over a node's turns (module docstring): :meth:`start` before a turn, :meth:`stop` after
    it with the messages sent in it, :meth:`busiest` at the end."""

    def __init__(self) -> None:
        self._sums: dict[int, list[int]] = defaultdict(lambda: [0, 0, 0])
        self._before: Times = {}
        self.messages = 0
        self._pid = 0  # the process's main thread has the process's id

    def start(self, pid: int) -> None:
        """Read the threads before a turn."""
        self._pid = pid
        self._before = thread_times(pid)

    def stop(self, pid: int, messages: int) -> None:
        """Read them after it and add the differences (threads seen both times), for ``messages`` sent."""
        after = thread_times(pid)
        for tid, (run, wait, invol) in after.items():
            if tid in self._before:
                run0, wait0, invol0 = self._before[tid]
                acc = self._sums[tid]
                acc[0] += run - run0
                acc[1] += wait - wait0
                acc[2] += invol - invol0
        self.messages += messages

    def busiest(self) -> dict[str, float]:
        """The thread that ran most: ``cpu_us_per_msg``, ``wait_us_per_msg`` (runnable, waiting for a core) and
        ``involuntary_per_msg`` (preemptions), per message sent, and its ``tid``; besides, the CPU per message of the
        process's main thread (``main_cpu_us_per_msg``: a node's executor, its timers) and of all its threads
        (``process_cpu_us_per_msg``); NaN when nothing was read."""
        if not self._sums or self.messages <= 0:
            return {"cpu_us_per_msg": math.nan, "wait_us_per_msg": math.nan, "involuntary_per_msg": math.nan,
                    "tid": math.nan, "main_cpu_us_per_msg": math.nan, "process_cpu_us_per_msg": math.nan}
        tid, (run, wait, invol) = max(self._sums.items(), key=lambda kv: kv[1][0])
        n = self.messages
        main = self._sums[self._pid][0] if self._pid in self._sums else math.nan
        return {"cpu_us_per_msg": 1e-3 * run / n, "wait_us_per_msg": 1e-3 * wait / n, "involuntary_per_msg": invol / n,
                "tid": tid, "main_cpu_us_per_msg": 1e-3 * main / n,
                "process_cpu_us_per_msg": 1e-3 * sum(acc[0] for acc in self._sums.values()) / n}


def print_threads(lat: dict) -> None:
    """The busiest thread of each node of the bench's latency report ``lat`` (each group against its floor)."""
    groups = [[(r["label"], r["extra"]["thread"]) for r in runs if r.get("extra", {}).get("thread")]
              for runs in (lat["runs"], lat.get("hog_runs", []))]
    if not any(groups):
        return
    print("  each node's busiest thread (the take loop; the bare echo's executor) per message sent: its CPU, its")
    print("  wait for a core (runnable, not running) and its preemptions; the main thread's CPU (the node's executor")
    print("  and timers) and all the process's threads', from /proc (benchmarks/thread_cpu.py)")
    print(f"  {'node':<24}{'CPU us':>8}{'above floor':>12}{'wait us':>9}{'preempted':>10}{'main us':>9}"
          f"{'process us':>11}")
    for rows in groups:
        floor = next((t for label, t in rows if label.startswith("echo, take loop")), None)
        for label, t in rows:
            above = t["cpu_us_per_msg"] - floor["cpu_us_per_msg"] if floor else math.nan
            print(f"  {label:<24}{_f(t['cpu_us_per_msg']):>8}{_f(above, '+.1f'):>12}{_f(t['wait_us_per_msg']):>9}"
                  f"{_f(t['involuntary_per_msg'], '.2f'):>10}{_f(t.get('main_cpu_us_per_msg', math.nan)):>9}"
                  f"{_f(t.get('process_cpu_us_per_msg', math.nan)):>11}")


def _f(value: float, spec: str = ".1f") -> str:
    return "n/a" if math.isnan(value) else format(value, spec)
