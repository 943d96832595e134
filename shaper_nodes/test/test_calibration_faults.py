"""Calibrate's stops and sensor faults without ROS: a dead accelerometer at a pose is a sensor fault (never an
OK pose, never in the rule base), the analysis' workers end with the process that started them (kill -9
included), a params file too large is refused before it is parsed, SIGTERM stops like Ctrl-C, and a failed
write is named in one line.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from test_calibration import SMALL, default_config, recorded

from shaper_nodes.analysis.calibration import (
    END,
    START,
    PoseData,
    compute,
    pose_sensor_fault,
    setup_dict,
)
from shaper_nodes.analysis.calibration_outputs import report_dict, sensor_faults
from shaper_nodes.core.calibration import IdentifySettings
from shaper_nodes.core.calibration.plan import make_plan
from shaper_nodes.nodes.calibrate_stops import (
    EXIT_CANCELLED,
    EXIT_TERMINATED,
    MAX_PARAMS_FILE_BYTES,
    Stopped,
    WriteFailed,
    params_file_too_large,
    stop_on_signals,
)


def one_pose(values) -> PoseData:
    """One excitation from t = 10 s to 12 s, the accelerometer ``values`` ((n, 3)) spread over it."""
    y = np.asarray(values, dtype=float).reshape(-1, 3)
    data = PoseData(0, events=[(START, 0, 10.0), (1, 0, 11.0), (END, 0, 12.0)])
    data.imu_t = list(np.linspace(10.0, 12.0, y.shape[0]))
    data.imu = [tuple(v) for v in y]
    return data


@pytest.mark.parametrize(("values", "words"), [
    (np.zeros((1000, 3)), "every accelerometer axis read one value"),
    (np.full((1000, 3), 3.0), "[3, 3, 3]"),
    (np.r_[np.full((999, 3), 3.0), [[170.0, 0.0, 0.0]]], "at or beyond the sensor's range of 160"),
    (np.zeros((0, 3)), "0 accelerometer samples"),
    (np.r_[np.random.default_rng(1).normal(size=(999, 3)), [[np.nan, 0.0, 0.0]]], "non-finite"),
])
def test_a_flat_stuck_saturated_silent_or_nan_accelerometer_is_a_sensor_fault(values, words):
    why = pose_sensor_fault(one_pose(values))
    assert why is not None and why.startswith("excitation 1: ") and words in why, why


def test_a_working_accelerometer_is_not_a_fault():
    assert pose_sensor_fault(one_pose(np.random.default_rng(0).normal(0.0, 1e-3, (1000, 3)))) is None


@pytest.mark.parametrize("workers", [1, 2])
def test_a_pose_with_a_dead_accelerometer_is_flagged_and_never_ok_nor_used(workers):
    plan = make_plan(default_config(**SMALL))
    setup = json.loads(json.dumps(setup_dict(plan, IdentifySettings(max_modes=2), "zv", 0.02)))
    poses = recorded(plan)
    poses[1].imu = [(3.0, 3.0, 3.0)] * len(poses[1].imu)  # grid 0: stuck at 3.0 m/s^2 throughout
    cal = compute(setup, poses, workers=workers)
    home, stuck, other = cal.results
    assert home.ok and other.ok and not home.flags and not other.flags
    assert not stuck.ok and stuck.modes == [] and len(stuck.flags) == 1
    assert stuck.flags[0].startswith("sensor_fault: excitation 1: every accelerometer axis read one value")
    report = report_dict(cal)
    row = report["poses"][1]
    assert row["ok"] is False and row["sensor_fault"].startswith("excitation 1: every accelerometer axis")
    assert report["poses"][0]["sensor_fault"] is None and stuck.name in report["flagged_poses"]
    assert sensor_faults(cal) == [(stuck.index, stuck.name, row["sensor_fault"])]  # what calibrate publishes
    # its place in the rule base holds its neighbour's measured modes, said so, never its own (it has none)
    assert cal.rule_base is not None
    assert any(n.startswith(f"{stuck.name}: mode(s)") and "taken from" in n for n in cal.notes), cal.notes


def test_a_params_file_larger_than_the_limit_is_refused_before_it_is_read(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * (MAX_PARAMS_FILE_BYTES + 1))
    small = tmp_path / "small.yaml"
    small.write_text("/**:\n  ros__parameters: {}\n")
    problem = params_file_too_large([str(small), str(big)])
    assert problem is not None and problem.startswith(f"--params-file {big}: 1.0 MB, more than calibrate reads")
    assert params_file_too_large([str(small), str(tmp_path / "missing.yaml")]) is None


def test_sigterm_and_sigint_raise_stopped_once_with_the_shells_status():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        stop_on_signals()
        with pytest.raises(Stopped) as stop:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5.0)  # the handler runs at once; the sleep is never finished
        assert stop.value.status == EXIT_TERMINATED == 143 and str(stop.value) == "SIGTERM"
        assert isinstance(stop.value, KeyboardInterrupt)
        os.kill(os.getpid(), signal.SIGINT)  # a second signal does not interrupt the stop
        assert EXIT_CANCELLED == 130
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def test_a_failed_write_names_the_file_and_the_reason(tmp_path):
    err = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    text = str(WriteFailed(err, tmp_path / "pose_001.partial" / "pose_001.partial.mcap"))
    assert text == f"cannot write {tmp_path}/pose_001.partial/pose_001.partial.mcap: No space left on device (ENOSPC)"


POOL = textwrap.dedent("""
    import sys, time
    from shaper_nodes.analysis.calibration import worker_pool
    with worker_pool(2) as pool:
        futures = [pool.submit(time.sleep, 600.0) for _ in range(2)]
        print(" ".join(str(p) for p in pool._processes), flush=True)
        futures[0].result()
