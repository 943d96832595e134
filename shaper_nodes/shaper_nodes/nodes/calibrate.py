"""calibrate: measure the arm's modes over its workspace and write the scheduler's rule base.

    ros2 run shaper_nodes calibrate --ros-args --params-file calibrate.yaml        # print the plan
    ros2 run shaper_nodes calibrate --execute --out DIR --ros-args --params-file calibrate.yaml
    ros2 run shaper_nodes calibrate --execute --resume --out DIR --ros-args ...  # after a stop
    ros2 run shaper_nodes calibrate --from-bag DIR/recording --out DIR2           # recompute offline

Without ``--execute`` it prints the plan (poses, excitation, duration) and moves nothing: it
moves a real robot. With it, for each pose of the plan (:mod:`shaper_nodes.core.calibration.plan`)
it sends ``control_msgs/action/FollowJointTrajectory`` goals (the controller's action, or the
shaper node's proxy with the shaper set to ``none``): the approach, then ``repeats`` out-and-back
excitations each followed by ``decay`` s of free vibration, and records the accelerometer, the
joint states and its own events to ``DIR/recording/pose_NNN`` (a rosbag2 folder with MCAP
storage, chunks zstd-compressed with ``compression: zstd``, written as ``pose_NNN.partial`` and renamed,
its MCAP file ``pose_NNN.mcap`` with it, when the pose is complete). At the end it
goes back home and writes, from the recording (:mod:`shaper_nodes.analysis.calibration`),
``report.json``, ``report.md`` with figures, ``scheduler.yaml`` and ``shaper.yaml``.

Stops: a goal the controller rejects or aborts, a dead or silent controller (``timeouts.peer``), a missing
action server or accelerometer, a failed write (a full disk), Ctrl-C or SIGTERM end the run with one line
naming the cause and a status of its own (:mod:`.calibrate_stops`); on every one of them the running goal is
cancelled at the controller, the pose in progress is discarded, completed poses stay, no report is written, and
``--resume`` continues from the first pose not completed (also after ``kill -9``, which leaves no analysis
worker behind). A refused plan (limits, sizes; a params file over 1 MiB before it is parsed) writes nothing.
A pose whose accelerometer was flat, stuck, saturated or silent is reported as a sensor fault and not used.

Every wait is on the robot's data (feedback stamps, accelerometer stamps), so it runs the same
on a robot, on a simulator in lockstep, or under load. Parameters: :data:`PARAMETERS`
(config/calibrate.yaml).
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import shutil
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from shaper_nodes.analysis.calibration import (
    compute,
    plan_from_setup,
    pose_folders,
    read_recording,
    setup_dict,
)
from shaper_nodes.analysis.calibration_outputs import sensor_faults
from shaper_nodes.analysis.calibration_pool import NICENESS, PosePipeline
from shaper_nodes.analysis.calibration_report import write_outputs
from shaper_nodes.analysis.worker_pool import worker_pool
from shaper_nodes.core.calibration import Plan, PlanError, Waypoint
from shaper_nodes.core.calibration.plan import approach as plan_approach
from shaper_nodes.core.calibration.plan import make_plan, quintic_time
from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.core.files import write_atomic
from shaper_nodes.ros.diagnostics import ERROR, Diagnostics
from shaper_nodes.ros.parameters import declare_all

from .calibrate_parameters import PARAMETERS, CalibrateParams, config_from_values, settings_from_values
from .calibrate_stops import (
    EXIT_ABORTED,
    EXIT_CANCELLED,
    EXIT_REFUSED,
    EXIT_TERMINATED,
    EXIT_WRITE_FAILED,
    Aborted,
    Stopped,
    WriteFailed,
    params_file_too_large,
    stop_on_signals,
)
from .calibrator import Calibrator

__all__ = ["EXIT_ABORTED", "EXIT_CANCELLED", "EXIT_REFUSED", "EXIT_TERMINATED", "EXIT_WRITE_FAILED", "PARAMETERS",
           "Aborted", "CalibrateParams", "Calibrator", "config_from_values", "main", "settings_from_values"]


def parse_args(argv: list[str]) -> argparse.Namespace:
    from shaper_nodes.ros.node_main import parameter_help

    epilog = ("ROS arguments follow --ros-args: --params-file FILE (see config/calibrate.yaml), -p NAME:=VALUE.\n\n"
              + parameter_help({"": PARAMETERS}) + "\nExample:\n  ros2 run shaper_nodes calibrate --ros-args"
              " --params-file $(ros2 pkg prefix shaper_nodes)/share/shaper_nodes/config/calibrate.yaml\n")
    p = argparse.ArgumentParser(prog="calibrate", description=__doc__.split("\n\n")[0], epilog=epilog,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--execute", action="store_true", help="move the robot through the plan (default: print it)")
    p.add_argument("--resume", action="store_true", help="continue the calibration in --out from its last"
                   " completed pose (with --execute)")
    p.add_argument("--out", type=pathlib.Path, default=None, help="output folder (default:"
                   " calibration-<date-time> in the current folder)")
    p.add_argument("--from-bag", type=pathlib.Path, default=None, metavar="RECORDING",
                   help="recompute the report, rule base and fallback from a calibration's recording folder")
    p.add_argument("--workers", type=int, default=2, help="processes identifying poses in parallel (default 2)")
    return p.parse_args(argv)


def from_bag(recording: pathlib.Path, out: pathlib.Path, workers: int) -> int:
    try:
        setup, poses = read_recording(recording)
        cal = compute(setup, poses, workers=workers)
    except PlanError as err:
        print(f"calibrate: {err}", file=sys.stderr)
        return EXIT_REFUSED
    try:
        written = write_outputs(out, cal, str(recording))
    except OSError as err:
        print(f"calibrate: stopped: {WriteFailed(err, err.filename or out)}", file=sys.stderr)
        return EXIT_WRITE_FAILED
    summary(cal)
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def summary(cal: Any) -> None:
    for r in cal.results:
        modes = ", ".join(f"{m.hz:.3f} Hz ({m.zeta:.4f})" for m in r.modes) or "none"
        print(f"  {r.index:3d} {r.name:<12} {modes}{'   ' + '; '.join(r.flags) if r.flags else ''}")
    for n in cal.notes:
        print(f"  note: {n}")


KEPT = "the pose in progress was discarded, completed poses are kept"


@survives_closed_pipe
def main(args: list[str] | None = None) -> int:
    from rclpy.utilities import remove_ros_args

    from shaper_nodes.ros.node_main import params_file_problem, params_files

    stop_on_signals()  # SIGINT and SIGTERM: Stopped, wherever the run is (parsing included)
    argv = list(sys.argv if args is None else args)
    try:
        # before any parser reads the file: its size, then what rcl would report as a traceback
        problem = params_file_too_large(params_files(argv)) or params_file_problem(argv)
        if problem is not None:
            print(f"calibrate: refused: {problem}", file=sys.stderr)
            return EXIT_REFUSED
        opts = parse_args(remove_ros_args(argv)[1:])
        if opts.from_bag is not None:
            return from_bag(opts.from_bag, opts.out or opts.from_bag.parent, opts.workers)
        if opts.resume and (opts.out is None or not opts.execute):
            print("calibrate: --resume needs --execute and the --out folder of the calibration to continue",
                  file=sys.stderr)
            return EXIT_REFUSED
        return _node_main(argv, opts)
    except KeyboardInterrupt as err:  # before or after the node ran
        code, head = _signalled(err)
        print(f"{head}; nothing was moved or is running", file=sys.stderr)
        return code


def _signalled(err: KeyboardInterrupt) -> tuple[int, str]:
    if isinstance(err, Stopped):
        return err.status, f"\ncalibrate: cancelled by {err}"
    return EXIT_CANCELLED, "\ncalibrate: cancelled by SIGINT"


def _node_main(argv: list[str], opts: argparse.Namespace) -> int:
    """The run with its node; every way out cancels the running goal and ends in one line (see calibrate_stops)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    from shaper_nodes.ros.parameters import read

    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("calibrate")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    cal: Calibrator | None = None
    code, head, tail = 0, "", ""
    try:
        declare_all(node, PARAMETERS)
        v = read(node, CalibrateParams)  # a one-shot command: its parameters do not change while it runs
        if not v.joint_names:
            raise PlanError("parameter joint_names is required: the controller's joints (see config/calibrate.yaml)")
        cal = Calibrator(node, executor, v)
        return _run(cal, v, opts)
    except KeyboardInterrupt as err:  # Ctrl-C, SIGTERM
        (code, head), tail = _signalled(err), f"; {KEPT} (--resume)"
    except (PlanError, ValueError) as err:
        code, head = EXIT_REFUSED, f"calibrate: refused: {err}"
    except WriteFailed as err:
        code, head, tail = EXIT_WRITE_FAILED, f"calibrate: stopped: {err}", f"; {KEPT}: free space, then --resume"
    except Aborted as err:
        code, head = EXIT_ABORTED, f"calibrate: aborted: {err}"
    finally:
        try:
            note = cal.cancel() if cal is not None else ""  # on every stop, an unforeseen error's too
        except Exception as err:
            note = f"; the running goal could not be cancelled ({err})"
        if head:
            print(head + note + tail, file=sys.stderr)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return code


