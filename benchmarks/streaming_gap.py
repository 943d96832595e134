"""The shaper node's streaming path while whole trajectories are shaped: its largest gap.

The shaper node streams one setpoint per command period on its array path and shapes whole
trajectories (topic, ``~/shape_trajectory``, FollowJointTrajectory) in a callback group of its own
on a multi-threaded executor. This benchmark drives the array path at ``rate`` from a paced
thread (:class:`benchmarks.latency_driver.Driver`) and records when each shaped setpoint comes back,
in two windows of the same run:

baseline
    streaming only;
loaded
    streaming while a second process (its own DDS participant, so that its work does not stall
    the driver) sends the largest whole trajectory the node accepts on its trajectory topic, over
    and over, each :data:`REST` s after the previous one came back shaped (the service and the
    action do the same work in the node: shape, check, build and convert one message).

Figures: the largest interval between two shaped setpoints arriving (``gap``), its 99.9th
percentile, how many intervals exceed two command periods, and the largest send-to-reply latency,
per window; and the ratio loaded / baseline. The baseline carries the driver's own jitter and
the machine's; only the difference is the node's. Not a pass/fail test.
"""

from __future__ import annotations

import multiprocessing as mp
import pathlib
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

JOINTS = 6
#: s between a shaped trajectory coming back and the next one sent
REST = 0.5


@dataclass
class Window:
    """One window's arrivals."""

    label: str
    sent: int
    replies: int
    gap_ms: float
    gap_p999_ms: float
    over_two_periods: int
    latency_max_ms: float
    trajectories: int = 0
    node_lag_ms: float = float("nan")  # the node's own largest queueing lag (its /diagnostics)


