"""Round-trip latency of a node that forwards ``std_msgs/Float64MultiArray``, from a driver node.

The driver (an rclpy node in this process, on a fresh :class:`rclpy.context.Context` per
measurement) publishes one message of ``joints`` doubles per period on the node's input topic and
time-stamps the replies on its output topic: driver -> node -> driver, two hops.

Matching replies to sends
-------------------------
The send time of every message is kept in an array indexed by its sequence number ``k``
(1, 2, ..., n). The sequence number travels with the message twice:

* in ``layout.data_offset``, which both nodes pass through unchanged (the echo node republishes
  the message itself, the shaper node copies the layout of its input to its output); this is
  the primary key, and it is immune to filtering and to lost messages;
* in the data, as the ramp ``x_j(k) = k (1 + j / 8)`` on joint ``j``. The node under test may
  filter the data (the shaper does, and the sequence number cannot simply be read back), so a
  reply is decoded by comparing its joint 0 with the node's *expected* output for the ramp,
  computed here with the same causal FIR (:class:`shaper_nodes.core.shaping.fir.StreamingShaper`,
  designed from the parameters given to the node; identity for the echo node and for shaper
  family ``none``). A causal FIR with non-negative taps and a positive first tap (every shaper
  family here) maps a ramp to a strictly increasing sequence, so the inverse is a
  nearest-neighbour look-up. This is the fallback when a reply carries no ``data_offset``; it is
  exact only while no message is lost on the way in (a lost input shifts the filter's history).

Before the ramp the driver sends zeros (``data_offset`` 0) until the first reply arrives (both
hops discovered) and for ``warmup`` s more, so the node's filter starts at rest at 0 exactly as
the local one does. Every joint of every reply is checked against the expected output
(``max_output_error``, relative; ``inexact`` counts replies off by more than 1e-9, which only
happens after a lost input): the comparison is only fair if the node did the work it should.
Shaper family ``none`` still runs the node's full path (validation, ``StreamingShaper`` with one
tap, message building).

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
import os
import pathlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import rclpy
import rclpy.context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from shaper_nodes.core.shaping import SparseFir, StreamingShaper
from shaper_nodes.ros.launching import ChildProcess

from .echo_node import DEPTH
from .thread_cpu import ThreadCpu
from .work_timing import work_env, work_path

#: the repository root (the parent of this package), the working directory of the echo node
REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
_CLK_TCK = os.sysconf("SC_CLK_TCK")
#: QoS depth of the driver's reply subscription
REPLY_DEPTH = 1000


# --------------------------------------------------------------------------- processes
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


def log_tail(path: pathlib.Path, lines: int = 20) -> str:
    """The last ``lines`` lines of a log file ('' if missing)."""
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return ""


# --------------------------------------------------------------------------- results
@dataclass
class LatencyResult:
    """Figures of one latency measurement (times in microseconds, CPU in percent of one core)."""

    label: str
    joints: int
    target_rate_hz: float
    sent: int
    received: int
    lost: int
    duplicates: int
    undecoded: int
    seq_from_data: int
    inexact: int
    max_output_error: float
    send_rate_hz: float
    send_interval_p99_us: float
    p50_us: float
    p99_us: float
    max_us: float
    mean_us: float
    node_cpu_pct: float
    node_cpu_us_per_msg: float
    driver_cpu_pct: float
    other_cpu_pct: float
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Plain dictionary (for JSON)."""
        return asdict(self)


def ramp(n: int, joints: int) -> np.ndarray:
    """The driver's data: row 0 is the rest value 0, row k the ramp ``k (1 + j / 8)``; shape (n + 1, joints)."""
    k = np.arange(n + 1, dtype=float)[:, None]
    return k * (1.0 + np.arange(joints) / 8.0)[None, :]


def expected_output(fir: SparseFir, data: np.ndarray) -> np.ndarray:
    """The node's output for ``data`` (rows = samples), started at rest at ``data[0]``."""
    return StreamingShaper(fir, data.shape[1]).process(data)


