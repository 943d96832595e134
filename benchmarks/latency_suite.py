"""The latency measurements as ``./run bench`` runs them, and their tables.

:func:`run_latency` measures the echo baseline, the floor (the echo on the take loop), shaper none, shaper ZVD and
the floor doing the ZVD shaper's work (:mod:`benchmarks.latency`), in turns, and unless ``--skip-hog`` all but shaper
none again with a busy-loop process on one core; :func:`print_latency` prints their table, the ratios to the
baseline of the same run and the hop set against the work it must do (:mod:`benchmarks.work_timing`).
"""

from __future__ import annotations

import argparse
import contextlib
import pathlib
import tempfile
import textwrap
from collections.abc import Callable

from .summary import fmt, ratio_of

#: outside load (percent of one core) above which the latency table carries a warning
BUSY_WARNING_PCT = 25.0


def _ratios(runs: list[dict], base: dict) -> list[dict]:
    """Each run's figures against ``base`` (measured in the same run, under the same load)."""
    return [{
        "label": r["label"],
        "p50": ratio_of(r["p50_us"], base["p50_us"]),
        "p99": ratio_of(r["p99_us"], base["p99_us"]),
        "max": ratio_of(r["max_us"], base["max_us"]),
        "node_cpu": ratio_of(r["node_cpu_pct"], base["node_cpu_pct"]),
        "cpu_per_msg": ratio_of(r["node_cpu_us_per_msg"], base["node_cpu_us_per_msg"]),
        "extra_p50_us": r["p50_us"] - base["p50_us"],
        "extra_p99_us": r["p99_us"] - base["p99_us"],
    } for r in runs]


def run_latency(args: argparse.Namespace, progress: Callable[[str], None]) -> dict:
    """The latency measurements (echo baseline, the floor: the echo on the take loop, shaper none, shaper ZVD)
    and their ratios; unless ``--skip-hog``, echo, floor and shaper ZVD again, each with a busy-loop process on
    one core (the same load for all), and their ratios; ``progress`` is told what is measured."""
    from .cpu_hog import CpuHog
    from .latency import measure_interleaved
    from .latency_targets import echo_target, lean_zvd_target, shaper_target

    zvd = {"shaper.family": "zvd", "shaper.frequency_hz": 8.0, "shaper.damping_ratio": 0.03,
           "discretization": "split"}
    # the floor: the echo's raw bytes on the shaper's take loop, a Python node that does no work on its path
    floor = ("/bench/echo_take_in", "/bench/echo_take_out")
    # the floor and the shapers time their callbacks in the node (benchmarks/work_timing.py)
    timed = not args.skip_work_timing
    groups = [(False, [echo_target(), echo_target(*floor, take=True, timed=timed),
                       shaper_target("shaper none", args.joints, args.rate, {"shaper.family": "none"}, timed=timed),
                       shaper_target("shaper zvd 8 Hz", args.joints, args.rate, zvd, timed=timed),
                       lean_zvd_target(args.joints, args.rate, zvd, timed)])]
    if not args.skip_hog:
        groups.append((True, [echo_target(), echo_target(*floor, take=True, timed=timed),
                              shaper_target("shaper zvd 8 Hz", args.joints, args.rate, zvd, timed=timed),
                              lean_zvd_target(args.joints, args.rate, zvd, timed)]))
    rounds = max(1, round(args.seconds / args.turn)) if args.turn > 0 else 1
    runs: list[dict] = []
    hog_runs: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="shaper_bench_") as tmp:
        for hog, targets in groups:
            for target in targets:
                target.label += " + hog" if hog else ""
            labels = ", ".join(t.label for t in targets)
            how = f"in turns of {args.seconds / rounds:.3g} s" if rounds > 1 else "in one stretch each"
            progress(f"latency: {labels} ({args.seconds:g} s each at {args.rate:g} Hz, {how})")
            with contextlib.ExitStack() as stack:
                load = stack.enter_context(CpuHog()) if hog else None
                if rounds > 1:
                    results = measure_interleaved(targets, seconds=args.seconds, rate=args.rate, joints=args.joints,
                                                  warmup=args.warmup, drain=args.drain,
                                                  discovery_timeout=args.discovery_timeout, log_dir=pathlib.Path(tmp),
                                                  rounds=rounds, progress=progress)
                else:  # one after the other, each node started for its own stretch
                    results = [r for t in targets
                               for r in measure_interleaved([t], seconds=args.seconds, rate=args.rate,
                                                            joints=args.joints, warmup=args.warmup, drain=args.drain,
                                                            discovery_timeout=args.discovery_timeout,
                                                            log_dir=pathlib.Path(tmp), progress=progress)]
            for target, result in zip(targets, results, strict=True):
                result.extra["dense_taps"] = target.fir.length
                result.extra["nonzero_taps"] = int(target.fir.delays.size)
                result.extra["turns"] = rounds
                if load is not None:
                    result.extra["hog_cpu"] = load.cpu
                (hog_runs if hog else runs).append(result.as_dict())
    out = {"baseline": runs[0]["label"], "runs": runs, "ratios_to_baseline": _ratios(runs[1:], runs[0])}
    if hog_runs:
        out.update(hog_baseline=hog_runs[0]["label"], hog_runs=hog_runs,
                   hog_ratios_to_baseline=_ratios(hog_runs[1:], hog_runs[0]))
    return out


