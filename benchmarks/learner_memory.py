"""Learners' memory over long runs (issue 17): a 1-hour LIST cycle at 1 kHz, 24 h of MRILC at 500 Hz.

Figures, not pass/fail. Each part runs in a fresh Python process (``python -m
benchmarks.learner_memory --part list|mrilc``), so that its resident set size starts from the
same interpreter and libraries and nothing of the other part is in it. Time is simulated (sample
stamps), not wall time: samples go straight into the core session objects, as fast as the
machine takes them.

What is measured:

* RSS: the process's resident set size (``VmRSS`` of /proc/self/status), MiB, what the operating
  system sees (the interpreter, numpy, scipy and the learner; freed memory that the allocator keeps
  counts until it gives it back).
* buffer: the bytes the session's sample buffers take (their capacity), the learner's own share.

``list``
    :class:`~shaper_nodes.core.learning.list.ListSession` with the node's defaults
    (``max_cycle_duration`` 600 s, ``sensor.max_abs_accel`` 160 m/s^2). First the baseline: a
    10 s cycle of a 3-axis accelerometer at 1 kHz (a decaying 1.6 Hz vibration plus noise),
    learned from (the reference). Then one cycle whose END comes after an hour (3.6 million
    samples fed one at a time through ``on_imu``, the node's path): refused at the 600 s limit,
    where its samples are dropped. RSS and the buffer every simulated 5 min.
``mrilc``
    :class:`~shaper_nodes.core.learning.mrilc.MrilcSession` at 500 Hz, six joints, joint states
    (positions and efforts) and the applied reference fed in blocks of one second
    (``on_joint_states``, ``on_references``: the same as one call a sample). Every two simulated
    hours: one hour of 4 s cycles with a 1 s pause (720 cycles, each learned from), then an hour
    of joint states with no START at all (an idle robot); in the second block a START whose END
    comes 20 min later (refused at the 600 s limit). RSS, the buffer, the learner's history and
    iteration every simulated 2 h.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

MIB = 1024.0 * 1024.0


def rss() -> float:
    """The resident set size of this process, MiB (VmRSS; the peak from getrusage where /proc is absent)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024 / MIB
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / MIB


# ---------------------------------------------------------------------------------------------- LIST


def run_list(rate: float = 1000.0, hours: float = 1.0, every: float = 300.0,
             progress: Callable[[str], None] = lambda s: None) -> dict:
    """The LIST part: the short baseline cycle, then one cycle of ``hours`` (see the module docstring)."""
    from shaper_nodes.core.cycles import END, MOTION_END, START
    from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListSession

    rng = np.random.default_rng(17)
    session = ListSession(ListLearner(ListConfig(highpass_hz=0.5)), "zv2")
    session.sent(None)
    session.on_shaper([1.0], [0.0], "learner", 1)
    start_rss = rss()
    dt = 1.0 / rate
    w, zeta = 10.0, 0.05

    def chunk(t: np.ndarray, t_motion_end: float) -> np.ndarray:
        s = np.clip(t - t_motion_end, 0.0, None)
        x = np.where(t > t_motion_end, np.exp(-zeta * w * s) * np.sin(w * math.sqrt(1 - zeta**2) * s), 0.0)
        a = np.column_stack([x, 0.3 * x, np.full_like(x, 9.81)])
        return a + rng.normal(0.0, 0.01, a.shape)

    # baseline: a 10 s cycle, learned from (the reference)
    progress("learner memory (LIST): the 10 s baseline cycle")
    session.on_event(START, 0, 0.0, [0.0], [1.0])
    session.on_event(MOTION_END, 0, 1.5)
    t = np.arange(int(round(10.0 * rate)) + 1) * dt
    a = chunk(t, 1.5)
    for k in range(t.size):
        session.on_imu(t[k], a[k])
    peak_buffer = session.buffered_bytes
    short_rss = rss()
    short = session.on_event(END, 0, float(t[-1]))
    if short is None:
        raise RuntimeError("the baseline cycle's END gave no result")
    baseline = {"seconds": 10.0, "samples": int(t.size), "rss_mib": short_rss, "buffer_bytes": peak_buffer,
                "outcome": short.update.action if short.update is not None else short.skipped}

    # the long cycle
    t0 = 20.0
    session.on_event(START, 1, t0, [0.0], [1.0])
    session.on_event(MOTION_END, 1, t0 + 1.5)
    rows = [{"t_s": 0.0, "rss_mib": rss(), "buffered": session.buffered, "buffer_bytes": session.buffered_bytes}]
    notice_at, notice = math.nan, ""
    peak = {"rss_mib": rows[0]["rss_mib"], "buffer_bytes": 0}
    total = int(round(hours * 3600.0 * rate))
    block = int(round(10.0 * rate))
    began = time.perf_counter()
    for first in range(0, total, block):
        t = t0 + (first + np.arange(min(block, total - first))) * dt
        a = chunk(t - t0, 1.5)
        for k in range(t.size):
            said = session.on_imu(t[k], a[k])
            if said:
                notice_at, notice = float(t[k] - t0), said
        peak["buffer_bytes"] = max(peak["buffer_bytes"], session.buffered_bytes)
        peak["rss_mib"] = max(peak["rss_mib"], rss())
        elapsed = float(t[-1] - t0) + dt
        if elapsed + 1e-9 >= rows[-1]["t_s"] + every:
            rows.append({"t_s": elapsed, "rss_mib": rss(), "buffered": session.buffered,
                         "buffer_bytes": session.buffered_bytes})
            progress(f"learner memory (LIST): {elapsed / 60:.0f} of {hours * 60:.0f} simulated min,"
                     f" RSS {rows[-1]['rss_mib']:.1f} MiB")
    end = session.on_event(END, 1, t0 + total * dt)
    if end is None:
        raise RuntimeError("the long cycle's END gave no result")
    return {"rate_hz": rate, "hours": hours, "max_cycle_duration_s": session.max_cycle_duration,
            "start_rss_mib": start_rss, "baseline": baseline, "rows": rows, "peak": peak,
            "notice_at_s": notice_at, "notice": notice, "outcome": end.skipped, "refusal": end.refusal,
            "samples": total, "wall_s": time.perf_counter() - began}


