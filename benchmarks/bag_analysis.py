"""Bag analysis throughput on a long recording, against the rosbags reader alone.

Data: a synthetic robot recording (:mod:`shaper_nodes.analysis.synthetic`): a 4 Hz, 2 % damped
mode moved back and forth, sensor_msgs/Imu and sensor_msgs/JointState (two joints) at 1 kHz
each, with gravity and noise, written with rosbags' Writer (rosbag2 folder, MCAP) into a
temporary folder; no cycle events, so the cycles come from the motion of the joint states.

Methods (messages per second over the whole bag):

``baseline: rosbags reader``
    ``AnyReader.messages()`` over every connection, doing nothing with the bytes: the least any
    analysis that reads the bag with rosbags must spend.
``rosbags reader + deserialize``
    The same plus ``AnyReader.deserialize`` of every message: what a straightforward analysis
    script spends before it computes anything.
``read_recording``
    The analysis' reading and extraction into arrays (topic choice, decoding, sorting).
``analyze_bag (full)``
    ``read_recording`` plus the whole analysis: segmentation, per-cycle residual vibration and
    settling, spectrum, identification (20 cycles), recommendation and the LIST replay.
"""

from __future__ import annotations

import pathlib
import tempfile
import time
from collections.abc import Callable


def run(*, messages: int = 1_000_000, progress: Callable[[str], None] = lambda s: None) -> dict:
    """Write the bag, time the methods once each (the bag is large), return the figures."""
    from rosbags.highlevel import AnyReader

    from shaper_nodes.analysis.analyze import Options, analyze
    from shaper_nodes.analysis.streams import read_recording
    from shaper_nodes.analysis.synthetic import simulate, write_bag

    rate = 1000.0
    seconds_per_cycle = 0.625 + 2.5  # move + dwell of simulate()'s defaults
    cycles = max(2, int(messages / (2 * rate * seconds_per_cycle)) + 1)
    with tempfile.TemporaryDirectory(prefix="bag_bench_") as tmp:
        path = pathlib.Path(tmp) / "robot"
        progress(f"bag analysis: simulating {cycles} cycles at {rate:g} Hz")
        t, u, a, truth = simulate(cycles=cycles, rate=rate, offset=(0.0, 0.0, 9.81))
        keep = min(t.size, (messages + 1) // 2)
        t, u, a = t[:keep], u[:keep], a[:keep]
        start = time.perf_counter()
        written = write_bag(path, t, u, a, joint_names=("joint_1", "joint_2"))
        write_s = time.perf_counter() - start
        size = sum(f.stat().st_size for f in path.iterdir())
        progress(f"bag analysis: wrote {written} messages ({size / 1e6:.0f} MB) in {write_s:.1f} s")
        timings: dict[str, float] = {}

        progress("bag analysis: rosbags reader alone")
        start = time.perf_counter()
        with AnyReader([path]) as reader:
            n = sum(1 for _ in reader.messages())
        timings["baseline: rosbags reader"] = time.perf_counter() - start
        assert n == written

        progress("bag analysis: rosbags reader + deserialize")
        start = time.perf_counter()
        with AnyReader([path]) as reader:
            for conn, _, raw in reader.messages():
                reader.deserialize(raw, conn.msgtype)
        timings["rosbags reader + deserialize"] = time.perf_counter() - start

        progress("bag analysis: read_recording")
        start = time.perf_counter()
        rec = read_recording(path)
        timings["read_recording"] = time.perf_counter() - start

        progress("bag analysis: full analysis")
        start = time.perf_counter()
        an = analyze(read_recording(path), Options(learner_params={"list.highpass_hz": 0.5}))
        timings["analyze_bag (full)"] = time.perf_counter() - start
    base = timings["baseline: rosbags reader"]
    return {
        "messages": written, "bag_mb": size / 1e6, "recorded_s": float(t[-1] - t[0]), "write_s": write_s,
        "cycles": len(an.cycles), "mode_hz": an.modes[0].hz if an.modes else float("nan"),
        "true_mode_hz": truth.mode_hz,
        "read_messages": rec.messages_read,
        "methods": [{"method": k, "seconds": v, "messages_per_s": written / v, "ratio_to_baseline": v / base}
                    for k, v in timings.items()],
    }


def print_table(result: dict) -> None:
    """The figures as a table."""
    print(f"Bag analysis: {result['messages']:,} messages (Imu + JointState at 1 kHz, {result['recorded_s']:.0f} s,"
          f" {result['bag_mb']:.0f} MB MCAP; written in {result['write_s']:.1f} s), {result['cycles']} cycles found,"
          f" mode {result['mode_hz']:.4g} Hz (true {result['true_mode_hz']:g})")
    head = f"  {'method':<32}{'s':>8}{'messages/s':>13}{'x baseline time':>17}"
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in result["methods"]:
        print(f"  {m['method']:<32}{m['seconds']:>8.2f}{m['messages_per_s']:>13,.0f}{m['ratio_to_baseline']:>17.2f}")


if __name__ == "__main__":
    print_table(run())
