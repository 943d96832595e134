"""Demo: input shaping end to end over DDS.

``demo`` (or ``demo arm``) tells the arm story (:mod:`sim_plant_node.arm_demo`, ``demo --help``):
calibrate the six-axis arm's workspace, then its pick-and-place cycle unshaped, with the
calibrated fixed shaper and with the calibrated schedule. ``demo joint`` runs the
one-dimensional demo below.

The one-dimensional demo (``demo joint``) starts the sim plant (lockstep), the shaper and the
recorder as separate processes, then for every plant case (true mode at the nominal frequency
and off it) and every shaper (none, ZV, ZVD, all designed at the nominal mode) runs a few cycles
of a point-to-point move, measures the residual vibration of each cycle from the tip
accelerometer, and prints a table. Writes the recording (rosbag2 folder, MCAP), a CSV of the
results and a PNG plot of the accelerometer traces, and prints where they are.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import math
import os
import pathlib
import sys
import time

import numpy as np

from shaper_nodes.core.closed_pipe import survives_closed_pipe

RECORDED = ["/joint_states", "/tip_imu", "/cycle_events", "/cycle_reports", "/shaper/commands",
            "/forward_position_controller/commands", "/shaper/active_shaper", "/sim_plant/tip_state",
            "/diagnostics"]


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="demo joint", description="The one-dimensional demo: a flexible joint at its"
                                " nominal mode and off it, unshaped, ZV and ZVD.")
    p.add_argument("--out", type=pathlib.Path, default=None,
                   help="output folder (default: out/demo-<date-time> in the current folder)")
    p.add_argument("--frequency", type=float, default=5.0, help="nominal mode natural frequency, Hz (default 5)")
    p.add_argument("--damping", type=float, default=0.01, help="nominal mode damping ratio (default 0.01)")
    p.add_argument("--offsets", default="-0.3,0,0.3",
                   help="true frequency offsets from nominal, fractions (default -0.3,0,0.3)")
    p.add_argument("--shapers", default="none,zv,zvd", help="shaper families to compare (default none,zv,zvd)")
    p.add_argument("--cycles", type=int, default=2, help="cycles per case (default 2)")
    p.add_argument("--rate", type=float, default=500.0, help="command rate, Hz (default 500)")
    p.add_argument("--noise", type=float, default=0.01, help="accelerometer noise, m/s^2 (default 0.01)")
    p.add_argument("--distance", type=float, default=0.5, help="move distance, rad (default 0.5)")
    p.add_argument("--compression", choices=("none", "zstd"), default="none",
                   help="MCAP chunk compression of the recording (default none)")
    p.add_argument("--flush-period", type=float, default=1.0,
                   help="the recorder's flush_period: time between two closed MCAP chunks of the recording, s"
                        " (default 1)")
    return p.parse_args(argv)


def plot(path: pathlib.Path, traces: dict, offsets: list[float], shapers: list[str], nominal_hz: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(offsets), 1, figsize=(10, 2.8 * len(offsets)), sharex=True, squeeze=False)
    for ax, off in zip(axes[:, 0], offsets, strict=True):
        for fam in shapers:
            r = traces[(off, fam)]
            ax.plot(r.accel_times - r.start, r.accel[:, 0], lw=0.8, label=fam)
            ax.axvline(r.residual.window_start - r.start, color="0.6", lw=0.5, ls=":")
        ax.set_title(f"true mode {nominal_hz * (1 + off):.3g} Hz ({off:+.0%} from the shapers' {nominal_hz:g} Hz)",
                     fontsize=9)
        ax.set_ylabel("tip accel. (m/s$^2$)")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time from cycle start (s); dotted: start of the residual window")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@survives_closed_pipe
def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] != ["joint"]:  # the arm story (arm_demo.py); "demo arm ..." is the same
        from .arm_demo import main as arm_main

        return arm_main(argv[1:] if argv[:1] == ["arm"] else argv)
    args = parse_args(argv[1:])
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from shaper_nodes.ros.launching import NodeProcess

    from .conductor import Conductor, rms, spin_context

    out = args.out or pathlib.Path("out") / datetime.datetime.now().strftime("demo-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    bag_path = out / "recording"
    offsets = [float(x) for x in args.offsets.split(",")]
    shapers = [s.strip() for s in args.shapers.split(",")]
    omega0 = 2 * math.pi * args.frequency
    print(f"demo: nominal mode {args.frequency:g} Hz, damping {args.damping:g}; plants at "
          + ", ".join(f"{args.frequency * (1 + o):.3g} Hz" for o in offsets)
          + f"; shapers {', '.join(shapers)}; {args.cycles} cycles each; output in {out}", flush=True)

    joint = ["joint_1"]
    procs = [
        NodeProcess("sim_plant_node", "sim_plant", {
            "joint_names": joint, "rate": args.rate, "mode": "lockstep", "imu.noise_stddev": args.noise,
            "imu.axes": [0, -1, -1], "task.start": [0.0], "task.goal": [args.distance], "task.dwell": 2.0,
            "task.max_velocity": 1.0, "task.max_acceleration": 10.0}, log_path=out / "sim_plant.log"),
        NodeProcess("shaper_nodes", "shaper_node", {
            "joint_names": joint, "command_rate": args.rate, "use_sim_time": True}, log_path=out / "shaper.log"),
        NodeProcess("shaper_nodes", "recorder", {
            "output": str(bag_path), "topics": RECORDED, "use_sim_time": True, "compression": args.compression,
            "flush_period": args.flush_period},
            log_path=out / "recorder.log"),
    ]
    ctx = spin_context()
    conductor = Conductor(context=ctx)
    rows = []
    traces = {}
    t_start = time.monotonic()
    failed = ""
    try:
        for p in procs:
            p.start()
        conductor.wait_ready(60.0, {"/shaper/commands": 2, "/forward_position_controller/commands": 2,
                                    "/tip_imu": 2, "/cycle_events": 2, "/joint_states": 2})
        total = len(offsets) * len(shapers)
        case = 0
        for off in offsets:
            conductor.set_plant_mode(omega0 * (1 + off), args.damping)
            for fam in shapers:
                case += 1
                conductor.set_shaper(fam, omega0, args.damping)
                label = f"[{case}/{total}] plant {args.frequency * (1 + off):.3g} Hz, shaper {fam:5s}"
                print(f"{label}: running", end="", flush=True)
                results = conductor.run_cycles(args.cycles, progress=lambda k: print(".", end="", flush=True))
                traces[(off, fam)] = results[0]
                rows.append({"offset": off, "true_hz": args.frequency * (1 + off), "shaper": fam,
                             "residual_rms": rms(results),
                             "residual_peak": float(np.mean([r.residual.peak for r in results])),
                             "per_cycle_rms": [r.residual.rms for r in results]})
                print(f" residual RMS {rows[-1]['residual_rms']:.4g} m/s^2", flush=True)
    except (TimeoutError, RuntimeError) as err:  # a wait that failed, a refusal: one line, no traceback
        failed = f": {err}"
    finally:
        conductor.close()
        ctx.try_shutdown()
        codes = [p.stop() for p in reversed(procs)]
    if not rows or len(rows) < len(offsets) * len(shapers):
        print(f"\ndemo: incomplete{failed} (exit codes {codes}); logs in {out}", file=sys.stderr)
        return 1

    with open(out / "results.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["true_frequency_hz", "offset", "shaper", "residual_rms_m_s2", "residual_peak_m_s2",
                    "percent_of_unshaped", "per_cycle_rms_m_s2"])
        for r in rows:
            base = next(x["residual_rms"] for x in rows if x["offset"] == r["offset"] and x["shaper"] == shapers[0])
            w.writerow([f"{r['true_hz']:.6g}", r["offset"], r["shaper"], f"{r['residual_rms']:.6g}",
                        f"{r['residual_peak']:.6g}", f"{100 * r['residual_rms'] / base:.4g}",
                        " ".join(f"{v:.6g}" for v in r["per_cycle_rms"])])
    plot(out / "accelerometer.png", traces, offsets, shapers, args.frequency)

    print()
    print(f"Residual vibration: RMS of tip acceleration after the move, m/s^2 (and % of '{shapers[0]}'),"
          f" mean of {args.cycles} cycles; accelerometer noise {args.noise:g} m/s^2")
    head = f"{'true mode':>18} | " + " | ".join(f"{s:>18}" for s in shapers)
    print(head)
    print("-" * len(head))
    for off in offsets:
        cells = []
        base = next(r["residual_rms"] for r in rows if r["offset"] == off and r["shaper"] == shapers[0])
        for fam in shapers:
            v = next(r["residual_rms"] for r in rows if r["offset"] == off and r["shaper"] == fam)
            cells.append(f"{v:9.4g} ({100 * v / base:5.1f}%)")
        print(f"{args.frequency * (1 + off):8.3g} Hz ({off:+4.0%}) | " + " | ".join(f"{c:>18}" for c in cells))
    print()
    print(f"recording:  {bag_path}  (rosbag2, MCAP storage)")
    print(f"plot:       {out / 'accelerometer.png'}")
    print(f"results:    {out / 'results.csv'}")
    print(f"node logs:  {out}/*.log   ({time.monotonic() - t_start:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
