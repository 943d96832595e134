"""The shaper's hop with each ``stream_executor`` against the bare echo node, in one run (issue 34).

``python -m benchmarks.latency_executors --seconds 20`` starts the echo node, its raw echo on the take loop
(the round trip of a Python node that does no work on the shaper's path: the floor), and one ZVD shaper node per
``stream_executor`` choice ('thread', 'take'; ``--executors``), drives them in turns
(:func:`~benchmarks.latency.measure_interleaved`: the machine's changes fall on every target alike), and
again with a busy-loop hog on one core unless ``--skip-hog``. It prints each target's figures and the
ratios to the echo node of the same group: the issue's goal is p50 and CPU per message at most 0.5x the
echo, p99 at most 0.75x, 0 lost (docs/results/benchmarks.md).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import sys
import tempfile

ZVD = {"shaper.family": "zvd", "shaper.frequency_hz": 8.0, "shaper.damping_ratio": 0.03, "discretization": "split"}


def run(executors: list[str], seconds: float, turn: float, hog: bool, rate: float = 1000.0,
        joints: int = 7) -> list[dict]:
    """Rows (group, label, lost, p50/p99 in us, CPU per message in us, and their ratios to the echo's)."""
    from .cpu_hog import CpuHog
    from .latency import measure_interleaved
    from .latency_targets import echo_target, shaper_target

    rows: list[dict] = []
    for loaded in ([False, True] if hog else [False]):
        floor = echo_target("/bench/echo_take_in", "/bench/echo_take_out", take=True)  # no work, the take loop
        targets = [echo_target(), floor] + [
            shaper_target(f"shaper zvd {e}", joints, rate, {**ZVD, "stream_executor": e})
            for e in executors]
        rounds = max(1, round(seconds / turn))
        with tempfile.TemporaryDirectory(prefix="shaper_bench_") as tmp, contextlib.ExitStack() as stack:
            if loaded:
                stack.enter_context(CpuHog())
            results = measure_interleaved(targets, seconds=seconds, rate=rate, joints=joints,
                                          log_dir=pathlib.Path(tmp), rounds=rounds,
                                          progress=lambda s: print(s, file=sys.stderr, flush=True))
        echo = results[0]
        for r in results:
            rows.append({"group": "hog" if loaded else "quiet", "label": r.label, "sent": r.sent, "lost": r.lost,
                         "p50_us": r.p50_us, "p99_us": r.p99_us, "cpu_us_per_msg": r.node_cpu_us_per_msg,
                         "p50_ratio": r.p50_us / echo.p50_us, "p99_ratio": r.p99_us / echo.p99_us,
                         "cpu_ratio": r.node_cpu_us_per_msg / echo.node_cpu_us_per_msg})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.latency_executors", description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=20.0, help="driven time per target, s (default 20)")
    p.add_argument("--turn", type=float, default=5.0, help="length of a turn, s (default 5)")
    p.add_argument("--executors", default="thread,take", help="stream_executor choices, comma-separated")
    p.add_argument("--skip-hog", action="store_true", help="leave out the group with a busy-loop hog")
    p.add_argument("--json", type=pathlib.Path, help="also write the rows to this JSON file")
    args = p.parse_args(argv)
    load0 = os.getloadavg()[0]
    rows = run([e.strip() for e in args.executors.split(",") if e.strip()], args.seconds, args.turn,
               not args.skip_hog)
    load1 = os.getloadavg()[0]
    print(f"load average {load0:.1f} -> {load1:.1f}")
    print("| group | target | lost of sent | p50 us (/ echo) | p99 us (/ echo) | CPU us per message (/ echo) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['group']} | {r['label']} | {r['lost']} of {r['sent']} | {r['p50_us']:.0f} ({r['p50_ratio']:.2f})"
              f" | {r['p99_us']:.0f} ({r['p99_ratio']:.2f}) | {r['cpu_us_per_msg']:.0f} ({r['cpu_ratio']:.2f}) |")
    if args.json:
        args.json.write_text(json.dumps({"load": [load0, load1], "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
