"""``python -m benchmarks``: run the benchmarks, print a table, optionally write JSON.

See :mod:`benchmarks` for what is measured, and ``--help`` for the options. The latency measurements and their
tables are in :mod:`benchmarks.latency_suite`, the one summary table in :mod:`benchmarks.summary`.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import pathlib
import platform
import signal
import sys
import time
from collections.abc import Callable
from typing import Any

from .latency_suite import print_latency, run_latency
from .summary import print_summary, summary


def _progress(text: str) -> None:
    print(f"[bench] {text}", file=sys.stderr, flush=True)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    p = argparse.ArgumentParser(prog="python -m benchmarks",
                                description="Shaper suite benchmarks (figures, not pass/fail).")
    p.add_argument("--seconds", type=float, default=5.0,
                   help="duration of the latency measurement per target (and of each scheduler CPU window), s"
                        " (default 5)")
    p.add_argument("--rate", type=float, default=1000.0, help="send rate of the latency driver, Hz (default 1000)")
    p.add_argument("--joints", type=int, default=7, help="joints (values per message and FIR channels; default 7)")
    p.add_argument("--turn", type=float, default=5.0,
                   help="latency: the targets take turns of this many seconds each, in rotated order, until each"
                        " has had --seconds (default 5; 0: one stretch per target, one after the other)")
    p.add_argument("--warmup", type=float, default=0.5, help="warm-up after the first reply, s (default 0.5)")
    p.add_argument("--drain", type=float, default=0.5, help="receive time after the last send, s (default 0.5)")
    p.add_argument("--discovery-timeout", type=float, default=30.0, help="node start-up and discovery limit, s")
    p.add_argument("--fir-repeats", type=int, default=5, help="passes per FIR method, best reported (default 5)")
    p.add_argument("--skip-latency", action="store_true", help="skip the node latency measurements")
    p.add_argument("--skip-work-timing", action="store_true",
                   help="latency: the floor and the shapers do not time their callbacks in the node (the hop above the"
                        " floor against the work, benchmarks/work_timing.py)")
    p.add_argument("--skip-hog", action="store_true",
                   help="skip the latency measurements under load (echo and shaper ZVD again, each with a busy-loop"
                        " process on one core)")
    p.add_argument("--skip-fir", action="store_true", help="skip the FIR throughput measurement")
    p.add_argument("--skip-list", action="store_true", help="skip the LIST update timing")
    p.add_argument("--skip-mrilc", action="store_true", help="skip the MRILC update timing")
    p.add_argument("--skip-scheduler", action="store_true", help="skip the scheduler timing and CPU share")
    p.add_argument("--skip-discretization", action="store_true", help="skip the shaper discretisation timing")
    p.add_argument("--skip-bag", action="store_true", help="skip the bag analysis throughput measurement")
    p.add_argument("--skip-fleet", action="store_true",
                   help="skip the fleet analysis (200 recordings: serial, 1 and 2 Dask workers, cached rerun)")
    p.add_argument("--skip-arm", action="store_true", help="skip the arm's lockstep speed")
    p.add_argument("--skip-streaming-gap", action="store_true",
                   help="skip the shaper's streaming gap while whole trajectories are shaped")
    p.add_argument("--skip-learner-memory", action="store_true",
                   help="skip the learners' memory over a 1 h LIST cycle and 24 h of MRILC (simulated time)")
    p.add_argument("--bag-messages", type=int, default=1_000_000,
                   help="messages in the bag analysis benchmark's recording (default 1000000)")
    p.add_argument("--json", metavar="PATH", type=pathlib.Path, help="also write the figures to this JSON file")
    args = p.parse_args(argv)
    if not (args.seconds > 0 and args.rate > 0 and args.joints >= 1 and args.fir_repeats >= 1):
        p.error("--seconds and --rate must be > 0, --joints and --fir-repeats >= 1")
    return args


def _terminate(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _json_safe(value: object) -> object:
    """``value`` with NaN and infinities replaced by None (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


#: the benchmarks after the latency measurements, in order: (key in the report, the --skip-*
#: option that leaves it out, its module (with ``run`` and ``print_table``), the options it takes)
BENCHMARKS: tuple[tuple[str, str, str, Callable[[argparse.Namespace], dict[str, Any]]], ...] = (
    ("fir", "skip_fir", "fir_throughput", lambda a: {"joints": a.joints, "repeats": a.fir_repeats}),
    ("list_update", "skip_list", "list_update", lambda a: {}),
    ("mrilc_update", "skip_mrilc", "mrilc_update", lambda a: {}),
    ("scheduler", "skip_scheduler", "scheduler", lambda a: {"seconds": a.seconds}),
    ("discretization", "skip_discretization", "discretization", lambda a: {}),
    ("bag_analysis", "skip_bag", "bag_analysis", lambda a: {"messages": a.bag_messages}),
    ("fleet", "skip_fleet", "fleet", lambda a: {}),
    ("arm_lockstep", "skip_arm", "arm_lockstep", lambda a: {}),
    ("learner_memory", "skip_learner_memory", "learner_memory", lambda a: {}),
    ("streaming_gap", "skip_streaming_gap", "streaming_gap", lambda a: {}),
)


def _module(name: str) -> Any:
    return importlib.import_module(f".{name}", __package__)


def _load() -> str:
    try:
        one, five, fifteen = os.getloadavg()
    except OSError:
        return "n/a"
    return f"load average {one:.2f}, {five:.2f}, {fifteen:.2f} on {os.cpu_count()} CPUs"


def run_all(args: argparse.Namespace, report: dict) -> None:
    """Run every benchmark the options do not skip; their figures go into ``report``."""
    if not args.skip_latency:
        report["latency"] = run_latency(args, _progress)
    for key, skip, module, options in BENCHMARKS:
        if not getattr(args, skip):
            report[key] = _module(module).run(**options(args), progress=_progress)


def print_report(report: dict, args: argparse.Namespace) -> None:
    """Every table of ``report``, then the run's machine and duration."""
    print()
    if "latency" in report:
        print_latency(report["latency"], args)
        print()
    for key, _, module, _ in BENCHMARKS:
        if key in report:
            _module(module).print_table(report[key])
            print()
    print(f"({report['meta']['cpus']} CPUs, {report['meta']['rmw']}, {report['meta']['elapsed_s']:.0f} s)")
    print()
    print_summary(report["summary"], report["meta"]["load_end"])


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = parse_args(argv)
    # SIGTERM unwinds like Ctrl-C, so that the nodes started are stopped (try/finally)
    signal.signal(signal.SIGTERM, _terminate)
    started = time.time()
    report: dict = {
        "meta": {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
                 "host": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version(),
                 "rmw": os.environ.get("RMW_IMPLEMENTATION", ""), "ros_domain_id": os.environ.get("ROS_DOMAIN_ID", ""),
                 "argv": sys.argv[1:] if argv is None else argv, "load_start": _load()},
    }
    try:
        run_all(args, report)
    except KeyboardInterrupt:
        _progress("interrupted")
        return 130
    except RuntimeError as err:  # a node did not start, was not discovered or died
        _progress(f"error: {err}")
        return 1
    report["meta"]["elapsed_s"] = time.time() - started
    report["meta"]["load_end"] = _load()
    report["summary"] = summary(report)
    print_report(report, args)
    if args.json:
        args.json.write_text(json.dumps(_json_safe(report), indent=2, allow_nan=False) + "\n")
        print(f"figures written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
