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
import os
import pathlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
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
    """

    label: str
    make_process: Callable[[pathlib.Path], ChildProcess]
    in_topic: str
    out_topic: str
    fir: SparseFir


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

    def __init__(self, in_topic: str, out_topic: str, context: rclpy.context.Context) -> None:
        super().__init__("bench_driver", context=context)
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
    """Start ``target``, drive it for ``seconds`` at ``rate`` and measure the round trips.

    Parameters
    ----------
    target : Target
        The node under test.
    seconds : float
        Duration of the measured ramp, s (``round(seconds * rate)`` messages).
    rate : float
        Send rate, Hz.
    joints : int
        Values per message.
    warmup : float
        Zeros are sent for this long after the first reply, s.
    drain : float
        Time to keep receiving after the last send, s.
    discovery_timeout : float
        Longest wait for the node to start and be discovered, s.
    log_dir : pathlib.Path
        Where the node's log goes.
    progress : callable
        Receives progress messages.

    Raises
    ------
    RuntimeError
        If the node dies, is not discovered, or never replies.
    """
    n = max(2, round(seconds * rate))
    data = ramp(n, joints)
    expected = expected_output(target.fir, data)
    log_path = log_dir / f"{target.label.replace(' ', '_')}.log"
    proc = target.make_process(log_path)
    context = rclpy.context.Context()
    rclpy.init(args=[], context=context)
    executor = SingleThreadedExecutor(context=context)
    driver = None
    try:
        popen = proc.start().proc
        assert popen is not None  # (start() sets it)

        def alive() -> None:
            if not proc.running():
                raise RuntimeError(f"{target.label}: node exited ({popen.returncode});"
                                   f" log {log_path}:\n{log_tail(log_path)}")

        driver = Driver(target.in_topic, target.out_topic, context)
        executor.add_node(driver)
        t0 = time.monotonic()
        if not _spin_until(executor, driver.discovered, discovery_timeout, alive):
            raise RuntimeError(f"{target.label}: not discovered within {discovery_timeout:g} s;"
                               f" log {log_path}:\n{log_tail(log_path)}")
        progress(f"{target.label}: discovered after {time.monotonic() - t0:.1f} s; warming up")

        # warm-up: zeros until the first reply, then `warmup` s more
        stop = threading.Event()
        sender = threading.Thread(target=driver.send_paced, args=(data[:1], rate), kwargs={"stop": stop}, daemon=True)
        sender.start()
        try:
            if not _spin_until(executor, lambda: bool(driver.replies), discovery_timeout, alive):
                raise RuntimeError(f"{target.label}: no reply within {discovery_timeout:g} s;"
                                   f" log {log_path}:\n{log_tail(log_path)}")
            end = time.monotonic() + warmup
            _spin_until(executor, lambda: time.monotonic() >= end, warmup + 1.0)
        finally:
            stop.set()
            sender.join()
        _spin_until(executor, lambda: False, 0.1)  # let the last zeros come back
        driver.replies.clear()

        # measurement: the ramp 1..n
        stamps = np.zeros(n, dtype=np.int64)
        pid = popen.pid
        node_cpu0, driver_cpu0, busy0 = proc_cpu_seconds(pid), self_cpu_seconds(), machine_busy_seconds()
        wall0 = time.perf_counter()
        sender = threading.Thread(target=driver.send_paced, args=(data[1:], rate),
                                  kwargs={"stamps": stamps, "first_seq": 1},
                                  daemon=True)
        sender.start()
        _spin_until(executor, lambda: not sender.is_alive(), seconds * 10 + 10)
        sender.join()
        node_cpu1, driver_cpu1, busy1 = proc_cpu_seconds(pid), self_cpu_seconds(), machine_busy_seconds()
        wall1 = time.perf_counter()
        end = time.monotonic() + drain
        _spin_until(executor, lambda: time.monotonic() >= end, drain + 1.0)
        alive()
        replies = list(driver.replies)
    finally:
        if driver is not None:
            executor.remove_node(driver)
            driver.destroy_node()
        executor.shutdown()
        context.try_shutdown()
        code = proc.stop()
        if code not in (0, None, -signal.SIGINT):
            progress(f"{target.label}: node exited with {code} (log {log_path})")

    return _analyse(target, replies, stamps, expected, rate, joints,
                    node_cpu=(node_cpu1 - node_cpu0), driver_cpu=(driver_cpu1 - driver_cpu0),
                    busy=(busy1 - busy0), wall=(wall1 - wall0))


def _analyse(target: Target, replies: list[tuple[int, int, object]], stamps: np.ndarray, expected: np.ndarray,
             rate: float, joints: int, *, node_cpu: float, driver_cpu: float, busy: float,
             wall: float) -> LatencyResult:
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
    intervals = np.diff(stamps) * 1e-3
    span = (stamps[-1] - stamps[0]) * 1e-9

    def pct(q: float) -> float:
        return float(np.percentile(lat, q)) if lat.size else float("nan")

    return LatencyResult(
        label=target.label, joints=joints, target_rate_hz=rate, sent=n, received=received, lost=n - received,
        duplicates=duplicates, undecoded=undecoded, seq_from_data=from_data, inexact=int(inexact),
        max_output_error=max_err,
        send_rate_hz=float((n - 1) / span) if span > 0 else float("nan"),
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


def echo_target(in_topic: str = "/bench/echo_in", out_topic: str = "/bench/echo_out") -> Target:
    """The bare echo node (:mod:`benchmarks.echo_node`) run with this interpreter."""

    def make(log_path: pathlib.Path) -> ChildProcess:
        cmd = [sys.executable, "-m", "benchmarks.echo_node", "--in", in_topic, "--out", out_topic]
        return ChildProcess(cmd, log_path, cwd=REPO_ROOT)

    return Target("echo (baseline)", make, in_topic, out_topic, identity_fir())


def shaper_target(label: str, joints: int, rate: float, params: Mapping[str, Any] | None = None) -> Target:
    """The real shaper node (``shaper_nodes shaper_node``) with ``joints`` joints at ``rate``.

    ``params`` are extra node parameters (``shaper.*``, ``discretization``); the FIR used for
    decoding is designed from them exactly as the node does.
    """
    from shaper_nodes.core.shaping import Mode, design, discretize
    from shaper_nodes.ros.launching import NodeProcess

    params = dict(params or {})
    family = str(params.get("shaper.family", "none"))
    mode = Mode.from_hz(float(params.get("shaper.frequency_hz", 10.0)), float(params.get("shaper.damping_ratio", 0.05)))
    shaper = design(family, [mode], derivative_order=int(params.get("shaper.derivative_order", 2)),
                    vibration_tolerance=float(params.get("shaper.vibration_tolerance", 0.05)))
    fir = discretize(shaper, rate, str(params.get("discretization", "split")))
    node_params = {"joint_names": [f"joint_{i + 1}" for i in range(joints)], "command_rate": float(rate), **params}

    def make(log_path: pathlib.Path) -> NodeProcess:
        return NodeProcess("shaper_nodes", "shaper_node", node_params, log_path=log_path)

    return Target(label, make, "/shaper/commands", "/forward_position_controller/commands", fir)
