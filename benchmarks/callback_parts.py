"""Where a streamed message's time goes inside the node: wake-up, callback, and the callback's parts.

``python -m benchmarks.callback_parts [--seconds S] [--hog]`` runs the echo node's pattern, the floor (the
echo's raw bytes on the shaper's take loop, as ``python -m benchmarks.echo_node --take``) and the shaper
node (ZVD 8 Hz, 7 joints, 1 kHz) at once, each in a process of its own started through this module, and
drives them in turns (:func:`benchmarks.latency.measure_interleaved`); ``--hog`` runs the bench's busy-loop
process on the last core meanwhile. In the node's process it wraps the callback and, for the shaper, its
parts (``_arrived``, ``_shape_values``, the filter's ``process_values``, the publish, ``_count_forwarded``
and ``_passed`` (the bookkeeping after the publish), the codec's ``read_sample`` and ``write_sample`` of the
serialized messages, or its ``decode`` and ``encode`` when those read them) with wall-clock timers, and
prints per node:

``wake``
    from the middleware's reception of the message (its ``received_timestamp``) to the callback's start:
    the executor's (or the take loop's) wake-up, wait set and take;
``callback``
    the callback's wall time, and the parts' (p50 and p90 over the driven messages).

These are the times of the code as it runs at 1 kHz, one message at a time, with the caches cold
from the wait between messages: a tight loop (``benchmarks.fir_throughput``) runs the same code hot
and can rank two versions the other way. The timers add well under a microsecond each. The echo and the
floor here take the message info (a two-argument callback, as the shaper does) so that all take the same
path through rclpy; the bench's echo node does not.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import json
import pathlib
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

#: the shaper's parts timed in the node: (name in the results, its module, class and method)
SHAPER_PARTS = (("_arrived", "shaper_nodes.ros.stream_watch", "StreamWatch", "arrived"),
                ("_shape_values", "shaper_nodes.core.shaping.stream", "CommandStream", "shape_values"),
                ("_count_forwarded", "shaper_nodes.ros.stream_watch", "StreamWatch", "count_forwarded"),
                ("_passed", "shaper_nodes.ros.stream_watch", "StreamWatch", "passed"),
                # the array input's serialized bytes read and the answer's written (ros/raw_stream.py): one sample
                # of the last layout by read_sample / write_sample, anything else by decode / encode
                ("codec.read_sample", "shaper_nodes.recordings.cdr_arrays", "Float64ArrayCodec", "read_sample"),
                ("codec.write_sample", "shaper_nodes.recordings.cdr_arrays", "Float64ArrayCodec", "write_sample"),
                ("codec.decode", "shaper_nodes.recordings.cdr_arrays", "Float64ArrayCodec", "decode"),
                ("codec.encode", "shaper_nodes.recordings.cdr_arrays", "Float64ArrayCodec", "encode"))
#: the floor's topics (the echo's raw bytes on the take loop, beside the echo)
FLOOR_IN, FLOOR_OUT = "/bench/floor_parts_in", "/bench/floor_parts_out"
ZVD = {"shaper.family": "zvd", "shaper.frequency_hz": 8.0, "shaper.damping_ratio": 0.03, "discretization": "split"}


def _timed(name: str, fn: Callable[..., Any], parts: dict[str, list[int]]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter_ns()
        out = fn(*args, **kwargs)
        parts.setdefault(name, []).append(time.perf_counter_ns() - t)
        return out
    return wrapper


def _node_main(kind: str, out: str, argv: list[str]) -> None:
    """In the node's process: run the echo pattern or the shaper node with the timers; write them at exit."""
    parts: dict[str, list[int]] = {}
    wake: list[int] = []

    def dump() -> None:
        pathlib.Path(out).write_text(json.dumps({"wake": wake, **parts}))

    atexit.register(dump)

    def timed_callback(callback: Callable[[Any, Any], None]) -> Callable[[Any, Any], None]:
        def wrapper(msg: Any, info: Any) -> None:
            t0 = time.time_ns()
            wake.append(t0 - int(info["received_timestamp"]))
            t = time.perf_counter_ns()
            callback(msg, info)
            parts.setdefault("callback", []).append(time.perf_counter_ns() - t)
        return wrapper

    if kind == "shaper":
        from shaper_nodes.nodes import shaper as shaper_module

        cls = shaper_module.ShaperNode
        for name, module, owner, method in SHAPER_PARTS:  # before the node is made: it binds them
            owner_cls = getattr(importlib.import_module(module), owner)
            if hasattr(owner_cls, method):  # (an older checkout's code may lack a part: not timed then)
                setattr(owner_cls, method, _timed(name, getattr(owner_cls, method), parts))
        on_array = cls._on_array

        def timed_on_array(self: Any, msg: Any, info: Any) -> None:
            t0 = time.time_ns()
            wake.append(t0 - int(info["received_timestamp"]))
            if "callback" not in parts:  # the filter and the publisher exist once the node runs
                f = self._array_filter
                f.process_values = _timed("filter.process_values", f.process_values, parts)
                self._array_pub.publish = _timed("publish", self._array_pub.publish, parts)
            t = time.perf_counter_ns()
            on_array(self, msg, info)
            parts.setdefault("callback", []).append(time.perf_counter_ns() - t)

        cls._on_array = timed_on_array  # type: ignore[method-assign,assignment]  # before the node is made: its subscription takes this
        sys.argv = [sys.argv[0], *argv]
        shaper_module.main()
        return
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import Float64MultiArray

    from shaper_nodes.ros.side_node import SideNode

    from .echo_node import DEPTH, IN_TOPIC, OUT_TOPIC, stop_signal_handlers

    in_topic, out_topic = (FLOOR_IN, FLOOR_OUT) if kind == "floor" else (IN_TOPIC, OUT_TOPIC)
    context = rclpy.context.Context()
    rclpy.init(args=argv, context=context, signal_handler_options=SignalHandlerOptions.ALL)
    node = rclpy.create_node(f"bench_{kind}_parts", context=context)
    side = SideNode(node, "take", take=True) if kind == "floor" else None
    on = node if side is None else side.node  # the floor: the echo's raw bytes on the shaper's take loop
    pub = on.create_publisher(Float64MultiArray, out_topic, DEPTH)
    publish = _timed("publish", pub.publish, parts)
    callback: Any = timed_callback(lambda msg, info: publish(msg))  # two arguments: rclpy passes the info
    on.create_subscription(Float64MultiArray, in_topic, callback, DEPTH, raw=side is not None)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    if side is not None:
        side.start()
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop_signal_handlers()  # before any executor is shut down (echo_node.py)
        executor.shutdown()
        if side is not None:
            side.close()
        node.destroy_node()
        context.try_shutdown()