def _print_runs(runs: list[dict]) -> None:
    head = (f"  {'node':<24}{'sent':>6}{'recv':>6}{'lost':>5}{'send Hz':>9}{'p50 us':>8}{'p99 us':>8}"
            f"{'max us':>8}{'mean us':>8}{'node CPU':>9}{'drv CPU':>8}{'other':>7}{'out err':>9}")
    print(head)
    print("  " + "-" * (len(head) - 2))
    for r in runs:
        print(f"  {r['label']:<24}{r['sent']:>6}{r['received']:>6}{r['lost']:>5}{fmt(r['send_rate_hz'], '.1f'):>9}"
              f"{fmt(r['p50_us']):>8}{fmt(r['p99_us']):>8}{fmt(r['max_us']):>8}{fmt(r['mean_us']):>8}"
              f"{fmt(r['node_cpu_pct'], '.1f'):>9}{fmt(r['driver_cpu_pct'], '.1f'):>8}"
              f"{fmt(r['other_cpu_pct'], '.0f'):>7}"
              f"{fmt(r['max_output_error'], '.0e'):>9}")


def _print_ratios(baseline: str, ratios: list[dict]) -> None:
    print(f"  ratio to {baseline:<22}{'p50':>7}{'p99':>7}{'max':>7}{'CPU':>7}{'CPU/msg':>8}{'+p50 us':>9}"
          f"{'+p99 us':>9}")
    for q in ratios:
        print(f"  {q['label']:<31}{fmt(q['p50'], '.2f'):>7}{fmt(q['p99'], '.2f'):>7}{fmt(q['max'], '.2f'):>7}"
              f"{fmt(q['node_cpu'], '.2f'):>7}{fmt(q['cpu_per_msg'], '.2f'):>8}{fmt(q['extra_p50_us'], '+.0f'):>9}"
              f"{fmt(q['extra_p99_us'], '+.0f'):>9}")


def print_latency(lat: dict, args: argparse.Namespace) -> None:
    """Latency table (and the one under load, when measured)."""
    runs = lat["runs"]
    n = runs[0]["sent"]
    print(f"Round-trip latency driver -> node -> driver (two hops), {args.joints} joints,"
          f" target {args.rate:g} Hz, {args.seconds:g} s ({n} messages per node)")
    print("  replies are matched to sends by the sequence number in layout.data_offset (fallback: the data")
    print("  ramp decoded through the node's FIR); out err: largest relative deviation of a reply from the")
    print("  expected FIR output; CPU: % of one core over the sending window, for the node, the driver")
    print("  (this process) and the rest of the machine (other: outside load, i.e. noise); CPU/msg: the node's CPU")
    print("  time per reply received")
    every = runs + lat.get("hog_runs", [])
    _print_runs(every)
    notes = [f"{r['label']}: {r['duplicates']} duplicates, {r['undecoded']} undecoded, {r['seq_from_data']} matched"
             f" through the data (no data_offset), {r['inexact']} inexact (after lost inputs)"
             for r in every if r["duplicates"] or r["undecoded"] or r["seq_from_data"] or r["inexact"]]
    busiest = max(runs, key=lambda r: r["other_cpu_pct"])
    if busiest["other_cpu_pct"] > BUSY_WARNING_PCT:
        notes.append(f"the machine was busy with other work (up to {busiest['other_cpu_pct']:.0f} % of a core during"
                     f" '{busiest['label']}'): these figures are noisy, compare runs with little 'other'")
    if lat.get("hog_runs"):
        notes.append("'+ hog': measured with a busy-loop process on one core (pinned where allowed; its share is"
                     " in 'other'), the same load for the echo node and the shaper")
    for note in notes:
        print(textwrap.fill(note, width=104, initial_indent="  note: ", subsequent_indent="        "))
    print("  send interval p99: " + ", ".join(f"{r['label']} {fmt(r['send_interval_p99_us'])} us" for r in every))
    print()
    _print_ratios(lat["baseline"], lat["ratios_to_baseline"])
    if lat.get("hog_runs"):
        _print_ratios(lat["hog_baseline"], lat["hog_ratios_to_baseline"])
    print()
    from .thread_cpu import print_threads
    from .work_timing import print_decomposition

    print_decomposition(lat)
    print_threads(lat)
