"""The shaper hop's own work per message, in one process: the array callback's read, rules, FIR and write.

``python -m benchmarks.hop_work [--source DIR] [--joints N] [--repeats R]`` times
:meth:`shaper_nodes.ros.raw_stream.RawArrays.shape` (what the node's ``_on_array`` does between the take and
the publish) on serialized ``Float64MultiArray`` samples of ``N`` joints (7) with the bench's ZVD 8 Hz at
1 kHz: the least, over ``R`` repeats (300), of the mean of 200 calls, in us per message. The caches are hot
here, so the node at 1 kHz, where each message meets cold ones, pays several times as much; the figure
ranks two versions of the code on a loaded machine (the least of many short repeats is the one nothing
interrupted), which the round-trip figures cannot. ``--source DIR``: the ``shaper_nodes`` package of another
checkout (its ``shaper_nodes/`` folder) is imported instead of the installed one, to compare two versions
in turns (A B A B). The printed hash of all the answers' bytes is the same for two versions that answer
alike. ``--paced N`` also times ``N`` calls one at a time 1 ms apart, as the node meets them at 1 kHz (the caches
cold from the wait; a ``time.sleep`` to each deadline): their median and p90, us. The node's own figure is the
bench's (``benchmarks/work_timing.py``); this one compares two versions in one process, without DDS.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import pathlib
import sys
import time
import timeit
from collections.abc import Callable, Iterator


def measure(joints: int = 7, repeats: int = 300, number: int = 200,
            paced: int = 0) -> tuple[float, str, str, tuple[float, float]]:
    """(us per message, the hash of the answers to 5000 messages, the shaper_nodes package's folder, the median and
    p90 of ``paced`` calls 1 ms apart, us (NaN when none))."""
    import numpy as np

    import shaper_nodes
    from shaper_nodes.core.shaping import Mode, design, discretize
    from shaper_nodes.core.shaping.limits import JointLimits
    from shaper_nodes.core.shaping.stream import CommandStream
    from shaper_nodes.recordings.cdr_arrays import ArrayLayout, Float64MultiArrayCdr
    from shaper_nodes.ros.raw_stream import RawArrays

    fir = discretize(design("zvd", [Mode.from_hz(8.0, 0.03)]), 1000.0, "split")
    raw = RawArrays(CommandStream(fir, JointLimits.unset([f"joint_{i + 1}" for i in range(joints)]), max_abs=1e6))
    msg = Float64MultiArrayCdr(ArrayLayout(), joints)
    inputs = []
    for k in range(5000):  # a sequence number in data_offset, as the latency driver sends
        msg.set_data_offset(k)
        inputs.append(msg.write(np.sin(0.01 * k + np.arange(joints)).tolist()))
    digest = hashlib.sha256(b"".join(raw.shape(m) for m in inputs)).hexdigest()[:16]
    feed = iter(inputs * (repeats * number // len(inputs) + 2))
    best = min(timeit.repeat(lambda: raw.shape(next(feed)), number=number, repeat=repeats)) / number
    return 1e6 * best, digest, str(pathlib.Path(shaper_nodes.__file__).parent), _paced(raw.shape, feed, paced)


def _paced(shape: Callable[[bytes], bytes], feed: Iterator[bytes], n: int) -> tuple[float, float]:
    """(median, p90) of ``n`` calls of ``shape`` 1 ms apart, us."""
    if n <= 0:
        return math.nan, math.nan
    clock = time.perf_counter_ns
    times = []
    deadline = time.monotonic()
    for _ in range(n):
        deadline += 1e-3
        time.sleep(max(0.0, deadline - time.monotonic()))
        msg = next(feed)
        t = clock()
        shape(msg)
        times.append(clock() - t)
    times.sort()
    return 1e-3 * times[n // 2], 1e-3 * times[(9 * n) // 10]


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.hop_work", description=__doc__.split("\n")[0])
    p.add_argument("--source", type=pathlib.Path, help="a checkout's shaper_nodes/ folder, imported first")
    p.add_argument("--joints", type=int, default=7)
    p.add_argument("--repeats", type=int, default=300)
    p.add_argument("--paced", type=int, default=0, help="also time this many calls 1 ms apart (cold caches)")
    args = p.parse_args(argv)
    if args.source is not None:
        if not (args.source / "shaper_nodes" / "__init__.py").is_file():
            p.error(f"--source {args.source}: no shaper_nodes package there (give a checkout's shaper_nodes/ folder)")
        sys.path.insert(0, str(args.source.resolve()))
    us, digest, where, (p50, p90) = measure(args.joints, args.repeats, paced=args.paced)
    cold = f"; {args.paced} calls 1 ms apart: median {p50:.2f} us, p90 {p90:.2f} us" if args.paced else ""
    print(f"RawArrays.shape, {args.joints} joints, ZVD 8 Hz at 1 kHz: {us:.2f} us per message (hot; least of"
          f" {args.repeats} x 200 calls){cold}; answers {digest}; code: {where}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
