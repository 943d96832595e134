"""Remake the six-axis arm's reference recordings of bags/ with the suite's own nodes.

Two recordings, both rosbag2 folders with zstd-compressed MCAP chunks:

``arm_calibration/``
    What ``calibrate --execute`` records (one rosbag2 folder per pose: the flange IMU, the joint
    states, the calibration's events and its setup), on a smaller grid than config/calibrate.yaml's
    3 x 3 so that it stays within a few MB: the elbow's three values (0.5, 1.57, 2.4 rad; the joint
    that moves the lowest mode most) at shoulder_lift -1.57 rad, wrist_1 following, two excitations
    per pose, 1.5 s of free decay each, and a quicker approach between poses (1 rad/s, 0.5 s at rest).
``arm_production_payload/``
    The pick-and-place cycle of the arm demo (six moves, 1.5 s at rest after each) through the shaper
    node's FollowJointTrajectory proxy with the calibration's fixed shaper (its shaper.yaml: ZV on the
    home pose's modes), recorded by the ``recorder`` node with the identifier's drift watch running;
    after ``--cycles-before`` cycles the payload goes from 2 kg to ``--payload`` kg
    (``arm.payload_mass`` set on the sim plant node, as ``ros2 param set`` does) and ``--cycles-after``
    cycles follow. ``/cycle_events`` marks each cycle's last move (the reach back home).

The sim plant runs the arm in lockstep (simulated time) with the controller at 250 Hz and two physics
steps per period (``rate`` 250, ``arm.substeps`` 2: half the demo's rates, a 2 ms physics step, whose
frequency error is 0.1 % at 10 Hz and 0.6 % at 20 Hz): the flange IMU at 500 Hz, the rate at which a
UR e-Series reports its tool accelerometer over RTDE, and the joint states at 250 Hz, so that the
recordings stay small (the joint states' 18 doubles a message hardly compress: at 500 Hz they were
3.2 MB of the production run's 4.4). The shaper node runs at the same 250 Hz. Run::

    ./run exec python scripts/arm_reference_bags.py --out out/armbags            # make, analyse, print
    ./run exec python scripts/arm_reference_bags.py --out out/armbags --install  # and replace bags/'s

It prints what ``analyze_bag`` (and ``calibrate --from-bag``) report on each recording.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import pathlib
import shutil
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
RATE = 250.0  # Hz, the controller (and the shaper, and the joint states)
NOISE = 0.01  # m/s^2, the accelerometer's white noise per axis (as the demo)
CALIBRATION_NAME, PRODUCTION_NAME = "arm_calibration", "arm_production_payload"
#: the calibration: config/calibrate.yaml with a smaller grid (see the module docstring)
CALIBRATION = {"grid.joints": ["elbow_joint"], "grid.lower": [0.5], "grid.upper": [2.4], "grid.counts": [2],
               "follow.joints": ["wrist_1_joint"], "follow.gains": [-1.0], "excitation.repeats": 2,
               "excitation.decay": 1.5, "approach.max_velocity": 1.0, "approach.settle": 0.5,
               "compression": "zstd"}
RECORDED = ["/joint_states", "/tip_imu", "/cycle_events", "/shaper/active_shaper", "/diagnostics",
            "/parameter_events"]
#: analyze_bag's options for the arm: the motor-side joint states ring by a few micro-radians after a
#: move (the elastic links pull on the motors), so rest is within 0.1 mrad; three modes at most
ANALYSIS = ["--settle-tolerance", "1e-4", "--max-modes", "3", "--learners="]


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="arm_reference_bags", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=pathlib.Path, required=True, help="working folder (must not exist)")
    p.add_argument("--install", action="store_true", help="replace bags/arm_calibration and"
                   " bags/arm_production_payload with the new recordings")
    p.add_argument("--payload", type=float, default=4.5, help="payload after the change, kg (default 4.5)")
    p.add_argument("--cycles-before", type=int, default=1, help="cycles with the 2 kg payload (default 1)")
    p.add_argument("--cycles-after", type=int, default=2, help="cycles with the new payload (default 2: the"
                   " identifier's drift watch confirms over two)")
    return p.parse_args(argv)


def run_calibration(start, out: pathlib.Path) -> pathlib.Path:
    """``calibrate --execute`` on the running sim, with the smaller grid; returns its output folder."""
    from ament_index_python.packages import get_package_share_directory

    config = pathlib.Path(get_package_share_directory("shaper_nodes")) / "config" / "calibrate.yaml"
    folder = out / "calibration"
    proc = start("shaper_nodes", "calibrate", CALIBRATION, params_file=config,
                 args=["--execute", "--out", str(folder)])
    code = proc.proc.wait(timeout=1800)
    if code != 0:
        tail = "\n".join(proc.log_path.read_text(errors="replace").splitlines()[-8:])
        raise RuntimeError(f"calibrate failed (exit {code}):\n{tail}")
    return folder


def run_production(start, ctx, out: pathlib.Path, calibration: pathlib.Path, args: argparse.Namespace) -> None:
    """The pick-and-place cycles with the calibrated fixed shaper; the payload changes part-way."""
    from diagnostic_msgs.msg import DiagnosticArray

    from sim_plant_node.arm.description import JOINT_NAMES
    from sim_plant_node.arm.task import cycle_moves
    from sim_plant_node.clients.arm_demo import ArmClient, fallback_request
    from sim_plant_node.clients.conductor import Conductor

    start("shaper_nodes", "shaper_node", {"joint_names": list(JOINT_NAMES), "command_rate": RATE,
                                          "use_sim_time": True, "action.server_timeout": 30.0})
    start("shaper_nodes", "identifier", {"use_sim_time": True, "buffer_cycles": 20, "settle_tolerance": 1e-4,
                                         "max_modes": 3})
    start("shaper_nodes", "recorder", {"output": str(out / PRODUCTION_NAME), "topics": RECORDED,
                                       "use_sim_time": True, "compression": "zstd"})
    conductor = Conductor(context=ctx)
    client = ArmClient(conductor)
    verdicts: list[str] = []  # the identifier's drift watch, per cycle

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith("identifier:"):
                level = {b"\x00": "OK", b"\x01": "WARN", b"\x02": "ERROR"}.get(bytes(status.level), "?")
                verdicts.append(f"{level} {status.message}")

    conductor.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 100)
    try:
        conductor.wait_ready(60.0, {"/cycle_events": 3})  # this node, the identifier, the recorder
        client.wait_ready(3)
        from shaper_nodes.ros.conversions import msg_hz

        request = fallback_request(calibration)
        resp = conductor.call(conductor.set_shaper_cli, request)
        if not resp.success:
            raise RuntimeError(f"the shaper refused the calibrated fallback: {resp.message}")
        print("production: calibrated fixed shaper " + request.shaper.family + " at " + ", ".join(
            f"{msg_hz(m):.3f} Hz" for m in request.shaper.design_modes), flush=True)
        moves = cycle_moves()
        for cycle in range(args.cycles_before + args.cycles_after):
            if cycle == args.cycles_before:
                conductor.set_plant(arm__payload_mass=float(args.payload))
                print(f"production: payload {args.payload:g} kg from cycle {cycle} on", flush=True)
            print(f"production: cycle {cycle} ", end="", flush=True)
            client.run_cycle(cycle, moves, lambda: print(".", end="", flush=True))
            print(flush=True)
        last = f"cycle {args.cycles_before + args.cycles_after - 1}"
        conductor.spin_until(lambda: any(last in v for v in verdicts), 60.0, f"the drift watch's verdict on {last}")
        for v in verdicts:
            print(f"production: identifier: {v}", flush=True)
    finally:
        conductor.close()


def analyse(out: pathlib.Path) -> str:
    """What analyze_bag and calibrate --from-bag report, as text."""
    from shaper_nodes.cli import analyze_bag
    from shaper_nodes.nodes import calibrate

    text = io.StringIO()
    recording = out / CALIBRATION_NAME
    for pose in sorted(p for p in recording.iterdir() if (p / "metadata.yaml").is_file()):
        text.write(f"$ analyze_bag {CALIBRATION_NAME}/{pose.name} {' '.join(ANALYSIS)}\n")
        with contextlib.redirect_stdout(text):
            analyze_bag.main([str(pose), *ANALYSIS, "--no-progress"])
    text.write(f"$ calibrate --from-bag {CALIBRATION_NAME}\n")
    with contextlib.redirect_stdout(text):
        calibrate.from_bag(recording, out / "from_bag", workers=1)
    text.write(f"$ analyze_bag {PRODUCTION_NAME} {' '.join(ANALYSIS)}\n")
    with contextlib.redirect_stdout(text):
        analyze_bag.main([str(out / PRODUCTION_NAME), *ANALYSIS, "--no-progress", "--out",
                          str(out / "production_report")])
    return text.getvalue()


def size(path: pathlib.Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from sim_plant_node.arm.task import HOME
    from sim_plant_node.clients.conductor import node_session

    out: pathlib.Path = args.out
    if out.exists():
        print(f"arm_reference_bags: {out} exists; give a new --out", file=sys.stderr)
        return 2
    out.mkdir(parents=True)
    t0 = time.monotonic()
    with node_session(out, "armbags") as (start, ctx):
        start("sim_plant_node", "sim_plant", {"plant.model": "arm", "mode": "lockstep", "rate": RATE,
                                              "arm.substeps": 2, "task.start": HOME.tolist(),
                                              "imu.noise_stddev": NOISE, "lockstep_timeout": 60.0})
        print("calibration: " + json.dumps(CALIBRATION), flush=True)
        calibration = run_calibration(start, out)
        shutil.copytree(calibration / "recording", out / CALIBRATION_NAME)
        print(f"calibration: done ({time.monotonic() - t0:.0f} s)", flush=True)
        run_production(start, ctx, out, calibration, args)
    print(f"recorded in {time.monotonic() - t0:.0f} s: {CALIBRATION_NAME} {size(out / CALIBRATION_NAME) / 1e6:.2f} MB,"
          f" {PRODUCTION_NAME} {size(out / PRODUCTION_NAME) / 1e6:.2f} MB", flush=True)
    report = analyse(out)
    (out / "analysis.txt").write_text(report)
    print(report)
    if args.install:
        for name in (CALIBRATION_NAME, PRODUCTION_NAME):
            target = ROOT / "bags" / name
            if target.exists():
                shutil.rmtree(target)
            shutil.copytree(out / name, target)
        print(f"installed in {ROOT / 'bags'}: {size(ROOT / 'bags') / 1e6:.2f} MB in all")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