def _run(cal: Calibrator, v: CalibrateParams, opts: argparse.Namespace) -> int:
    out: pathlib.Path = opts.out or pathlib.Path(datetime.datetime.now().strftime("calibration-%Y%m%d-%H%M%S"))
    if opts.resume:
        try:
            setup = json.loads((out / "plan.json").read_text())
        except (OSError, ValueError) as err:
            raise PlanError(f"nothing to resume in {out}: {err}") from None
        plan, _, _, _ = plan_from_setup(setup)
        print(f"calibrate: resuming {out}: {len(pose_folders(out / 'recording'))} of {len(plan.steps)} poses done")
    else:
        here = _start_pose(cal, v, opts.execute)
        config = config_from_values(v, here)
        plan = make_plan(config, here)
        setup = setup_dict(plan, settings_from_values(v), str(v.scheduler.family),
                           float(v.scheduler.premise_threshold),
                           {"action": str(v.action), "joint_states": str(v.topics.joint_states)})
        plan_from_setup(setup)  # the setup recorded recomputes this plan (refused here, not after the moves)
    print(plan.describe(), flush=True)
    if not opts.execute:
        print("calibrate: plan only; add --execute to move the robot", flush=True)
        return 0
    if not opts.resume:
        if out.exists():
            raise PlanError(f"{out} exists: give another --out, or --resume to continue it")
        try:
            (out / "recording").mkdir(parents=True)
            write_atomic(out / "plan.json", json.dumps(setup, indent=1, sort_keys=True) + "\n")
        except OSError as err:
            raise WriteFailed(err, err.filename or out / "plan.json") from None
    return _execute(cal, plan, setup, out, opts.workers)