# ---------------------------------------------------------------------------------------------- MRILC


def run_mrilc(rate: float = 500.0, hours: float = 24.0, joints: int = 6, cycle_s: float = 4.0,
              progress: Callable[[str], None] = lambda s: None) -> dict:
    """The MRILC part (see the module docstring)."""
    from shaper_nodes.core.cycles import END, START
    from shaper_nodes.core.learning.mrilc import MrilcLearner, MrilcSession, model_from_params

    model, settings = model_from_params({"mrilc.rate": rate}, require_convergence=False)
    session = MrilcSession(MrilcLearner(model, joints, settings.patience, settings.noise_floor))
    start_rss = rss()
    period = 1.0 / rate
    per_s = int(round(rate))
    n = int(round(cycle_s * rate))
    r = np.zeros((n, joints))
    r[n // 8: n // 2] = 1.0  # a step and back on every joint
    y = 0.95 * model.reference_response(r, rest=np.zeros(joints))
    effort = np.zeros((n, joints))
    rest = np.zeros((per_s, joints))
    k = 0          # the next sample's index: its stamp is k / rate
    cycle = 0
    stats = {"learned": 0, "refused": 0, "too_long": 0}
    notices: list[str] = []
    reasons: dict[str, int] = {}

    def feed(values: np.ndarray, force: np.ndarray, ref: np.ndarray) -> None:
        nonlocal k
        t = (k + np.arange(values.shape[0])) * period
        for said in (session.on_joint_states(t, values, force), session.on_references(t, ref)):
            if said:
                notices.append(said)
        k += values.shape[0]

    def one_cycle() -> None:
        nonlocal cycle
        t_start = k * period
        session.on_event(START, cycle, t_start)
        for first in range(0, n, per_s):
            feed(y[first:first + per_s], effort[first:first + per_s], r[first:first + per_s])
        done = session.on_event(END, cycle, t_start + (n - 1) * period)
        cycle += 1
        if done is not None and done.update is not None:
            stats["learned"] += 1
        elif done is not None:
            stats["refused"] += 1
            stats["too_long"] += done.refusal == "too_long"
            reasons[done.skipped[:60]] = reasons.get(done.skipped[:60], 0) + 1

    rows = [{"t_h": 0.0, "rss_mib": rss(), "buffered": session.buffered, "buffer_bytes": session.buffered_bytes,
             "history": len(session.learner.history), "iteration": session.learner.iteration}]
    peak = {"rss_mib": rows[0]["rss_mib"], "buffer_bytes": 0}

    def track() -> None:
        """The peaks, the RSS once a simulated minute."""
        peak["buffer_bytes"] = max(peak["buffer_bytes"], session.buffered_bytes)
        if k % (60 * per_s) < per_s:
            peak["rss_mib"] = max(peak["rss_mib"], rss())

    began = time.perf_counter()
    blocks = int(round(hours / 2.0))
    for b in range(blocks):
        working_until = (2 * b + 1) * 3600 * per_s
        while k + n + per_s <= working_until:  # an hour of cycles with a pause of 1 s
            one_cycle()
            feed(rest, rest, rest)
            track()
        idle_until = (2 * b + 2) * 3600 * per_s
        if b == 1:  # a START whose END comes 20 min later
            t_start = k * period
            session.on_event(START, cycle, t_start)
            for _ in range(20 * 60):
                feed(rest, rest, rest)
                track()
            done = session.on_event(END, cycle, k * period)
            cycle += 1
            stats["refused"] += 1
            stats["too_long"] += done is not None and done.refusal == "too_long"
        while k < idle_until:  # then joint states with no START at all
            feed(rest, rest, rest)
            track()
        peak["rss_mib"] = max(peak["rss_mib"], rss())
        rows.append({"t_h": 2.0 * (b + 1), "rss_mib": rss(), "buffered": session.buffered,
                     "buffer_bytes": session.buffered_bytes, "history": len(session.learner.history),
                     "iteration": session.learner.iteration})
        progress(f"learner memory (MRILC): {2 * (b + 1)} of {hours:g} simulated h, RSS {rows[-1]['rss_mib']:.1f} MiB,"
                 f" {stats['learned']} cycles learned")
    return {"rate_hz": rate, "hours": hours, "joints": joints, "cycle_s": cycle_s, "start_rss_mib": start_rss,
            "rows": rows, "peak": peak, "stats": stats, "notices": notices[:3], "reasons": reasons,
            "samples_per_stream": k, "wall_s": time.perf_counter() - began}


# ---------------------------------------------------------------------------------------------- driver


def _child(part: str) -> dict:
    """Run ``part`` in a fresh interpreter; its figures."""
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    out = subprocess.run([sys.executable, "-m", "benchmarks.learner_memory", "--part", part, "--json"],
                         capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"learner memory ({part}) failed: {out.stderr.strip()[-2000:]}")
    result: dict = json.loads(out.stdout)
    return result


def run(progress: Callable[[str], None] = lambda s: None) -> dict:
    """Both parts, each in its own process."""
    report = {}
    for part in ("list", "mrilc"):
        progress(f"learner memory: {part} (its own process; a few minutes at most)")
        report[part] = _child(part)
    return report


def print_table(result: dict) -> None:
    if "list" in result:
        r = result["list"]
        b = r["baseline"]
        print(f"Learner memory, LIST: one cycle of {r['hours']:g} h at {r['rate_hz']:g} Hz (3 axes, simulated time,"
              f" {r['samples']} samples through on_imu, {r['wall_s']:.0f} s wall)")
        print(f"  RSS: VmRSS of the process, MiB; buffer: the session's sample buffer, KiB. Process at start"
              f" {r['start_rss_mib']:.1f} MiB")
        print(f"  baseline, a {b['seconds']:g} s cycle ({b['samples']} samples): RSS {b['rss_mib']:.1f} MiB, buffer"
              f" {b['buffer_bytes'] / 1024:.0f} KiB ({b['outcome']})")
        head = f"  {'sim min':>8}{'RSS MiB':>9}{'vs base':>9}{'samples':>10}{'buffer KiB':>12}"
        print(head)
        print("  " + "-" * (len(head) - 2))
        for row in r["rows"]:
            print(f"  {row['t_s'] / 60:>8.0f}{row['rss_mib']:>9.1f}{row['rss_mib'] - b['rss_mib']:>+9.1f}"
                  f"{row['buffered']:>10}{row['buffer_bytes'] / 1024:>12.0f}")
        print(f"  peak: RSS {r['peak']['rss_mib']:.1f} MiB, buffer {r['peak']['buffer_bytes'] / MIB:.1f} MiB;"
              f" limit passed at {r['notice_at_s']:.3f} s ({r['max_cycle_duration_s']:g} s); END: {r['refusal']}")
        print(f"  {r['outcome']}")
    if "mrilc" in result:
        if "list" in result:
            print()
        m = result["mrilc"]
        s = m["stats"]
        print(f"Learner memory, MRILC: {m['hours']:g} simulated h at {m['rate_hz']:g} Hz, {m['joints']} joints"
              f" ({m['samples_per_stream']} samples per stream in 1 s blocks, {m['wall_s']:.0f} s wall);"
              f" every 2 h: 1 h of {m['cycle_s']:g} s cycles, 1 h with no START")
        print(f"  cycles learned {s['learned']}, refused {s['refused']} ({s['too_long']} too long);"
              f" process at start {m['start_rss_mib']:.1f} MiB")
        head = f"  {'sim h':>6}{'RSS MiB':>9}{'samples':>9}{'buffer KiB':>12}{'history':>9}{'iteration':>11}"
        print(head)
        print("  " + "-" * (len(head) - 2))
        for row in m["rows"]:
            print(f"  {row['t_h']:>6.0f}{row['rss_mib']:>9.1f}{row['buffered']:>9}{row['buffer_bytes'] / 1024:>12.0f}"
                  f"{row['history']:>9}{row['iteration']:>11}")
        print(f"  peak: RSS {m['peak']['rss_mib']:.1f} MiB, buffer {m['peak']['buffer_bytes'] / MIB:.1f} MiB")
        for reason, count in m["reasons"].items():
            print(f"  refused {count}x: {reason}...")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.learner_memory", description=__doc__.split("\n")[0])
    p.add_argument("--part", choices=("list", "mrilc"), help="run one part in this process")
    p.add_argument("--json", action="store_true", help="print the part's figures as JSON")
    args = p.parse_args(argv)

    def progress(text: str) -> None:
        print(f"[bench] {text}", file=sys.stderr, flush=True)

    if args.part:
        result = (run_list if args.part == "list" else run_mrilc)(progress=progress)
        report = {args.part: result}
    else:
        report = run(progress)
    if args.json and args.part:
        print(json.dumps(report[args.part]))
    else:
        print_table(report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
