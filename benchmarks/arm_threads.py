"""Per-thread scheduler figures of a process, from Linux's /proc: what a lockstep run of the arm spent where.

For the runs of :mod:`benchmarks.arm_readers`: the sim plant's main thread (its stepping) and the reader processes'
threads, each thread's CPU time, its time runnable but waiting for a core, and its context switches, voluntary
(it slept: a wait, a wake-up to come) and involuntary (another task took its core: a woken thread preempting it, a
time slice's end). Read at the goal's request and at its result; the differences are the run's.

``/proc/PID/task/TID/schedstat`` gives the CPU and wait times (ns), ``/proc/PID/task/TID/sched`` the switch counts.
On another system, or a thread gone between two reads, the figures are left out (an empty snapshot).
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

__all__ = ["ThreadFigures", "between", "run_figures", "snapshot"]


@dataclass(frozen=True)
class ThreadFigures:
    """One thread's counters: its name, CPU time and wait for a core (s), voluntary and involuntary switches."""

    name: str
    cpu: float
    waiting: float
    voluntary: int
    involuntary: int


def _thread(task: pathlib.Path) -> ThreadFigures:
    cpu, waiting, _ = (int(v) for v in (task / "schedstat").read_text().split())
    counts = {}
    for line in (task / "sched").read_text().splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("nr_voluntary_switches", "nr_involuntary_switches"):
            counts[key.strip()] = int(float(value))
    return ThreadFigures((task / "comm").read_text().strip(), cpu * 1e-9, waiting * 1e-9,
                         counts["nr_voluntary_switches"], counts["nr_involuntary_switches"])


def snapshot(pid: int) -> dict[int, ThreadFigures]:
    """The counters of every thread of process ``pid`` now, by thread id (empty where /proc does not give them)."""
    out = {}
    try:
        tasks = list(pathlib.Path(f"/proc/{pid}/task").iterdir())
    except OSError:
        return {}
    for task in tasks:
        try:
            out[int(task.name)] = _thread(task)
        except (OSError, ValueError, KeyError):  # (a thread that ended meanwhile; a kernel without the fields)
            continue
    return out


def between(before: dict[int, ThreadFigures], after: dict[int, ThreadFigures]) -> dict[int, ThreadFigures]:
    """Per thread in both snapshots, what it did between them."""
    return {tid: ThreadFigures(a.name, a.cpu - before[tid].cpu, a.waiting - before[tid].waiting,
                               a.voluntary - before[tid].voluntary, a.involuntary - before[tid].involuntary)
            for tid, a in after.items() if tid in before}


def run_figures(plant_pid: int, plant: dict[int, ThreadFigures], readers: list[dict[int, ThreadFigures]],
                seconds: float, periods: int) -> dict[str, float]:
    """A lockstep run's figures from its threads' differences (:func:`between`) over ``seconds`` simulated s of
    ``periods`` periods: the plant's main thread (its thread id is its process id) CPU and wait for a core per
    simulated s and its preemptions per period, and the readers' Fast DDS receive threads' wake-ups per simulated s
    (``dds.shm``/``dds.udp`` threads' voluntary switches: one per time a sample found them asleep). Empty without
    the plant's main thread."""
    main = plant.get(plant_pid)
    if main is None or seconds <= 0 or periods <= 0:
        return {}
    wakeups = sum(f.voluntary for r in readers for f in r.values() if f.name.startswith(("dds.shm", "dds.udp")))
    return {"plant main thread CPU per sim s": main.cpu / seconds,
            "plant main thread waiting per sim s": main.waiting / seconds,
            "plant main thread preemptions per period": main.involuntary / periods,
            "readers' DDS wake-ups per sim s": wakeups / seconds}
