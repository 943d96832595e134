"""Bag analysis results: the demo's recording, a robot-style recording, and both cut short.

``python -m reproductions.bag_results`` (``./run exec python -m reproductions.bag_results``)
runs the demo (sim plant, shaper and recorder as processes; plant mode 6.5 Hz, shapers designed
at 5 Hz), analyses its recording with :mod:`shaper_nodes.analysis`, and compares the per-cycle
residual vibration with what the demo measured live and what the sim plant reported; analyses a
recording written by rosbags directly (standard types, no cycle events); analyses both cut in the
middle of a chunk; analyses a synthetic recording of three plants; and writes
docs/results/bag_analysis_results.md and docs/results/img/bag_*.png.
"""

from __future__ import annotations

import argparse
import csv
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

from reproductions.common import docs_option


def _cut(src: pathlib.Path, dst: pathlib.Path) -> int:
    """Copy ``src`` cut in the middle of its last chunk; returns the bytes kept."""
    from shaper_nodes.recordings import mcap_chunks

    data = src.read_bytes()
    last, length = mcap_chunks(data)[-1]
    dst.write_bytes(data[: last + length // 2])
    return last + length // 2


def _small_png(src: pathlib.Path, dst: pathlib.Path) -> None:
    """Copy a plot for the docs as a 64-colour palette PNG (a third of the size, the lines unchanged)."""
    from PIL import Image

    with Image.open(src) as im:
        im.convert("RGB").quantize(colors=64).save(dst, optimize=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="bag_results", description=__doc__.split("\n\n")[0])
    docs_option(p, "bag_analysis_results.md and img/bag_*.png")
    p.add_argument("--cycles", type=int, default=2, help="demo cycles per shaper (default 2)")
    args = p.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from shaper_nodes.analysis.analyze import Options, analyze
    from shaper_nodes.analysis.report import write_report
    from shaper_nodes.analysis.streams import read_recording
    from shaper_nodes.analysis.synthetic import simulate, simulate_plants, write_bag
    from shaper_nodes.recordings import Bag, describe_damage

    t0 = time.monotonic()
    work = pathlib.Path("out") / "bag_results"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    # 1. the demo
    demo = subprocess.run([sys.executable, "-m", "sim_plant_node.demo", "joint", "--out", str(work / "demo"),
                           "--offsets", "0.3",
                           "--shapers", "none,zv,zvd", "--cycles", str(args.cycles)], capture_output=True, text=True)
    if demo.returncode != 0:
        print(demo.stdout + demo.stderr, file=sys.stderr)
        return 1
    printed = [float(x) for x in re.findall(r"residual RMS ([0-9.eE+-]+) m/s\^2", demo.stdout)]
    with open(work / "demo" / "results.csv") as f:
        live = [float(v) for row in csv.DictReader(f) for v in row["per_cycle_rms_m_s2"].split()]
    bag = work / "demo" / "recording"
    start = time.perf_counter()
    an = analyze(read_recording(bag), Options(learners=()))
    demo_s = time.perf_counter() - start
    with Bag(bag) as b:
        decode = b.deserializer("shaper_msgs/msg/CycleReport")
        plant = [decode(raw).residual_rms for _, _, _, raw in b.messages(["/cycle_reports"])]
    write_report(an, work / "demo_report")
    # 2. a robot-style recording: rosbags directly, standard types, no events, gravity on z
    t, u, a, truth = simulate(cycles=8, mode_hz=4.0, zeta=0.02, offset=(0.0, 0.0, 9.81))
    write_bag(work / "robot", t, u, a, joint_names=("shoulder", "elbow"))
    robot = analyze(read_recording(work / "robot"), Options(learner_params={"list.highpass_hz": 0.5}))
    write_report(robot, work / "robot_report")
    # 3. both cut in the middle of their last chunk
    cuts = {}
    for name, src in (("demo", next(bag.glob("*.mcap"))), ("robot", next((work / "robot").glob("*.mcap")))):
        kept = _cut(src, work / f"{name}_cut.mcap")
        rec = read_recording(work / f"{name}_cut.mcap")
        cuts[name] = (src.stat().st_size, kept, rec, analyze(rec, Options(learners=())))
    # 4. three plants in one recording (the figures of docs/guide/analysis.md: one traces panel per plant)
    t, u, a, _truths = simulate_plants((3.5, 5.0, 6.5), cycles=6)
    write_bag(work / "plants", t, u, a, joint_noise=1e-5)
    write_report(analyze(read_recording(work / "plants"), Options()), work / "plants_report")

    img = args.docs / "img"
    img.mkdir(parents=True, exist_ok=True)
    for plot, dst in (("demo_report/traces.png", "bag_demo_traces.png"),
                      ("demo_report/spectrum.png", "bag_demo_spectrum.png"),
                      ("demo_report/sensitivity.png", "bag_demo_sensitivity.png"),
                      ("robot_report/traces.png", "bag_robot_traces.png"),
                      ("plants_report/traces.png", "bag_plants_traces.png"),
                      ("plants_report/spectrum.png", "bag_plants_spectrum.png")):
        _small_png(work / plot, img / dst)

    md = ["# Bag analysis results (generated)", "",
          f"Regenerate with `./run exec python -m reproductions.bag_results` ({time.monotonic() - t0:.0f} s here)."
          " See [the analysis guide](../guide/analysis.md) for the method.", "",
          "## The demo's recording", "",
          f"The demo ran the sim plant with its mode at 6.5 Hz, damping 0.01 (the shapers designed at 5 Hz),"
          f" {args.cycles} cycles per shaper, sim plant, shaper and recorder as separate processes over DDS."
          f" `analyze_bag` on the recording ({an.recording.messages_read} messages, {1e3 * demo_s:.0f} ms):", "",
          "| # | shaper | demo, live (m/s²) | sim plant's report (m/s²) | analysis (m/s²) | analysis vs demo |"
          " peak (m/s²) | settling to 5 % of peak (s) |", "|---|---|---|---|---|---|---|---|"]
    # three sources (the analysis, the demo's results.csv, the plant's reports): their counts need not agree
    for i, (r, lv, pl) in enumerate(zip(an.cycles, live, plant, strict=False)):
        settle = f"{r.settling_time:.3f}" if r.settling_time == r.settling_time else f"> {r.end - r.window_start:.2f}"
        md.append(f"| {i} | {r.shaper} | {lv:.6g} | {pl:.6g} | {r.rms:.6g} | {100 * (r.rms / lv - 1):+.3f} % |"
                  f" {r.peak:.4g} | {settle} |")
    means = [sum(r.rms for r in an.cycles[k * args.cycles:(k + 1) * args.cycles]) / args.cycles
             for k in range(len(printed))]
    m = an.modes[0]
    best = an.recommendation.best if an.recommendation is not None else None
    if best is None:
        print("the analysis of the demo's recording recommends no shaper", file=sys.stderr)
        return 1
    md += ["", "The demo prints the mean over a shaper's cycles: "
           + ", ".join(f"{x:.4g} (analysis {y:.4g}, {100 * (y / x - 1):+.2f} %)"
                       for x, y in zip(printed, means, strict=True))
           + " m/s²; the per-cycle values are from its results.csv.", "",
           f"Identified mode: {m.hz:.5g} Hz ± {m.omega_std / 6.283185307179586:.2g}, damping {m.zeta:.4g}"
           f" ± {m.zeta_std:.2g} (true: 6.5 Hz, 0.01; {100 * (m.hz / 6.5 - 1):+.3f} %).", "",
           f"Recommended: {best.family}, {1e3 * best.duration:.1f} ms, V {100 * best.nominal_vibration:.2g} % at the"
           f" mode ({100 * best.worst_vibration:.2g} % worst case); predicted residual"
           f" {an.predicted['rms_nominal']:.3g} m/s² plus noise, against {an.cycles[0].rms:.3g} m/s² unshaped.", "",
           "![traces](img/bag_demo_traces.png)", "", "![spectrum](img/bag_demo_spectrum.png)", "",
           "![sensitivity](img/bag_demo_sensitivity.png)", "",
           "## A recording by another writer, without cycle events", "",
           "Written with rosbags directly: sensor_msgs/Imu on /imu/data (tip acceleration on x, 9.81 m/s² of gravity"
           " on z, 0.01 m/s² noise) and sensor_msgs/JointState (two joints) at 500 Hz, 8 back-and-forth moves"
           f" of a 4 Hz, 2 % damped mode; no commands, no events. Cycles from {robot.segmentation}:", "",
           "| # | start (s) | true start | motion end (s) | true end | RMS (m/s²) |", "|---|---|---|---|---|---|"]
    for i, r in enumerate(robot.cycles):
        md.append(f"| {i} | {r.start - robot.origin:.3f} | {truth.move_starts[i]:.3f} |"
                  f" {r.motion_end - robot.origin:.3f} | {truth.move_ends[i]:.3f} | {r.rms:.4g} |")
    rm = robot.modes[0]
    rows = [x for x in robot.replays["list"].rows if "skipped" not in x]
    md += ["", f"Identified mode {rm.hz:.5g} Hz, damping {rm.zeta:.4g} (true 4 Hz, 0.02); the offset"
           f" ({'removed' if robot.removed_mean else 'kept'}) is found automatically. LIST replay: "
           + (f"the reference cycle gives A1 {rows[0]['a1_next']:.4f}, T2 {rows[0]['t2_next']:.4f} s; " if rows else "")
           + "; ".join(robot.replays["list"].notes) + ".", "",
           "![robot traces](img/bag_robot_traces.png)", "",
           "## Cut short", "", "| recording | size (bytes) | kept | readable | warning | cycles analysed (of) |",
           "|---|---|---|---|---|---|"]
    for name, (size, kept, rec, part) in cuts.items():
        full = an if name == "demo" else robot
        md.append(f"| {name} | {size} | {kept} | {rec.damage[0].readable} | {describe_damage(rec.damage[0])} |"
                  f" {len([c for c in part.cycles if c.complete])} ({len(full.cycles)}) |")
    md.append("")
    (args.docs / "bag_analysis_results.md").write_text("\n".join(md))
    print(f"wrote {args.docs / 'bag_analysis_results.md'} and {img}/bag_*.png ({time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