# --------------------------------------------------------------------------- driver
class Driver(Node):
    """Publishes on the node's input, time-stamps the replies on its output.

    Parameters
    ----------
    in_topic, out_topic : str
        The node's input (the driver publishes there) and output (the driver listens there).
    context : rclpy.context.Context
        The context of this measurement.
    """

    def __init__(self, in_topic: str, out_topic: str, context: rclpy.context.Context,
                 name: str = "bench_driver") -> None:
        super().__init__(name, context=context)
        self.in_topic, self.out_topic = in_topic, out_topic
        self.pub = self.create_publisher(Float64MultiArray, in_topic, DEPTH)
        # a deep queue on the measuring side, so that the driver itself never drops a reply
        self.create_subscription(Float64MultiArray, out_topic, self._on_reply, REPLY_DEPTH)
        self.replies: list[tuple[int, int, object]] = []

    def _on_reply(self, msg: Float64MultiArray) -> None:
        self.replies.append((time.perf_counter_ns(), msg.layout.data_offset, msg.data))

    def discovered(self) -> bool:
        """Whether the node's subscription and publisher are both seen."""
        return self.pub.get_subscription_count() >= 1 and self.count_publishers(self.out_topic) >= 1

    def send_paced(self, rows: np.ndarray, rate: float, stamps: np.ndarray | None = None,
                   stop: threading.Event | None = None, first_seq: int = 0) -> int:
        """Publish the rows of ``rows`` one per period (wall clock), cycling until ``stop`` if given.

        Parameters
        ----------
        rows : ndarray, shape (n, joints)
            Data to send, in order.
        rate : float
            Send rate, Hz.
        stamps : ndarray of int64, shape (n,), optional
            Receives the :func:`time.perf_counter_ns` stamp taken just before each publish.
        stop : threading.Event, optional
            If given, keep sending (cycling through ``rows``) until it is set.
        first_seq : int
            If > 0, row ``i`` is sent with ``layout.data_offset = first_seq + i``; else with 0.

        Returns
        -------
        int
            Number of messages sent.
        """
        period = round(1e9 / rate)
        msg = Float64MultiArray()
        lists = rows.tolist()
        deadline = time.perf_counter_ns()
        i = 0
        while (i < len(lists)) if stop is None else not stop.is_set():
            msg.data = lists[i % len(lists)]
            msg.layout.data_offset = first_seq + i if first_seq > 0 else 0
            now = time.perf_counter_ns()
            if now < deadline:
                time.sleep((deadline - now) * 1e-9)
            elif now - deadline > period:
                deadline = now  # more than a period late: re-anchor instead of bursting
            t = time.perf_counter_ns()
            self.pub.publish(msg)
            if stamps is not None:
                stamps[i] = t
            deadline += period
            i += 1
        return i


def _spin_until(executor: SingleThreadedExecutor, done: Callable[[], bool], timeout: float,
                check: Callable[[], None] | None = None) -> bool:
    end = time.monotonic() + timeout
    while not done():
        if time.monotonic() > end:
            return False
        if check is not None:
            check()
        executor.spin_once(timeout_sec=0.02)
    return True


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
    if not _spin_until(executor, d.driver.discovered, discovery_timeout, alive):
        raise RuntimeError(f"{d.target.label}: not discovered within {discovery_timeout:g} s;"
                           f" log {d.log_path}:\n{log_tail(d.log_path)}")
    progress(f"{d.target.label}: discovered after {time.monotonic() - t0:.1f} s; warming up")
    stop = threading.Event()
    sender = threading.Thread(target=d.driver.send_paced, args=(rest, rate), kwargs={"stop": stop}, daemon=True)
    sender.start()
    try:
        if not _spin_until(executor, functools.partial(_has_replies, d.driver, 1), discovery_timeout, alive):
            raise RuntimeError(f"{d.target.label}: no reply within {discovery_timeout:g} s;"
                               f" log {d.log_path}:\n{log_tail(d.log_path)}")
        _spin_until(executor, functools.partial(_past, time.monotonic() + warmup), warmup + 1.0)
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
    _spin_until(executor, functools.partial(_ended, sender), (hi - lo) / rate * 10 + 10, alive)
    sender.join()
    d.node_cpu += proc_cpu_seconds(pid) - node0
    d.driver_cpu += self_cpu_seconds() - driver0
    d.busy += machine_busy_seconds() - busy0
    d.wall += time.perf_counter() - wall0
    d.threads.stop(pid, hi - lo)
    # its last replies come back before the next turn
    _spin_until(executor, functools.partial(_has_replies, d.driver, hi - 1), 0.2, alive)


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
        _spin_until(executor, lambda: False, 0.1)  # let the last zeros come back
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
        _spin_until(executor, functools.partial(_past, time.monotonic() + drain), drain + 1.0)
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
    results = [_analyse(d.target, rep, d.stamps, d.expected, rate, joints, node_cpu=d.node_cpu,
                        driver_cpu=d.driver_cpu, busy=d.busy, wall=d.wall, turns=turns)
               for d, rep in zip(driven, replies, strict=True)]
    for d, result in zip(driven, results, strict=True):  # the node's own timers, where it kept them (work_timing.py)
        result.extra["thread"] = d.threads.busiest()
        with contextlib.suppress(OSError, ValueError):
            result.extra["work"] = json.loads(work_path(d.log_path).read_text())
    return results


