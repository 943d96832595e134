"""A fleet's recordings analysed serially, on 1 and 2 local Dask workers, and again from the cache.

Data: :func:`shaper_nodes.analysis.synthetic.write_fleet`: ``robots`` x ``recordings`` short
robot-style recordings (3 back-and-forth moves each, IMU and joint states at 250 Hz, gravity,
noise, a 0.5 % day-to-day spread of the mode), two robots of which have their mode moved by
10 % from the middle of their recordings on; written into a temporary folder.

Methods (wall time over the whole fleet, analysis options as ``analyze_fleet``'s defaults; the methods are
run ``repeats`` times, interleaved, and the best time of each is reported with every pass and the
1-minute load average at its start):

``serial``
    :func:`~shaper_nodes.analysis.fleet.run_fleet` with ``workers=0``: a plain loop in this process,
    no Dask, no cache, BLAS with its default threads (OpenBLAS: one per core).
``serial, 1 BLAS thread``
    The same loop as ``analyze_fleet --workers 0 --no-cache`` in a new process started with
    ``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1`` (as the Dask workers are); includes
    the interpreter's start and imports (about 2 s).
``Dask, N workers``
    A new ``LocalCluster`` of N worker processes (one thread, one BLAS thread each), no cache;
    includes starting and closing the cluster; ``of which cluster start`` is the time until the
    workers are up and have imported the analysis (numpy, scipy, rosbags), before the first task.
``rerun, cache hits``
    With a cache filled by a first run: every recording hashed (SHA-256 of its bytes) and found.

Then the drift rule's verdict (:func:`~shaper_nodes.analysis.fleet_drift.fleet_drift`, defaults):
the robots flagged against the two that drift. The machine's load average before and after is
recorded (the figures are wall times: other work on the machine slows them).
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable


def run(*, robots: int = 10, recordings: int = 20, worker_counts: tuple[int, ...] = (1, 2), repeats: int = 2,
        progress: Callable[[str], None] = lambda s: None) -> dict:
    """Write the fleet, time the methods once each, return the figures."""
    from shaper_nodes.analysis.analyze import Options
    from shaper_nodes.analysis.fleet import SINGLE_THREAD, Cache, find_recordings, run_fleet
    from shaper_nodes.analysis.fleet_drift import DriftRule, fleet_drift
    from shaper_nodes.analysis.synthetic import write_fleet

    options, rule = Options(learners=()), DriftRule()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="fleet_bench_") as tmp:
        root = pathlib.Path(tmp) / "fleet"
        progress(f"fleet: writing {robots} x {recordings} recordings")
        start = time.perf_counter()
        truth = write_fleet(root, robots=robots, recordings=recordings, drifting=(3, 7))
        write_s = time.perf_counter() - start
        paths = find_recordings(root)
        size = sum(f.stat().st_size for p in paths for f in p.iterdir())
        timings: dict[str, list[float]] = {}
        loads: dict[str, list[float]] = {}

        def timed(label: str, seconds: float, load: float) -> None:
            timings.setdefault(label, []).append(seconds)
            loads.setdefault(label, []).append(load)

        for k in range(repeats):  # interleaved, so that a burst of outside load hits one pass, not one method
            progress(f"fleet: pass {k + 1}/{repeats}: serial")
            load = os.getloadavg()[0]
            serial = run_fleet(paths, options, None, workers=0)
            timed("serial (plain loop, no Dask)", serial.seconds, load)
            progress(f"fleet: pass {k + 1}/{repeats}: serial, 1 BLAS thread (new process)")
            load, start = os.getloadavg()[0], time.perf_counter()
            subprocess.run([sys.executable, "-m", "shaper_nodes.cli.analyze_fleet", str(root), "--workers", "0",
                            "--no-cache", "--quiet"], env={**os.environ, **SINGLE_THREAD}, check=True,
                           stdout=subprocess.DEVNULL)
            timed("serial, 1 BLAS thread", time.perf_counter() - start, load)
            for n in worker_counts:
                progress(f"fleet: pass {k + 1}/{repeats}: Dask, {n} worker(s)")
                load = os.getloadavg()[0]
                r = run_fleet(paths, options, None, workers=n)
                timed(f"Dask, {n} worker process{'es' if n > 1 else ''}", r.seconds, load)
                timed(f"  of which cluster start, {n}", r.startup_s, load)
        cache = Cache(pathlib.Path(tmp) / "cache")
        progress("fleet: filling the cache (2 workers)")
        run_fleet(paths, options, cache, workers=max(worker_counts))
        progress("fleet: rerun with the cache")
        rerun = run_fleet(paths, options, cache, workers=max(worker_counts))
        timed("rerun, cache hits", rerun.seconds, os.getloadavg()[0])
    drift = fleet_drift(serial.results, rule)
    flagged = sorted(d.robot for d in drift if d.alerts)
    best = {k: min(v) for k, v in timings.items()}
    base = best["serial (plain loop, no Dask)"]
    return {
        "recordings": len(paths), "robots": robots, "fleet_mb": size / 1e6, "write_s": write_s,
        "failed": sum(1 for r in serial.results if r.error), "cache_hits": rerun.cached,
        "analysis_s_per_recording": sum(r.seconds for r in serial.results) / len(serial.results),
        "drifting": sorted(truth.drift_from), "flagged": flagged,
        "false_alarms": sorted(set(flagged) - set(truth.drift_from)),
        "missed": sorted(set(truth.drift_from) - set(flagged)),
        "alerts": [{"robot": a.robot, "first_out": pathlib.Path(a.first_out).name, "shift": a.shift,
                    "frequency_hz": a.frequency_hz, "retune": a.retune["family"] if a.retune else None}
                   for d in drift for a in d.alerts],
        "blas_env": {k: os.environ.get(k) for k in SINGLE_THREAD}, "load_before": load_before[0],
        "load_after": os.getloadavg()[0], "cpus": os.cpu_count(),
        "repeats": repeats,
        "methods": [{"method": k, "seconds": v, "all_seconds": timings[k], "load_at_start": loads[k],
                     "ratio_to_serial": v / base} for k, v in best.items()],
    }


def print_table(result: dict) -> None:
    """The figures as a table."""
    print(f"Fleet analysis: {result['recordings']} recordings of {result['robots']} robots"
          f" ({result['fleet_mb']:.0f} MB, written in {result['write_s']:.1f} s),"
          f" {result['analysis_s_per_recording']:.2f} s per recording serially;"
          f" load average {result['load_before']:.1f} before, {result['load_after']:.1f} after, {result['cpus']} CPUs")
    print(f"  best of {result['repeats']} interleaved passes (all passes, with the 1-min load average at their start)")
    head = f"  {'method':<32}{'s':>8}{'x serial':>10}  passes: s (load)"
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in result["methods"]:
        passes = ", ".join(f"{s:.1f} ({ld:.1f})" for s, ld in zip(m["all_seconds"], m["load_at_start"], strict=True))
        print(f"  {m['method']:<32}{m['seconds']:>8.2f}{m['ratio_to_serial']:>10.2f}  {passes}")
    print(f"  drifting {', '.join(result['drifting'])}; flagged {', '.join(result['flagged']) or 'none'};"
          f" false alarms {len(result['false_alarms'])}, missed {len(result['missed'])};"
          f" cache hits {result['cache_hits']}/{result['recordings']}; failed {result['failed']}")
    for a in result["alerts"]:
        print(f"  alert {a['robot']} from {a['first_out']}: mode {a['frequency_hz']:.4g} Hz"
              f" ({100 * a['shift']:+.1f} %), retune {a['retune']}")


if __name__ == "__main__":
    print_table(run())
