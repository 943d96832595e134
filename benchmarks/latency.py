"""Round-trip latency of a node that forwards ``std_msgs/Float64MultiArray``, from a driver node: the
interleaved measurement.

The driver (an rclpy node in this process, :class:`benchmarks.latency_driver.Driver`, on a fresh
:class:`rclpy.context.Context` per measurement) publishes one message of ``joints`` doubles per period on the
node's input topic and time-stamps the replies on its output topic: driver -> node -> driver, two hops.
:func:`measure_interleaved` starts the targets (:mod:`benchmarks.latency_targets`), warms each up, drives them
in turns and hands each one's replies to :func:`benchmarks.latency_replies.analyse`, which matches them to the
sends and checks them against the node's expected output ("Matching replies to sends" there).
:mod:`benchmarks.latency_suite` prints the tables; :mod:`benchmarks.cpu_hog` is the outside load.

The parts' names are importable from here as before (``Target``, ``echo_target``, ``shaper_target``,
``Driver``, ``LatencyResult``, ``CpuHog``, ``proc_cpu_seconds``, ...).

Timing
------
Sends are paced by a wall-clock loop in a thread of their own (absolute deadlines
``t0 + k / rate`` with ``time.sleep``; when more than one period late the schedule is re-anchored
rather than bursting), stamped with :func:`time.perf_counter_ns` just before ``publish``; replies
are stamped on entry to the subscription callback (the main thread spins a
``SingleThreadedExecutor``). The achieved send rate is reported. CPU shares come from
``/proc/<pid>/stat`` (utime + stime over the sending window) for the node and from
:func:`os.times` for the driver, in percent of one core; ``other_cpu_pct`` is the rest of the
machine's busy time over the same window (from ``/proc/stat``), an indicator of outside noise.
``node_cpu_us_per_msg`` is the node's CPU time over the window per reply received: a node that loses
messages under load does less work, so its CPU share alone would flatter it.
"""

from __future__ import annotations

import contextlib
import functools
import json
import pathlib
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
import rclpy.context
from rclpy.executors import SingleThreadedExecutor

from .cpu_hog import HOG_CODE, CpuHog
from .latency_driver import REPLY_DEPTH, Driver, spin_until
from .latency_replies import LatencyResult, analyse, expected_output, ramp
from .latency_targets import REPO_ROOT, Target, echo_target, identity_fir, shaper_target
from .proc_cpu import machine_busy_seconds, proc_cpu_seconds, self_cpu_seconds
from .thread_cpu import ThreadCpu
from .work_timing import work_path

# the measurement, and its parts importable from here as before the split
__all__ = ["HOG_CODE", "REPLY_DEPTH", "REPO_ROOT", "CpuHog", "Driver", "LatencyResult", "Target", "echo_target",
           "expected_output", "identity_fir", "log_tail", "machine_busy_seconds", "measure", "measure_interleaved",
           "proc_cpu_seconds", "ramp", "self_cpu_seconds", "shaper_target"]


def log_tail(path: pathlib.Path, lines: int = 20) -> str:
    """The last ``lines`` lines of a log file ('' if missing)."""
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


def measure(target: Target, *, seconds: float = 5.0, rate: float = 1000.0, joints: int = 7,
            warmup: float = 0.5, drain: float = 0.5, discovery_timeout: float = 30.0,
            log_dir: pathlib.Path, progress: Callable[[str], None] = lambda s: None) -> LatencyResult:
    """Start ``target``, drive it for ``seconds`` at ``rate`` and measure the round trips (one target
    of :func:`measure_interleaved`, in one stretch)."""
    return measure_interleaved([target], seconds=seconds, rate=rate, joints=joints, warmup=warmup, drain=drain,
                               discovery_timeout=discovery_timeout, log_dir=log_dir, rounds=1,
                               progress=progress)[0]


def _past(t: float) -> bool:
    return time.monotonic() >= t


def _ended(thread: threading.Thread) -> bool:
    return not thread.is_alive()


def _has_replies(driver: Driver, n: int) -> bool:
    return len(driver.replies) >= n