def _analyse(target: Target, replies: list[tuple[int, int, object]], stamps: np.ndarray, expected: np.ndarray,
             rate: float, joints: int, *, node_cpu: float, driver_cpu: float, busy: float,
             wall: float, turns: Sequence[int] = ()) -> LatencyResult:
    n = stamps.size
    key = expected[:, 0]  # strictly increasing; index = sequence number (0 = rest)
    half_gap = 0.5 * float(np.min(np.diff(key)))
    latencies: list[float] = []
    seen = np.zeros(n + 1, dtype=bool)
    duplicates = undecoded = inexact = from_data = 0
    max_err = 0.0
    for t_recv, offset, values in replies:
        row = np.asarray(values, dtype=float)
        if row.size != joints:
            undecoded += 1
            continue
        if 1 <= offset <= n:
            k = int(offset)
        else:
            if abs(row[0] - key[0]) <= half_gap:
                continue  # a late reply to the warm-up's rest value
            k = int(np.clip(np.searchsorted(key, row[0]), 1, n))
            if k > 1 and abs(key[k - 1] - row[0]) < abs(key[k] - row[0]):
                k -= 1
            if abs(key[k] - row[0]) > half_gap:
                undecoded += 1
                continue
            from_data += 1
        err = float(np.max(np.abs(row - expected[k]) / np.maximum(1.0, np.abs(expected[k]))))
        max_err = max(max_err, err)
        inexact += err > 1e-9
        if seen[k]:
            duplicates += 1
            continue
        seen[k] = True
        latencies.append((t_recv - int(stamps[k - 1])) * 1e-3)
    lat = np.asarray(latencies)
    received = int(seen.sum())
    # send intervals within each turn (the pause from one turn to the next is not a send interval)
    keep = np.ones(max(n - 1, 0), dtype=bool)
    for b in turns:
        if 0 < b < n:
            keep[b - 1] = False
    intervals = np.diff(stamps)[keep] * 1e-3
    span = float(intervals.sum()) * 1e-6

    def pct(q: float) -> float:
        return float(np.percentile(lat, q)) if lat.size else float("nan")

    return LatencyResult(
        label=target.label, joints=joints, target_rate_hz=rate, sent=n, received=received, lost=n - received,
        duplicates=duplicates, undecoded=undecoded, seq_from_data=from_data, inexact=int(inexact),
        max_output_error=max_err,
        send_rate_hz=float(intervals.size / span) if span > 0 else float("nan"),
        send_interval_p99_us=float(np.percentile(intervals, 99)) if intervals.size else float("nan"),
        p50_us=pct(50), p99_us=pct(99), max_us=float(lat.max()) if lat.size else float("nan"),
        mean_us=float(lat.mean()) if lat.size else float("nan"),
        node_cpu_pct=100.0 * node_cpu / wall,
        node_cpu_us_per_msg=1e6 * node_cpu / received if received else float("nan"),
        driver_cpu_pct=100.0 * driver_cpu / wall,
        other_cpu_pct=100.0 * max(0.0, busy - node_cpu - driver_cpu) / wall,
    )


# --------------------------------------------------------------------------- the targets
# --------------------------------------------------------------------------- outside load
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