""")


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie (a re-parented worker's zombie waits for a reaper)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_pool_left_by_an_exception_has_wound_down_when_the_with_ends():
    """calibrate's abort leaves the pool by an exception with its workers identifying (or warming up): the
    workers are ended and the pool's manager thread has wound down (its wake-up pipe closed) when the ``with``
    ends, so the interpreter's exit does not wake it while it closes that pipe (an EBADF traceback at exit)."""
    from shaper_nodes.analysis.worker_pool import worker_pool

    with pytest.raises(RuntimeError, match="abort"), worker_pool(2) as pool:
        futures = [pool.submit(time.sleep, 600.0) for _ in range(2)]
        manager, processes = pool._executor_manager_thread, list(pool._processes.values())
        raise RuntimeError("abort")
    assert manager is not None and not manager.is_alive()
    assert all(not p.is_alive() for p in processes)
    assert all(f.cancelled() or f.done() for f in futures)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_kill_9_of_the_analysis_leaves_no_worker_alive():
    """The analysis' pool (as calibrate and --from-bag run it) killed with -9 while its two workers
    identify: the workers end too (before: they were alive 28 minutes later)."""
    with subprocess.Popen([sys.executable, "-c", POOL], stdout=subprocess.PIPE, text=True) as proc:
        try:
            assert proc.stdout is not None
            pids = [int(p) for p in proc.stdout.readline().split()]
            assert len(pids) == 2 and all(_alive(p) for p in pids)
            proc.kill()
            proc.wait()
            deadline = time.monotonic() + 60.0  # generous: the kernel signals them as the parent ends
            while any(_alive(p) for p in pids) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not any(_alive(p) for p in pids), [p for p in pids if _alive(p)]
        finally:
            proc.kill()


def test_from_bag_names_what_the_folder_is_when_it_holds_no_pose(tmp_path):
    """The owner's mistakes of session 15's walk: a wrong path, the output folder instead of its
    recording/, and one recording of another kind (a rosbag2 folder, a bare .mcap) each get their own
    words, not "holds no completed pose"."""
    from shaper_nodes.analysis.calibration import read_recording
    from shaper_nodes.core.calibration.plan import PlanError

    with pytest.raises(PlanError, match="no such folder; --from-bag takes a calibration's recording folder"):
        read_recording(tmp_path / "cal" / "recordin")
    pose = tmp_path / "cal" / "recording" / "pose_000"
    pose.mkdir(parents=True)
    (pose / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    with pytest.raises(PlanError, match=r"holds no completed pose; its recording/ does: --from-bag .*cal/recording"):
        read_recording(tmp_path / "cal")
    with pytest.raises(PlanError, match="is a single recording, not a calibration's recording folder"):
        read_recording(pose)
    (tmp_path / "bare.mcap").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(PlanError, match="is a single recording"):
        read_recording(tmp_path / "bare.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(PlanError, match=r"holds no completed pose \(pose_NNN bags with metadata.yaml\)"):
        read_recording(tmp_path / "empty")