def _trajectory(points: int, span: float, joints: int) -> Any:
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    msg = JointTrajectory(joint_names=[f"joint_{i + 1}" for i in range(joints)])
    times = np.linspace(0.0, span, points)
    pos = 0.2 * np.sin(2 * np.pi * times[:, None] / max(span, 1e-3) + np.arange(joints)[None, :])
    for t, p in zip(times, pos, strict=True):
        ns = int(round(t * 1e9))
        msg.points.append(JointTrajectoryPoint(positions=p.tolist(),
                                               time_from_start=Duration(sec=ns // 10**9, nanosec=ns % 10**9)))
    return msg


def _loader(points: int, span: float, stop: Any, ready: Any, count: Any) -> None:
    """In its own process: send whole trajectories on the node's trajectory topic until ``stop`` is set,
    each as soon as the shaped one came back. The shaped trajectories are taken as serialized bytes
    (``raw``), so that this process does not spend a core decoding them: on two cores that would be
    load the node's stream pays for, not the node's own work."""
    import rclpy
    from rclpy.node import Node
    from trajectory_msgs.msg import JointTrajectory

    rclpy.init()
    node = Node("bench_trajectory_loader")
    got = threading.Event()
    node.create_subscription(JointTrajectory, "/joint_trajectory_controller/joint_trajectory",
                             lambda _m: got.set(), 10, raw=True)
    pub = node.create_publisher(JointTrajectory, "/shaper/joint_trajectory", 10)
    msg = _trajectory(points, span, JOINTS)
    end = time.monotonic() + 30.0
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    ready.set()
    k = 0
    while not stop.is_set():
        got.clear()
        pub.publish(msg)
        deadline = time.monotonic() + 120.0
        while not got.is_set() and not stop.is_set() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        k += 1
        count.value = k
        rest = time.monotonic() + REST  # one trajectory at a time, as a robot's moves come
        while not stop.is_set() and time.monotonic() < rest:
            rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()
    rclpy.shutdown()


def measure(seconds: float = 8.0, rate: float = 1000.0, points: int | None = None, span: float | None = None,
            progress: Any = lambda s: None) -> list[Window]:
    """Baseline and loaded windows of ``seconds`` each (see the module docstring)."""
    import rclpy
    import rclpy.context
    from rclpy.executors import SingleThreadedExecutor

    from benchmarks.latency_driver import Driver
    from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
    from shaper_nodes.nodes.shaper import DEFAULT_MAX_SAMPLES
    from shaper_nodes.ros.launching import NodeProcess

    fir_len = 300  # a zvd shaper at 5 Hz is ~0.2 s: room for it within the samples limit
    span = span or (DEFAULT_MAX_SAMPLES - fir_len - 4) / rate  # default: the longest span the node accepts
    points = points or min(MAX_TRAJECTORY_POINTS, 1000)
    params = {"joint_names": [f"joint_{i + 1}" for i in range(JOINTS)], "command_rate": rate,
              "shaper.family": "zvd", "shaper.frequency_hz": 5.0, "shaper.damping_ratio": 0.05}
    log = pathlib.Path(tempfile.mkdtemp(prefix="gap_")) / "shaper.log"
    proc = NodeProcess("shaper_nodes", "shaper_node", params, log_path=log).start()
    ctx = rclpy.context.Context()
    rclpy.init(args=[], context=ctx)
    driver = Driver("/shaper/commands", "/forward_position_controller/commands", ctx)
    lags: list[float] = []

    def on_diag(msg: Any) -> None:
        for st in msg.status:
            if st.name.endswith(": shaper"):
                kv = {k.key: k.value for k in st.values}
                if "input.array.largest_lag_ms" in kv:
                    lags.append(float(kv["input.array.largest_lag_ms"]))

    from diagnostic_msgs.msg import DiagnosticArray
    driver.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(driver)
    mpx = mp.get_context("spawn")
    stop, ready, count = mpx.Event(), mpx.Event(), mpx.Value("i", 0)
    loader = None
    windows: list[Window] = []
    try:
        end = time.monotonic() + 60.0
        while not driver.discovered():
            if time.monotonic() > end or not proc.running():
                raise RuntimeError(f"the shaper node was not discovered (log: {log})")
            ex.spin_once(timeout_sec=0.05)
        rows = np.zeros((1, JOINTS))
        for label in ("baseline", "loaded"):
            if label == "loaded":
                loader = mpx.Process(target=_loader, args=(points, span, stop, ready, count), daemon=True)
                loader.start()
                if not ready.wait(60.0):
                    raise RuntimeError("the trajectory loader did not find the node")
                while count.value < 1 and loader.is_alive():  # the first trajectory is through: the load is on
                    ex.spin_once(timeout_sec=0.05)
            progress(f"streaming gap: {label} window, {seconds:g} s at {rate:g} Hz"
                     + (f" with trajectories of {span:g} s ({points} points)" if label == "loaded" else ""))
            driver.replies.clear()
            _spin_for(ex, 1.1)  # a diagnostics period: the window's lag figures start clean
            lags.clear()
            n = int(seconds * rate)
            stamps = np.zeros(n, dtype=np.int64)
            first = 1_000_000 * (len(windows) + 1)
            done0 = count.value
            sender = threading.Thread(target=driver.send_paced, args=(np.repeat(rows, n, axis=0), rate, stamps),
                                      kwargs={"first_seq": first})
            sender.start()
            while sender.is_alive():
                ex.spin_once(timeout_sec=0.01)
            _spin_for(ex, 0.5)
            windows.append(_window(label, driver.replies, stamps, first, rate, count.value - done0))
            windows[-1].node_lag_ms = max(lags, default=float("nan"))
    finally:
        stop.set()
        if loader is not None:
            loader.join(10.0)
            if loader.is_alive():
                loader.kill()
        ex.shutdown()
        driver.destroy_node()
        rclpy.shutdown(context=ctx)
        proc.stop()
    return windows


def _spin_for(ex: Any, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)


def _window(label: str, replies: list[tuple[int, int, object]], stamps: np.ndarray, first: int, rate: float,
            trajectories: int) -> Window:
    t = np.array([r[0] for r in replies if r[1] >= first], dtype=np.int64)
    seq = np.array([r[1] - first for r in replies if r[1] >= first], dtype=np.int64)
    ok = (seq >= 0) & (seq < stamps.size)
    lat = (t[ok] - stamps[seq[ok]]) * 1e-6 if ok.any() else np.array([np.nan])
    gaps = np.diff(t) * 1e-6 if t.size > 1 else np.array([np.nan])
    return Window(label, int(stamps.size), int(t.size), float(np.max(gaps)), float(np.percentile(gaps, 99.9)),
                  int(np.sum(gaps > 2e3 / rate)), float(np.max(lat)), trajectories)


@dataclass
class Stall:
    """How long a thread of the node's process waited for the interpreter while a whole trajectory of
    ``samples`` samples was shaped on ``path``."""

    path: str
    samples: int
    work_ms: float
    baseline_gap_ms: float
    stall_gap_ms: float


def interpreter_stalls(sizes: tuple[int, ...] = (5_000, 10_000, 30_000, 60_000), rate: float = 1000.0) -> list[Stall]:
    """The node's own share of the streaming gap, free of the other processes of a 2-core machine.

    A real ``ShaperNode`` runs in this process, its interpreter tuned as its ``main`` does. A ticker
    thread wakes every 0.5 ms, as the streaming thread does for each setpoint at 2 kHz, and records the
    largest interval between its wake-ups; meanwhile this thread does what the side node's thread does
    for one trajectory: on the topic path, hand the serialized message to the worker process and publish
    the bytes it returns (``_on_trajectory``); on the service path, shape in this process
    (``_on_shape_trajectory``) and serialize the answer, as rclpy does before sending it. The interval
    beyond the ticker's own in a quiet second before (``baseline``) is time the streaming thread would
    have waited for the interpreter.
    """
    import rclpy
    import rclpy.context
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message

    from shaper_msgs.srv import ShapeTrajectory
    from shaper_nodes.nodes import shaper as shaper_module

    shaper_module._tune_interpreter()
    ctx = rclpy.context.Context()
    rclpy.init(args=[], context=ctx, domain_id=202)
    node = shaper_module.ShaperNode(context=ctx, parameter_overrides=[
        Parameter("joint_names", value=[f"joint_{i + 1}" for i in range(JOINTS)]),
        Parameter("command_rate", value=rate), Parameter("shaper.family", value="zvd"),
        Parameter("shaper.frequency_hz", value=5.0), Parameter("limits.max_trajectory_samples", value=300_000)])
    gaps: list[float] = []
    stop = threading.Event()

    def tick() -> None:
        last = time.perf_counter()
        while not stop.is_set():
            time.sleep(5e-4)
            now = time.perf_counter()
            gaps.append(now - last)
            last = now

    def service(msg: Any) -> None:
        resp = node._on_shape_trajectory(ShapeTrajectory.Request(trajectory=msg), ShapeTrajectory.Response())
        serialize_message(resp)

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    out: list[Stall] = []
    try:
        node._on_trajectory(serialize_message(_trajectory(10, 1.0, JOINTS)))  # the worker started
        for n in sizes:
            msg = _trajectory(500, (n - 300) / rate, JOINTS)
            for path, work in (("topic (worker process)", lambda m=msg: node._on_trajectory(serialize_message(m))),
                               ("service (side thread)", lambda m=msg: service(m))):
                gaps.clear()
                time.sleep(1.0)
                base = max(gaps)
                gaps.clear()
                t0 = time.perf_counter()
                work()
                elapsed = time.perf_counter() - t0
                out.append(Stall(path, n, 1e3 * elapsed, 1e3 * base, 1e3 * max(gaps, default=0.0)))
    finally:
        stop.set()
        ticker.join()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    return out


def print_stalls(stalls: list[Stall]) -> None:
    print("\nInterpreter stalls of the node's process while one whole trajectory is shaped"
          " (in-process ticker every 0.5 ms; benchmarks/streaming_gap.py)")
    print(f"{'path':<24}{'samples':>8}{'work ms':>10}{'quiet gap ms':>14}{'gap while shaping ms':>22}{'ratio':>8}")
    for st in stalls:
        print(f"{st.path:<24}{st.samples:>8}{st.work_ms:>10.1f}{st.baseline_gap_ms:>14.2f}{st.stall_gap_ms:>22.2f}"
              f"{st.stall_gap_ms / max(st.baseline_gap_ms, 1e-9):>8.2f}")


def print_windows(windows: list[Window], rate: float) -> None:
    print(f"\nShaper node streaming path at {rate:g} Hz (array path, {JOINTS} joints) while whole trajectories"
          " are shaped (benchmarks/streaming_gap.py)")
    print(f"{'window':<10}{'sent':>7}{'replies':>9}{'traj':>6}{'gap ms':>9}{'p99.9 ms':>10}{'>2 periods':>12}"
          f"{'max latency ms':>16}{'node lag ms':>13}")
    for w in windows:
        print(f"{w.label:<10}{w.sent:>7}{w.replies:>9}{w.trajectories:>6}{w.gap_ms:>9.2f}{w.gap_p999_ms:>10.2f}"
              f"{w.over_two_periods:>12}{w.latency_max_ms:>16.2f}{w.node_lag_ms:>13.2f}")
    if len(windows) == 2 and windows[0].gap_ms > 0:
        print(f"loaded / baseline: largest gap x{windows[1].gap_ms / windows[0].gap_ms:.2f},"
              f" max latency x{windows[1].latency_max_ms / max(windows[0].latency_max_ms, 1e-9):.2f}")


def _stalls_in_child(queue: Any) -> None:
    queue.put([asdict(s) for s in interpreter_stalls()])


def run(progress: Any = lambda s: None) -> dict:
    """``python -m benchmarks``: the DDS windows at 1 kHz with the largest trajectory the node accepts by
    default, and the interpreter stalls (in a child process: they tune its interpreter as the node does)."""
    windows = measure(progress=progress)
    progress("streaming gap: interpreter stalls per trajectory size")
    mpx = mp.get_context("spawn")
    queue = mpx.Queue()
    child = mpx.Process(target=_stalls_in_child, args=(queue,))
    child.start()
    stalls = queue.get(timeout=600)
    child.join(30)
    return {"rate": 1000.0, "windows": [asdict(w) for w in windows], "stalls": stalls}


def print_table(result: dict) -> None:
    print_windows([Window(**w) for w in result["windows"]], result["rate"])
    print_stalls([Stall(**s) for s in result["stalls"]])


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--points", type=int, default=None, help="input points per trajectory (default 1000)")
    ap.add_argument("--span", type=float, default=None, help="trajectory span, s (default: the longest accepted)")
    ap.add_argument("--stalls-only", action="store_true", help="only the in-process interpreter stalls")
    a = ap.parse_args(argv)
    if not a.stalls_only:
        windows = measure(a.seconds, a.rate, a.points, a.span, progress=print)
        print_windows(windows, a.rate)
    print_stalls(interpreter_stalls(rate=a.rate))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