@dataclass
class _Driven:
    """One target of :func:`measure_interleaved` while it runs."""

    target: Target
    proc: Any
    log_path: pathlib.Path
    driver: Driver
    expected: np.ndarray
    stamps: np.ndarray
    node_cpu: float = 0.0
    driver_cpu: float = 0.0
    busy: float = 0.0
    wall: float = 0.0
    threads: ThreadCpu = field(default_factory=ThreadCpu)  # its busiest thread per message (thread_cpu.py)

    def alive(self) -> None:
        if not self.proc.running():
            raise RuntimeError(f"{self.target.label}: node exited ({self.proc.proc.returncode});"
                               f" log {self.log_path}:\n{log_tail(self.log_path)}")


def _warm_up(executor: SingleThreadedExecutor, d: _Driven, rest: np.ndarray, rate: float, warmup: float,
             discovery_timeout: float, alive: Callable[[], None], progress: Callable[[str], None]) -> None:
    """Wait for ``d``'s node to be discovered, then send it the rest value until it replies, and ``warmup`` s more."""
    t0 = time.monotonic()
    if not spin_until(executor, d.driver.discovered, discovery_timeout, alive):
        raise RuntimeError(f"{d.target.label}: not discovered within {discovery_timeout:g} s;"
                           f" log {d.log_path}:\n{log_tail(d.log_path)}")
    progress(f"{d.target.label}: discovered after {time.monotonic() - t0:.1f} s; warming up")
    stop = threading.Event()
    sender = threading.Thread(target=d.driver.send_paced, args=(rest, rate), kwargs={"stop": stop}, daemon=True)
    sender.start()
    try:
        if not spin_until(executor, functools.partial(_has_replies, d.driver, 1), discovery_timeout, alive):
            raise RuntimeError(f"{d.target.label}: no reply within {discovery_timeout:g} s;"
                               f" log {d.log_path}:\n{log_tail(d.log_path)}")
        spin_until(executor, functools.partial(_past, time.monotonic() + warmup), warmup + 1.0)
    finally:
        stop.set()
        sender.join()


def _drive_turn(executor: SingleThreadedExecutor, d: _Driven, data: np.ndarray, lo: int, hi: int, rate: float,
                alive: Callable[[], None]) -> None:
    """Send rows ``lo`` to ``hi - 1`` of ``data`` to ``d``'s node at ``rate`` (one turn); add up its CPU and wall
    time."""
    pid = d.proc.proc.pid
    d.threads.start(pid)
    node0, driver0, busy0 = proc_cpu_seconds(pid), self_cpu_seconds(), machine_busy_seconds()
    wall0 = time.perf_counter()
    stamps = d.stamps[lo - 1:hi - 1]  # the stamp of data row i is at i - 1
    sender = threading.Thread(target=d.driver.send_paced, args=(data[lo:hi], rate),
                              kwargs={"stamps": stamps, "first_seq": lo}, daemon=True)
    sender.start()
    spin_until(executor, functools.partial(_ended, sender), (hi - lo) / rate * 10 + 10, alive)
    sender.join()
    d.node_cpu += proc_cpu_seconds(pid) - node0
    d.driver_cpu += self_cpu_seconds() - driver0
    d.busy += machine_busy_seconds() - busy0
    d.wall += time.perf_counter() - wall0
    d.threads.stop(pid, hi - lo)
    # its last replies come back before the next turn
    spin_until(executor, functools.partial(_has_replies, d.driver, hi - 1), 0.2, alive)