def _start_pose(cal: Calibrator, v: CalibrateParams, execute: bool) -> np.ndarray | None:
    """Where the arm is (its joint states), the plan's start: the first approach, and so the plan's duration,
    starts there. A plan only, with base_pose and home_pose given, is still printed when no joint states come
    (no robot running): from the home pose, and it says so."""
    try:
        return cal.wait_pose()
    except Aborted as err:
        if execute or not v.base_pose or not v.home_pose:
            raise
        print(f"calibrate: {err}; the plan below starts at the home pose", flush=True)
        return None


def publish_sensor_faults(diagnostics: Diagnostics, faults: list[tuple[int, str, str]]) -> None:
    """``calibrate: sensor`` (ERROR) on /diagnostics naming each pose whose accelerometer failed (index, name,
    why); nothing if none did."""
    if faults:
        poses = "; ".join(f"pose {i} ({name}): {why}" for i, name, why in faults)
        diagnostics.publish("sensor", ERROR, f"sensor fault at {len(faults)} pose(s), not identified: {poses}",
                            [(f"pose {i} ({name})", why) for i, name, why in faults])


def _execute(cal: Calibrator, plan: Plan, setup: dict[str, Any], out: pathlib.Path, workers: int) -> int:
    """Record every pose not done yet, back home, then the outputs. With ``workers`` > 1 each pose is identified
    in a worker as soon as its recording is complete, while the next one is recorded (:class:`PosePipeline`), and
    a worker assembles the results and writes the outputs: the same as :func:`compute` and :func:`write_outputs`
    on the whole recording after the last pose (as with one worker), byte for byte."""
    recording = out / "recording"
    for partial in recording.glob("*.partial"):
        shutil.rmtree(partial)
    t_wall = time.monotonic()
    if workers <= 1:
        _record(cal, plan, setup, recording, t_wall, lambda _index, _folder: None)
        print("calibrate: identifying the modes at every pose ...", flush=True)
        setup_read, poses = read_recording(recording)
        result = compute(setup_read, poses, workers=workers)
        publish_sensor_faults(cal.diagnostics, sensor_faults(result))
        try:
            written = write_outputs(out, result, "recording")
        except OSError as err:
            raise WriteFailed(err, err.filename or out) from None
    else:
        n = min(workers, len(plan.steps))
        with worker_pool(n, NICENESS) as pool:
            pipeline = PosePipeline(pool, setup, n)
            _record(cal, plan, setup, recording, t_wall, pipeline.submit)
            print("calibrate: identifying the modes at every pose ...", flush=True)
            setup_read, results = pipeline.results()
            publish_sensor_faults(cal.diagnostics, sensor_faults(results))
            try:
                result, written = pipeline.finish(out, setup_read, results)
            except OSError as err:
                raise WriteFailed(err, err.filename or out) from None
    summary(result)
    print(f"calibrate: done in {time.monotonic() - t_wall:.0f} s; written: " + ", ".join(p.name for p in written))
    return 0


def _record(cal: Calibrator, plan: Plan, setup: dict[str, Any], recording: pathlib.Path, t_wall: float,
            completed: Callable[[int, pathlib.Path], None]) -> None:
    """Record the poses not done yet, then move back home; ``completed(index, folder)`` is called for every
    completed pose (those done before first), as soon as its folder is complete."""
    folders = {int(p.name.split("_")[1]): p for p in pose_folders(recording)}
    for index, folder in sorted(folders.items()):
        completed(index, folder)
    c = plan.config
    for step in plan.steps:
        if step.index in folders:
            continue
        here = cal.wait_pose()
        approach = plan_approach(step.pose, quintic_time(step.pose - here, c.approach_velocity,
                                                         c.approach_acceleration), c.settle)
        folder = recording / f"pose_{step.index:03d}"
        lost = cal.run_pose(step, setup, folder, approach)
        completed(step.index, folder)
        print(f"calibrate: pose {step.index + 1}/{len(plan.steps)} ({step.name}) recorded"
              f" ({time.monotonic() - t_wall:.0f} s)" + (f"; {lost} (gaps in the stamps)" if lost else ""), flush=True)
    here = cal.wait_pose()
    cal.move((Waypoint(quintic_time(c.home_pose - here, c.approach_velocity, c.approach_acceleration),
                       c.home_pose),), "the move back home")


if __name__ == "__main__":
    raise SystemExit(main())
