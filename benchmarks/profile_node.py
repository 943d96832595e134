"""Where a node's time goes per message: cProfile of the node (every thread) under the latency driver.

``python -m benchmarks.profile_node [--target shaper|echo] [--seconds S] [--top N]`` starts the
node as :mod:`benchmarks.latency` does, but under :mod:`benchmarks._profiled` (cProfile in every
thread of the node's process, one profile per thread, merged at exit), drives it at 1 kHz with 7
joints for ``seconds``, and prints the functions with the most own time and the most cumulative
time, per message driven. cProfile slows Python code down (about 2x on small calls), so the
shares matter, not the absolute times; the latency figures of such a run are not comparable with
``./run bench``.
"""

from __future__ import annotations

import argparse
import pathlib
import pstats
import sys
import tempfile

from shaper_nodes.ros.launching import ChildProcess

from .latency import measure
from .latency_targets import REPO_ROOT, Target, echo_target, identity_fir, shaper_target

ZVD = {"shaper.family": "zvd", "shaper.frequency_hz": 8.0, "shaper.damping_ratio": 0.03, "discretization": "split"}


def profiled_target(kind: str, out: pathlib.Path, joints: int, rate: float) -> Target:
    """The echo or shaper ZVD target, run under the profiler writing to ``out``."""
    base = echo_target() if kind == "echo" else shaper_target("shaper zvd 8 Hz", joints, rate, ZVD)
    if kind == "echo":
        cmd = ["-m", "benchmarks.echo_node", "--in", base.in_topic, "--out", base.out_topic]
        fir = identity_fir()
    else:
        cmd = base.argv
        fir = base.fir

    def make(log_path: pathlib.Path) -> ChildProcess:
        return ChildProcess([sys.executable, "-m", "benchmarks._profiled", str(out), *cmd], log_path, cwd=REPO_ROOT)

    return Target(f"{base.label} (profiled)", make, base.in_topic, base.out_topic, fir)


#: the functions of the per-message table: (label, file suffix, function name), cumulative CPU time each
KEY_FUNCTIONS = (
    ("executor: one spin_once (wait set, take, callback)", "rclpy/executors.py", "_spin_once_impl"),
    ("executor: wait set built and waited on", "rclpy/executors.py", "_wait_for_ready_callbacks"),
    ("rcl_wait itself", "~", "<built-in method rclpy._rclpy_pybind11.wait>"),
    ("take (deserialise the message)", "rclpy/subscription.py", "handle.take_message"),
    ("take_message (C)", "~", "<built-in method rclpy._rclpy_pybind11.take_message>"),
    ("take loop: one wake-up's messages taken and served", "ros/take_loop.py", "_drain"),
    ("callback: echo's publish / shaper's _on_array", "", "_on_array"),
    ("  decode (the serialized input read)", "recordings/cdr_arrays.py", "decode"),
    ("  encode (the serialized answer written)", "recordings/cdr_arrays.py", "encode"),
    ("  read_sample (one sample's bytes read)", "recordings/cdr_arrays.py", "read_sample"),
    ("  write_sample (its answer packed)", "recordings/cdr_arrays.py", "write_sample"),
    ("  shape_values (rules and filter)", "core/shaping/stream.py", "shape_values"),
    ("    the FIR's step (written-out taps)", "", "tap_step"),
    ("  arrived (rate watch)", "ros/stream_watch.py", "arrived"),
    ("  finite_array", "core/checks.py", "finite_array"),
    ("  _shape_checked", "core/shaping/stream.py", "_shape_checked"),
    ("  shape_array", "core/shaping/stream.py", "shape_array"),
    ("    deepcopy", "copy.py", "deepcopy"),
    ("    StreamingShaper.process", "core/shaping/fir.py", "process"),
    ("    JointLimits.check", "core/shaping/limits.py", "check"),
    ("  Float64MultiArray()", "std_msgs/msg/_float64_multi_array.py", "__init__"),
    ("  Publisher.publish", "rclpy/publisher.py", "publish"),
    ("  publish (C: serialise, write)", "~", "<built-in method rclpy._rclpy_pybind11.publish>"),
    ("  publish_raw (C: write the bytes)", "~", "<built-in method rclpy._rclpy_pybind11.publish_raw>"),
    ("  count_forwarded", "ros/stream_watch.py", "count_forwarded"),
)


def print_per_message(stats: pstats.Stats, messages: int, top: int) -> None:
    """The CPU time of :data:`KEY_FUNCTIONS` per message handled, then the top functions by own time."""
    raw = stats.stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in raw.values())
    print(f"CPU time profiled in all: {total:.2f} s; per message handled ({messages}): {1e6 * total / messages:.0f} us"
          " (startup included)")
    print(f"  {'function':<52}{'calls/msg':>10}{'cum us/msg':>12}{'own us/msg':>12}")
    for label, path, name in KEY_FUNCTIONS:
        hits = [(k, v) for k, v in raw.items() if k[2] == name and k[0].endswith(path)]
        if not hits:
            continue
        calls = sum(v[1] for _, v in hits)
        cum = sum(v[3] for _, v in hits)
        own = sum(v[2] for _, v in hits)
        print(f"  {label:<52}{calls / messages:>10.2f}{1e6 * cum / messages:>12.1f}{1e6 * own / messages:>12.1f}")
    print(f"\n--- top {top} by own CPU time")
    stats.sort_stats("tottime").print_stats(top)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.profile_node", description=__doc__.split("\n")[0])
    p.add_argument("--target", choices=("shaper", "echo"), default="shaper")
    p.add_argument("--seconds", type=float, default=10.0, help="driven time, s (default 10)")
    p.add_argument("--rate", type=float, default=1000.0, help="Hz (default 1000)")
    p.add_argument("--joints", type=int, default=7)
    p.add_argument("--top", type=int, default=25, help="functions listed per table (default 25)")
    p.add_argument("--save", type=pathlib.Path, help="keep the merged profile in this file (pstats)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="shaper_profile_") as tmp:
        out = pathlib.Path(args.save or pathlib.Path(tmp) / "node.prof").resolve()
        target = profiled_target(args.target, out, args.joints, args.rate)
        res = measure(target, seconds=args.seconds, rate=args.rate, joints=args.joints, log_dir=pathlib.Path(tmp),
                      progress=lambda s: print(f"[profile] {s}", file=sys.stderr))
        print(f"{res.label}: {res.sent} sent, {res.lost} lost, node CPU {res.node_cpu_pct:.1f} % of a core,"
              f" p50 {res.p50_us:.0f} us (profiled: slower than unprofiled)")
        if not out.exists():
            print(f"no profile written ({out})", file=sys.stderr)
            return 1
        stats = pstats.Stats(str(out))
        print_per_message(stats, res.sent - res.lost, args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