def measure_interleaved(targets: list[Target], *, seconds: float = 5.0, rate: float = 1000.0, joints: int = 7,
                        warmup: float = 0.5, drain: float = 0.5, discovery_timeout: float = 30.0,
                        log_dir: pathlib.Path, rounds: int = 1,
                        progress: Callable[[str], None] = lambda s: None) -> list[LatencyResult]:
    """Start every target, and drive each for ``seconds`` at ``rate`` in ``rounds`` turns.

    With several targets and rounds, the targets take turns: in each round each target is driven for
    ``seconds / rounds`` while the others idle (their drivers out of the executor), in an order rotated
    and reversed from round to round. A change of
    the machine's state (another process, the host) then falls on every target alike, and their
    ratios compare like with like; in one stretch each, a minute apart, they did not (the echo
    node's p50 moved between 350 and 480 us from run to run on the quiet machine). Each target's
    data is one ramp, sent in order across its turns (its filter state runs on between them).

    Parameters
    ----------
    targets : list of Target
        The nodes under test (processes started together, each with its own topics).
    seconds : float
        Driven time per target, s (``round(seconds * rate)`` messages each).
    rate : float
        Send rate, Hz.
    joints : int
        Values per message.
    warmup : float
        Zeros are sent to each target for this long after its first reply, s.
    drain : float
        Time to keep receiving after the last send, s.
    discovery_timeout : float
        Longest wait for the nodes to start and be discovered, s.
    log_dir : pathlib.Path
        Where the nodes' logs go.
    rounds : int
        Turns per target (>= 1).
    progress : callable
        Receives progress messages.

    Raises
    ------
    RuntimeError
        If a node dies, is not discovered, or never replies.
    """
    n = max(2, round(seconds * rate))
    rounds = max(1, min(int(rounds), n))
    data = ramp(n, joints)
    context = rclpy.context.Context()
    rclpy.init(args=[], context=context)
    executor = SingleThreadedExecutor(context=context)
    driven: list[_Driven] = []
    try:
        for k, target in enumerate(targets):
            log_path = log_dir / f"{target.label.replace(' ', '_')}.log"
            proc = target.make_process(log_path)
            proc.start()
            driver = Driver(target.in_topic, target.out_topic, context, name=f"bench_driver_{k}")
            executor.add_node(driver)
            driven.append(_Driven(target, proc, log_path, driver, expected_output(target.fir, data),
                                  np.zeros(n, dtype=np.int64)))

        def alive() -> None:
            for d in driven:
                d.alive()

        for d in driven:
            _warm_up(executor, d, data[:1], rate, warmup, discovery_timeout, alive, progress)
        spin_until(executor, lambda: False, 0.1)  # let the last zeros come back
        for d in driven:
            d.driver.replies.clear()
            executor.remove_node(d.driver)  # each driver spins only in its own turns: the executor's wait set
            #                                 stays the one of a lone driver, as in a run with one target

        # measurement: the ramp 1..n of each target, in `rounds` turns
        bounds = np.linspace(1, n + 1, rounds + 1).round().astype(int)  # rows [bounds[r], bounds[r+1]) of data
        for r in range(rounds):
            lo, hi = int(bounds[r]), int(bounds[r + 1])
            if hi <= lo:
                continue
            order = driven[r % len(driven):] + driven[:r % len(driven)]  # rotated, and reversed every other
            for d in (order[::-1] if r % 2 else order):  # round: each target follows each of the others
                executor.add_node(d.driver)
                _drive_turn(executor, d, data, lo, hi, rate, alive)
                executor.remove_node(d.driver)
        for d in driven:
            executor.add_node(d.driver)
        spin_until(executor, functools.partial(_past, time.monotonic() + drain), drain + 1.0)
        alive()
        replies = [list(d.driver.replies) for d in driven]
    finally:
        for d in driven:
            if d.driver in executor.get_nodes():
                executor.remove_node(d.driver)
            d.driver.destroy_node()
        executor.shutdown()
        context.try_shutdown()
        for d in driven:
            code = d.proc.stop()
            if code not in (0, None, -signal.SIGINT):
                progress(f"{d.target.label}: node exited with {code} (log {d.log_path})")

    # the stamp index at which each turn after the first began
    turns = [int(b) - 1 for b in bounds[1:-1]]
    results = [analyse(d.target, rep, d.stamps, d.expected, rate, joints, node_cpu=d.node_cpu,
                       driver_cpu=d.driver_cpu, busy=d.busy, wall=d.wall, turns=turns)
               for d, rep in zip(driven, replies, strict=True)]
    for d, result in zip(driven, results, strict=True):  # the node's own timers, where it kept them (work_timing.py)
        result.extra["thread"] = d.threads.busiest()
        with contextlib.suppress(OSError, ValueError):
            result.extra["work"] = json.loads(work_path(d.log_path).read_text())
    return results
