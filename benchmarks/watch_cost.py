"""The shaper node's main-thread bookkeeping per message, in one process: the rate watch and the summary.

``python -m benchmarks.watch_cost [--source DIR] [--repeats R] [--arrivals N] [--cold]`` keeps ``N`` arrivals
(1000: a second at 1 kHz, what each 1 s summary finds; 250 was the 0.25 s watch before session 15) in a
:class:`~shaper_nodes.ros.stream_watch.StreamWatch` as the streaming path does (``passed``, with infos shaped as
rclpy's), then times what the node's main thread does with them, :meth:`StreamWatch.watch`, in this thread's CPU
time (``time.thread_time_ns``): per arrival, the least and the median over ``R`` repeats (400), and the same for a
:meth:`StreamWatch.summary` after four such batches, per message. The least is the run that nothing interrupted
(hot caches); ``--cold`` makes fresh infos for each watch and flushes the caches before it, nearer the node, whose
main thread meets them cold. The node pays besides each wake-up of its executor (about 0.45 ms, session 15),
which this does not time. ``--source DIR``: the ``shaper_nodes`` package of another checkout (its
``shaper_nodes/`` folder) is imported instead of the installed one, to compare two versions in turns (A B A B).
The printed hash of the summaries' values over a stream with gaps, bursts, drops, repeats and absent stamps is the
same for two versions that count alike.
"""

from __future__ import annotations

import argparse
import hashlib
import pathlib
import statistics
import sys
import time
from typing import Any, cast

MS = 1_000_000
T0 = 1_764_400_000 * 10**9  # a wall clock, ns


def infos(n: int, start: int = 0, trouble: bool = False) -> list[tuple[dict[str, Any] | None, int]]:
    """``n`` kept arrivals at 1 kHz from message ``start`` on, as rclpy's infos and the taken stamp; with
    ``trouble``, gaps, bunched receptions, lost and repeated sequence numbers and absent infos among them."""
    out: list[tuple[dict[str, Any] | None, int]] = []
    for k in range(start, start + n):
        source, received, seq = T0 + k * MS, T0 + k * MS + 80_000, k + 1
        if trouble and k % 97 == 5:
            source += 3 * MS  # a late send: a gap
        if trouble and k % 61 == 7:
            received -= 900_000  # bunched on the way: a burst
        if trouble and k % 89 == 3:
            seq += 2  # lost on the way: drops
        if trouble and k % 53 == 11:
            seq -= 1  # a repeat
        info = None if trouble and k % 71 == 13 else {
            "source_timestamp": source, "received_timestamp": received, "publication_sequence_number": seq,
            "reception_sequence_number": k + 1}
        out.append((info, received + 30_000 + (k % 7) * 1_000))
    return out


def measure(arrivals: int = 1000, repeats: int = 400, cold: bool = False) -> dict[str, Any]:
    """The watch's and the summary's CPU time per message (least and median, us), the hash of the summaries'
    values, and the shaper_nodes package's folder. ``cold``: fresh infos for each watch and the caches flushed
    before it (a pass over 32 MB), as the node meets them after a quarter second of other work."""
    import shaper_nodes
    from shaper_nodes.ros.diagnostics import Diagnostics
    from shaper_nodes.ros.stream_watch import StreamWatch

    no_reports = cast(Diagnostics, None)  # nothing is refused here, so nothing is reported
    digest = hashlib.sha256()
    check = StreamWatch(1000.0, no_reports, lambda k: 1)
    for b in range(40):
        for info, taken in infos(arrivals, b * arrivals, trouble=True):
            check.passed("array", info, taken)
        check.watch()
        if b % 4 == 3:
            digest.update(repr(check.summary("quiet")).encode())

    clock = time.thread_time_ns
    watch = StreamWatch(1000.0, no_reports, lambda k: 1)
    batch = infos(arrivals)
    flush = bytearray(32 << 20)
    per_watch, per_summary = [], []
    for r in range(repeats):
        if cold:
            batch = infos(arrivals, r * arrivals)
        for info, taken in batch:
            watch.passed("array", info, taken)
        if cold:
            flush[::64] = bytes(len(flush) // 64)  # a write to every cache line
        t = clock()
        watch.watch()
        per_watch.append(clock() - t)
        if r % 4 == 3:
            t = clock()
            watch.summary("quiet")
            per_summary.append(clock() - t)
    us = 1e-3 / arrivals
    return {"watch_least_us": us * min(per_watch), "watch_median_us": us * statistics.median(per_watch),
            "summary_least_us": us / 4 * min(per_summary), "summary_median_us": us / 4 * statistics.median(per_summary),
            "hash": digest.hexdigest()[:16], "code": str(pathlib.Path(shaper_nodes.__file__).parent)}


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.watch_cost", description=__doc__.split("\n")[0])
    p.add_argument("--source", type=pathlib.Path, help="a checkout's shaper_nodes/ folder, imported first")
    p.add_argument("--arrivals", type=int, default=1000, help="arrivals per watch (1000: 1 s at 1 kHz)")
    p.add_argument("--repeats", type=int, default=400)
    p.add_argument("--cold", action="store_true", help="fresh infos and the caches flushed before each watch")
    args = p.parse_args(argv)
    if args.source is not None:
        if not (args.source / "shaper_nodes" / "__init__.py").is_file():
            p.error(f"--source {args.source}: no shaper_nodes package there (give a checkout's shaper_nodes/ folder)")
        sys.path.insert(0, str(args.source.resolve()))
    m = measure(args.arrivals, args.repeats, args.cold)
    cold = " (cold)" if args.cold else ""
    print(f"main thread CPU per message, {args.arrivals} arrivals a watch{cold}: watch {m['watch_least_us']:.3f} us"
          f" least, {m['watch_median_us']:.3f} us median; summary {m['summary_least_us']:.3f} /"
          f" {m['summary_median_us']:.3f} us (least / median, per message of a 1 s window); summaries {m['hash']};"
          f" code: {m['code']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
