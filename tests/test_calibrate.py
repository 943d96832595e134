"""The calibrate node against the simulated arm over DDS: accuracy, offline recomputation, resume, stops.

The sim plant runs the arm in lockstep behind its joint_trajectory_controller emulation; the
``calibrate`` executable runs as a process with the installed config/calibrate.yaml (overridden
where a test needs a smaller plan), exactly as ``ros2 run shaper_nodes calibrate`` would.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
import rclpy
import yaml
from conftest import ARM_RATE, ONE_WORKER, RESTARTED, SMALL_PLAN, arm_parameters, calibrate_config, call_answered
from mcap.reader import make_reader
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState

from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.calibration.plan import make_plan
from shaper_nodes.nodes.calibrate import config_from_values
from sim_plant_node.arm.dynamics import ArmModel
from sim_plant_node.arm.modal import modes, simulated_modes
from sim_plant_node.arm.task import HOME

CONFIG = calibrate_config()
RATE = ARM_RATE
#: a small plan: the elbow at three values (home's among them), two excitations each (tests/conftest.py)
SMALL = SMALL_PLAN


def sim(start_node, noise: float = 0.01, env: dict[str, str] | None = None, **extra):
    return start_node("sim_plant_node", "sim_plant", arm_parameters(noise, **extra), env=env)


def calibrate(start_node, args: list[str], params: dict | None = None, timeout: float = 600.0,
              env: dict[str, str] | None = None) -> tuple[int, str]:
    proc = start_node("shaper_nodes", "calibrate", params or {}, params_file=CONFIG, args=args, env=env)
    try:
        code = proc.proc.wait(timeout=timeout)
    finally:
        proc.stop()
    return code, proc.log_path.read_text()


def test_calibration_meets_modal_analysis(start_node, tmp_path, ros_context):
    """The default plan (9 poses, the suite's only calibration on the full grid): every mode within 2 % (frequency)
    and 20 % (damping) of modal analysis, the true frequency inside two sigma for 90 % of them, and the scheduler
    takes the scheduler.yaml written. (The recomputation from the recording alone, ``--from-bag``, is the same
    code on any plan: it is checked on the small plan's uninterrupted run below, 3 poses instead of 9.)"""
    sim(start_node)
    out = tmp_path / "cal"
    code, log = calibrate(start_node, ["--execute", "--out", str(out), *ONE_WORKER], {"compression": "zstd"})
    assert code == 0, log
    for bag in sorted((out / "recording").glob("pose_*/*.mcap")):  # compression: zstd, as the recorder's
        with open(bag, "rb") as f:
            assert {c.compression for c in make_reader(f).get_summary().chunk_indexes} == {"zstd"}, bag
    report = json.loads((out / "report.json").read_text())
    assert report["complete"] and len(report["poses"]) == 9
    model = ArmModel()
    rows = []
    for pose in report["poses"]:
        q = np.array(list(pose["positions"].values()))
        modal = [(m.hz, m.zeta) for m in modes(model, q)]
        truth = [(w / (2 * math.pi), z) for w, z in simulated_modes(model, q, 1.0 / (2 * RATE), 0.5)]
        assert pose["modes"], f"{pose['name']}: no mode"
        for m in pose["modes"]:
            f_m, z_m = min(modal, key=lambda x: abs(x[0] - m["frequency_hz"]))
            f_t, _ = min(truth, key=lambda x: abs(x[0] - m["frequency_hz"]))
            assert abs(m["frequency_hz"] / f_m - 1) <= 0.02, (pose["name"], m, f_m)
            assert abs(m["damping_ratio"] / z_m - 1) <= 0.20, (pose["name"], m, z_m)
            rows.append((pose["name"], abs(m["frequency_hz"] - f_t) <= 2 * m["frequency_hz_std"] + 5e-6))
    covered = sum(ok for _, ok in rows) / len(rows)
    assert covered >= 0.9, f"the true frequency is inside two sigma for {100 * covered:.0f} % of the modes"
    # the scheduler takes scheduler.yaml as written, and schedules the home pose's modes at home
    start_node("shaper_nodes", "scheduler", {}, params_file=out / "scheduler.yaml")
    node = rclpy.create_node("probe", context=ros_context)
    client = node.create_client(ShaperAt, "/scheduler/shaper_at")
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        answer = call_answered(executor, client, ShaperAt.Request(pose=JointState(
            name=list(report["plan"]["joint_names"]), position=HOME.tolist())), "the scheduler's shaper_at")
        assert answer.success, answer
        home = next(p for p in report["poses"] if p["name"] == "home")
        got = sorted(m.frequency_hz for m in answer.shaper.design_modes)
        assert got == pytest.approx(sorted(m["frequency_hz"] for m in home["modes"]), rel=1e-4)
    finally:
        # shut down before the context is: an executor left to the garbage collector after the fixture shut the
        # context down raised InvalidHandle in Executor.__del__, an error at some later test's teardown (session 15)
        executor.shutdown()
        node.destroy_node()


def test_a_calibration_killed_mid_run_resumes_to_the_uninterrupted_result(start_node, tmp_path, small_calibration):
    """Each run starts with a fresh simulator (noise-free, lockstep: deterministic), so the poses measured before
    the kill are the uninterrupted run's to the last bit; the poses measured after the resume start from wherever
    the killed run left the arm, and agree within their reported uncertainty. The uninterrupted run's recording
    alone (``--from-bag``, offline) gives its report to the last byte. The uninterrupted run is the session's
    shared one (tests/conftest.py's ``small_calibration``: the same plan, a plant as this test's, which also waits
    for calibrate; test_lockstep_readers.py pauses calibrate against it)."""
    whole, run = small_calibration
    assert run["returncode"] == 0, run["log"]
    again = tmp_path / "again"  # offline, from the recording alone: the same report
    code, log = calibrate(start_node, ["--from-bag", str(whole / "recording"), "--out", str(again), *ONE_WORKER])
    assert code == 0, log
    assert (again / "report.json").read_text() == (whole / "report.json").read_text()
    sim(start_node, noise=0.0)
    cut = tmp_path / "cut"
    proc = start_node("shaper_nodes", "calibrate", SMALL, params_file=CONFIG, args=["--execute", "--out", str(cut)])
    first = cut / "recording" / "pose_000"
    deadline = time.monotonic() + 300.0
    while not (first / "metadata.yaml").exists():  # killed once the first pose is complete, in the second
        assert proc.running() and time.monotonic() < deadline, proc.log_path.read_text()
        time.sleep(0.05)
    proc.proc.kill()  # kill -9
    proc.proc.wait()
    kept = {p.name: p.read_bytes() for p in first.iterdir()}
    assert not (cut / "report.json").exists()
    code, log = calibrate(start_node, ["--execute", "--resume", "--out", str(cut), *ONE_WORKER], SMALL,
                          env=RESTARTED)
    assert code == 0, log
    assert "resuming" in log
    assert {p.name: p.read_bytes() for p in first.iterdir()} == kept  # what was measured is not lost
    assert not list((cut / "recording").glob("*.partial"))
    for pose in sorted((cut / "recording").iterdir()):  # each complete pose's file named after its folder
        assert sorted(p.name for p in pose.iterdir()) == ["metadata.yaml", f"{pose.name}.mcap"], pose
        assert "partial" not in (pose / "metadata.yaml").read_text(), pose
    a = json.loads((whole / "report.json").read_text())
    b = json.loads((cut / "report.json").read_text())
    assert b["poses"][0] == a["poses"][0]  # measured before the kill: the same to the last digit
    assert [p["name"] for p in b["poses"]] == [p["name"] for p in a["poses"]]
    assert [p["flags"] for p in b["poses"]] == [p["flags"] for p in a["poses"]]
    for pa, pb in zip(a["poses"], b["poses"], strict=True):
        assert len(pa["modes"]) == len(pb["modes"]), (pa, pb)
        for ma, mb in zip(pa["modes"], pb["modes"], strict=True):
            df = 2 * max(ma["frequency_hz_std"], mb["frequency_hz_std"]) + 5e-4  # + half the printed digit
            dz = 2 * max(ma["damping_ratio_std"], mb["damping_ratio_std"]) + 5e-5
            assert abs(ma["frequency_hz"] - mb["frequency_hz"]) <= df, (pa["name"], ma, mb)
            assert abs(ma["damping_ratio"] - mb["damping_ratio"]) <= dz, (pa["name"], ma, mb)


def test_the_pose_pipeline_writes_the_sequential_runs_files_byte_for_byte(small_calibration, tmp_path):
    """``calibrate --execute`` with two workers identifies each pose as it completes and draws the figures in both
    workers at once (analysis/calibration_pool.py); on the session's one-worker run's recording it writes that
    run's files (the figures, scheduler.yaml, shaper.yaml, report.md and report.json) byte for byte."""
    from shaper_nodes.analysis.calibration import pose_folders, read_recording
    from shaper_nodes.analysis.calibration_pool import NICENESS, PosePipeline
    from shaper_nodes.analysis.worker_pool import worker_pool

    whole, run = small_calibration
    assert run["returncode"] == 0, run["log"]
    setup, _ = read_recording(whole / "recording")
    out = tmp_path / "pipeline"
    with worker_pool(2, NICENESS) as pool:
        pipeline = PosePipeline(pool, setup, 2)
        for folder in pose_folders(whole / "recording"):
            pipeline.submit(int(folder.name.removeprefix("pose_")), folder)
        _, written = pipeline.finish(out, *pipeline.results())
    names = [p.name for p in written]
    assert names == ["modes_vs_pose.png", "spectra.png", "residual.png", "scheduler.yaml", "shaper.yaml",
                     "report.md", "report.json"]
    for name in names:
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert sorted(p.name for p in out.iterdir()) == sorted(names)  # no temporary file left


def _flat(tree: dict, prefix: str = ""):
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from _flat(value, prefix + key + ".")
        else:
            yield prefix + key, value


def test_the_plan_only_starts_where_the_arm_is(start_node):
    """A plan printed without --execute times its first approach from the arm's joint states, not from home."""
    start = HOME.copy()
    start[0] = 1.0  # the base turned 1 rad away from home
    sim(start_node, **{"task.start": start.tolist()})
    code, log = calibrate(start_node, [], timeout=300.0)
    assert code == 0, log
    config = config_from_values(dict(_flat(yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"])), None)
    here, home = make_plan(config, start), make_plan(config)
    assert here.duration > home.duration + 1.0  # 1 rad more to travel first
    assert f"duration: {here.duration:.1f} s of robot time" in log, log
    assert "plan only" in log


def test_a_plan_outside_the_limits_is_refused_and_nothing_is_written(start_node, tmp_path):
    sim(start_node)
    out = tmp_path / "refused"
    upper = [2 * math.pi, 2 * math.pi, 2.0, 2 * math.pi, 2 * math.pi, 2 * math.pi]
    code, log = calibrate(start_node, ["--execute", "--out", str(out)], {"limits.upper": upper})
    assert code == 2, log
    assert "refused" in log and "elbow_joint +2.4000 > +2.0000" in log, log
    assert not out.exists()


def test_an_aborted_goal_stops_the_run_and_leaves_no_half_written_pose_or_report(start_node, tmp_path):
    sim(start_node, **{"jtc.trajectory_tolerance": [1e-6]})  # every move violates the path tolerance
    out = tmp_path / "aborted"
    code, log = calibrate(start_node, ["--execute", "--out", str(out)], SMALL)
    assert code == 1, log
    assert "aborted" in log and "error_code -4" in log, log
    assert not list((out / "recording").iterdir())  # no pose, no partial
    assert not (out / "report.json").exists() and not (out / "scheduler.yaml").exists()


def test_a_controller_killed_mid_goal_ends_calibrate_with_one_line_and_resume_completes(start_node, tmp_path):
    """The simulator (the controller) killed with -9 during the second pose: calibrate notices from the
    controller's silence (timeouts.peer, 10 s: the DDS lease alone takes 20 s), ends with one line and the
    aborted status, no traceback; with a new simulator, --resume completes the calibration."""
    from shaper_nodes.nodes.calibrate import EXIT_ABORTED

    plant = sim(start_node, noise=0.0)
    out = tmp_path / "cal"
    proc = start_node("shaper_nodes", "calibrate", SMALL, params_file=CONFIG, args=["--execute", "--out", str(out)])
    first = out / "recording" / "pose_000"
    deadline = time.monotonic() + 300.0
    while not (first / "metadata.yaml").exists():  # the first pose is complete: the second is under way
        assert proc.running() and time.monotonic() < deadline, proc.log_path.read_text()
        time.sleep(0.05)
    plant.proc.kill()  # kill -9: no goodbye on the graph
    killed = time.monotonic()
    code = proc.proc.wait(timeout=300.0)
    ended = time.monotonic() - killed
    log = proc.log_path.read_text()
    assert code == EXIT_ABORTED, log
    assert "Traceback" not in log, log
    last = [ln for ln in log.splitlines() if ln.startswith("calibrate: aborted:")]
    assert len(last) == 1 and ("no feedback from the controller" in last[0] or "left the graph" in last[0]), log
    print(f"calibrate ended {ended:.1f} s after the controller was killed: {last[0]}")
    sim(start_node, noise=0.0, env=RESTARTED)
    code, log = calibrate(start_node, ["--execute", "--resume", "--out", str(out), *ONE_WORKER], SMALL)
    assert code == 0, log
    assert "resuming" in log and (out / "report.json").exists()