def run(seconds: float = 30.0, progress: Callable[[str], None] = print,
        hog: bool = False) -> dict[str, dict[str, tuple[float, float]]]:
    """Drive the three nodes for ``seconds`` each in 5 s turns (``hog``: with the bench's busy-loop process on
    the last core); per node and part, (p50, p90) in us."""
    from shaper_nodes.ros.launching import ChildProcess

    from .cpu_hog import CpuHog
    from .latency import measure_interleaved
    from .latency_targets import REPO_ROOT, Target, echo_target, identity_fir, shaper_target

    echo, zvd = echo_target(), shaper_target("shaper zvd 8 Hz", 7, 1000.0, ZVD)
    with tempfile.TemporaryDirectory(prefix="callback_parts_") as tmp:
        files = {k: pathlib.Path(tmp) / f"{k}.json" for k in ("echo", "floor", "shaper")}

        def make(kind: str, argv: list[str]) -> Callable[[pathlib.Path], ChildProcess]:
            def start(log_path: pathlib.Path) -> ChildProcess:
                cmd = [sys.executable, "-m", "benchmarks.callback_parts", "--node", kind, str(files[kind]), *argv]
                return ChildProcess(cmd, log_path, cwd=REPO_ROOT)
            return start

        targets = [Target("echo (two-argument callback)", make("echo", []), echo.in_topic, echo.out_topic,
                          identity_fir()),
                   Target("echo, take loop (two-argument callback)", make("floor", []), FLOOR_IN, FLOOR_OUT,
                          identity_fir()),
                   Target(zvd.label, make("shaper", zvd.argv[1:]), zvd.in_topic, zvd.out_topic, zvd.fir)]
        with CpuHog() if hog else contextlib.nullcontext():
            results = measure_interleaved(targets, seconds=seconds, rounds=max(1, round(seconds / 5)),
                                          log_dir=pathlib.Path(tmp), progress=progress)
        n = round(seconds * 1000)
        out: dict[str, dict[str, tuple[float, float]]] = {}
        for (kind, path), res in zip(files.items(), results, strict=True):
            timers = json.loads(path.read_text())
            table = {"round trip (driver)": (res.p50_us, float("nan"))}
            for name, values in timers.items():
                v = np.asarray(values[-n:], dtype=float) / 1e3
                table[name] = (float(np.median(v)), float(np.percentile(v, 90)))
            out[kind] = table
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--node"]:
        _node_main(argv[1], argv[2], argv[3:])
        return 0
    p = argparse.ArgumentParser(prog="python -m benchmarks.callback_parts", description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=30.0, help="driven time per node, s (default 30)")
    p.add_argument("--hog", action="store_true", help="with the bench's busy-loop process on the last core")
    args = p.parse_args(argv)
    out = run(args.seconds, hog=args.hog)
    print(f"\nper message, us (p50 / p90), {args.seconds:g} s per node at 1 kHz, 7 joints"
          + (", with the hog" if args.hog else ""))
    for kind, table in out.items():
        print(f"  {kind}")
        for name, (p50, p90) in table.items():
            print(f"    {name:<28}{p50:9.1f}" + ("" if np.isnan(p90) else f" / {p90:7.1f}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
