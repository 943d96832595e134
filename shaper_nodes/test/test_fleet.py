"""A small synthetic fleet through analyze_fleet on a real Dask LocalCluster (one worker).

The worker runs as a thread of the test process (``processes=False``): the same scheduler, client,
task submission and result transfer as with worker processes, without a process start-up per test.
"""

from __future__ import annotations

import csv
import json
import pathlib

import pytest

from shaper_nodes.analysis.analyze import Options
from shaper_nodes.analysis.fleet import Cache, FleetError, content_key, find_recordings, robot_of, run_fleet
from shaper_nodes.analysis.fleet_drift import DriftRule, fleet_drift
from shaper_nodes.analysis.fleet_report import write_fleet_report
from shaper_nodes.analysis.synthetic import simulate, write_bag, write_fleet

OPTIONS = Options(learners=())
RULE = DriftRule(baseline=3, confirm=2)


@pytest.fixture
def fleet(tmp_path):
    root = tmp_path / "fleet"
    truth = write_fleet(root, robots=3, recordings=6, drifting=(1,), shift=0.10, drift_at=0.5, seed=3)
    return root, truth


def test_fleet_on_dask_flags_the_drifting_robot_caches_and_reports(fleet, tmp_path):
    root, truth = fleet
    paths = find_recordings(root)
    assert len(paths) == 18
    cache = Cache(tmp_path / "cache")

    first = run_fleet(paths, OPTIONS, cache, workers=1, processes=False)
    assert first.where.startswith("local Dask cluster")
    assert (first.analysed, first.cached) == (18, 0)
    assert not [r.error for r in first.results if r.error]
    for r in first.results:  # robot from the recording's metadata; the true mode found
        assert r.robot == pathlib.Path(r.path).parent.name
        hz = truth.modes_hz[r.robot] * (1 + truth.shift if r.robot in truth.drift_from
                                        and int(r.path[-3:]) >= truth.drift_from[r.robot] else 1)
        assert r.modes and r.modes[0]["frequency_hz"] == pytest.approx(hz, rel=0.03)

    drift = {d.robot: d for d in fleet_drift(first.results, RULE)}
    assert [name for name, d in drift.items() if d.alerts] == ["robot_01"]
    alert = drift["robot_01"].alerts[0]
    assert alert.shift == pytest.approx(truth.shift, abs=0.03)
    assert alert.retune is not None and alert.retune["designed_hz"] == pytest.approx(alert.frequency_hz)

    # a rerun analyses nothing: every result comes from the cache, the same
    again = run_fleet(paths, OPTIONS, cache, workers=1, processes=False)
    assert (again.analysed, again.cached) == (0, 18)
    assert [r.modes for r in again.results] == [r.modes for r in first.results]

    # a changed recording is analysed again, and only it
    changed = truth.paths["robot_02"][1]
    t, u, a, _ = simulate(cycles=3, rate=250.0, mode_hz=4.2, zeta=0.03, dwell=1.5, noise=0.02, offset=(0, 0, 9.81))
    for f in changed.iterdir():
        f.unlink()
    changed.rmdir()
    write_bag(changed, t, u, a, t0=1.7e9 + 86400.0 + 1200.0, custom_data={"robot": "robot_02"})
    third = run_fleet(paths, OPTIONS, cache, workers=1, processes=False)
    assert (third.analysed, third.cached) == (1, 17)
    redone = next(r for r in third.results if r.path == str(changed))
    assert redone.modes[0]["frequency_hz"] == pytest.approx(4.2, rel=0.03)

    # the report: files exist, the CSV and JSON hold the modes
    out = tmp_path / "report"
    files = write_fleet_report(first, list(drift.values()), RULE, out)
    assert all(f.is_file() and f.stat().st_size > 0 for f in files)
    with (out / "recordings.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len({r["path"] for r in rows}) == 18
    first_modes = {r.path: r.modes[0]["frequency_hz"] for r in first.results}
    for row in rows:
        if row["mode"] == "1":
            assert float(row["frequency_hz"]) == pytest.approx(first_modes[row["path"]], rel=1e-5)
    doc = json.loads((out / "fleet.json").read_text())
    robots = {r["robot"]: r for r in doc["robots"]}
    assert [a["robot"] for r in doc["robots"] for a in r["alerts"]] == ["robot_01"]
    assert sum(len(r["recordings"]) for r in robots.values()) == 18
    assert all(rec["modes"] for r in robots.values() for rec in r["recordings"])
    assert "robot_01" in (out / "alerts.csv").read_text()


def test_unreadable_recording_is_reported_not_fatal(tmp_path):
    bad = tmp_path / "cell_9" / "broken"
    bad.mkdir(parents=True)
    (bad / "broken_0.mcap").write_bytes(b"not an mcap file")
    run = run_fleet(find_recordings(tmp_path), OPTIONS, None, workers=0)
    assert len(run.results) == 1 and run.results[0].error and run.results[0].robot == "cell_9"


def test_robot_from_metadata_else_folder_and_refusals(tmp_path):
    t, u, a, _ = simulate(cycles=2, rate=250.0, dwell=1.0)
    write_bag(tmp_path / "day_1" / "rec_a", t, u, a, custom_data={"robot": "arm_7"})
    write_bag(tmp_path / "day_1" / "rec_b", t, u, a)
    assert robot_of(tmp_path / "day_1" / "rec_a") == "arm_7"
    assert robot_of(tmp_path / "day_1" / "rec_b") == "day_1"
    assert content_key(tmp_path / "day_1" / "rec_a", OPTIONS) != content_key(tmp_path / "day_1" / "rec_b", OPTIONS)
    assert content_key(tmp_path / "day_1" / "rec_b", OPTIONS) != content_key(tmp_path / "day_1" / "rec_b",
                                                                            Options(learners=(), max_modes=1))
    # a recording directly in the fleet's folder has no robot folder: it is a robot of its own (bags/ holds the
    # 1-D demo and the arm's production run side by side: not one robot), unless its metadata names one
    write_bag(tmp_path / "loose_run", t, u, a)
    assert robot_of(tmp_path / "loose_run", root=tmp_path) == "loose_run"
    assert robot_of(tmp_path / "day_1" / "rec_b", root=tmp_path) == "day_1"
    assert robot_of(tmp_path / "day_1" / "rec_a", root=tmp_path / "day_1") == "arm_7"
    assert robot_of(tmp_path / "day_1" / "rec_b", root=tmp_path / "day_1") == "rec_b"
    with pytest.raises(FleetError, match="more than 1 recordings"):
        find_recordings(tmp_path, limit=1)
    with pytest.raises(FleetError, match="missing: no such folder"):
        find_recordings(tmp_path / "missing")
    # the owner's mistakes of session 15's walk: one recording's .mcap given for the fleet's folder
    bare = next((tmp_path / "loose_run").glob("*.mcap"))
    with pytest.raises(FleetError, match="not a folder; it is one recording: analyze_bag analyses one recording"):
        find_recordings(bare)
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(FleetError, match=r"notes.txt: not a folder$"):
        find_recordings(tmp_path / "notes.txt")


def test_analyze_bag_names_analyze_fleet_for_a_folder_of_recordings(tmp_path, capsys):
    from shaper_nodes.cli import analyze_bag

    t, u, a, _ = simulate(cycles=2, rate=250.0, dwell=1.0)
    for name in ("rec_a", "rec_b"):
        write_bag(tmp_path / "cell_1" / name, t, u, a)
    assert analyze_bag.main([str(tmp_path), "--no-progress"]) == 2
    assert "analyze_fleet" in capsys.readouterr().err


def _comparable(doc: dict) -> dict:
    """A fleet report without what depends on where and how fast it ran."""
    doc = {k: v for k, v in doc.items() if k not in ("seconds", "where")}
    doc["robots"] = [{**r, "recordings": [{k: v for k, v in rec.items() if k != "seconds"}
                                          for rec in r["recordings"]]} for r in doc["robots"]]
    return doc


def test_analyze_fleet_on_an_existing_dask_cluster_gives_the_local_clusters_report(tmp_path, capsys):
    """A Dask scheduler and a worker started by dask's own command line, as processes of their own (an
    existing cluster); ``analyze_fleet --scheduler ADDRESS`` on it gives the report a local cluster gives."""
    import os
    import subprocess
    import sys
    import time

    from distributed import Client

    from shaper_nodes.analysis.fleet import SINGLE_THREAD
    from shaper_nodes.analysis.fleet_report import fleet_doc
    from shaper_nodes.cli import analyze_fleet

    root = tmp_path / "fleet"
    write_fleet(root, robots=2, recordings=3, drifting=(1,), shift=0.10, drift_at=0.5, cycles=2, seed=5)
    rule = DriftRule(baseline=2, confirm=1)
    local = run_fleet(find_recordings(root), OPTIONS, None, workers=1, processes=False)
    expected = fleet_doc(local, fleet_drift(local.results, rule), rule)

    address_file = tmp_path / "scheduler.json"
    env = {**os.environ, **SINGLE_THREAD}
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(address_file)],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60.0
        address = ""
        while not address:  # polled: the file is the scheduler's only sign; read once it is whole JSON
            assert procs[0].poll() is None, "the dask scheduler exited"
            assert time.monotonic() < deadline, "the dask scheduler wrote no address within 60 s"
            try:
                address = json.loads(address_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads",
                                       "1", "--nworkers", "1", "--no-nanny", "--no-dashboard"],
                                      env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout=60) as client:
            client.wait_for_workers(1, timeout=60)
            (worker_pid,) = client.run(os.getpid).values()
        assert worker_pid == procs[1].pid  # the analysis runs in the worker process, not here

        code = analyze_fleet.main([str(root), "--scheduler", address, "--json", "--no-cache", "--quiet",
                                   "--baseline", "2", "--confirm", "1"])
        out, err = capsys.readouterr()
        assert code == 0 and "WARNING" not in err
        got = json.loads(out)
        assert got["where"] == f"Dask scheduler {address}"
        assert (got["recordings"], got["analysed"], got["failed"]) == (6, 6, [])
        assert _comparable(got) == _comparable(json.loads(json.dumps(expected)))
        assert [a["robot"] for r in got["robots"] for a in r["alerts"]] == ["robot_01"]
    finally:
        for proc in reversed(procs):
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _oversized_metadata(folder: pathlib.Path, size: int) -> None:
    """A recording folder with a real MCAP file and a metadata.yaml of ``size`` bytes (sparse: made at once)."""
    t, u, a, _ = simulate(cycles=2, rate=250.0, dwell=1.0)
    write_bag(folder, t, u, a, custom_data={"robot": "arm_7"})
    with open(folder / "metadata.yaml", "r+b") as f:
        f.truncate(size)


def test_analyze_fleet_refuses_an_oversized_metadata_yaml_as_analyze_bag_does(tmp_path, capsys):
    """The same reader entry point and bounds: a metadata.yaml beyond the limit is not parsed by analyze_fleet
    (not for the robot's name either) and is refused with analyze_bag's message."""
    from shaper_nodes.cli import analyze_bag, analyze_fleet
    from shaper_nodes.recordings import ReadLimits

    folder = tmp_path / "cell_4" / "huge"
    _oversized_metadata(folder, 3 * 2**20)  # 3 MiB, beyond a 2 MiB limit
    assert analyze_bag.main([str(folder), "--no-progress", "--max-metadata-mib", "2"]) == 2
    bag_err = capsys.readouterr().err.splitlines()[0]
    assert bag_err.startswith("analyze_bag: ") and "metadata.yaml is 3.0 MiB, beyond the limit of 2.0 MiB" in bag_err
    message = bag_err.removeprefix("analyze_bag: ")

    assert analyze_fleet.main([str(tmp_path), "--workers", "0", "--no-cache", "--quiet",
                               "--max-metadata-mib", "2"]) == 0
    out = capsys.readouterr()
    assert f"{folder}: not analysed: BagError: {message}" in out.err
    run = run_fleet([folder], OPTIONS, None, workers=0, limits=ReadLimits(metadata_bytes=2 * 2**20))
    (res,) = run.results
    assert res.error == f"BagError: {message}"
    assert res.robot == "cell_4"  # the oversized metadata.yaml was not parsed for the robot's name
    assert robot_of(folder, ReadLimits(metadata_bytes=2 * 2**20)) == "cell_4"
    # the key depends on the limits (a refused recording is read again under others), not for the defaults
    assert content_key(folder, OPTIONS, ReadLimits(metadata_bytes=2 * 2**20)) != content_key(folder, OPTIONS)
    assert content_key(folder, OPTIONS, ReadLimits()) == content_key(folder, OPTIONS)


def test_analyze_fleet_refuses_a_metadata_yaml_just_over_the_default_bound(tmp_path):
    """The default bound (16 MiB) holds in analyze_fleet as in analyze_bag, on a file one byte over it."""
    from shaper_nodes.analysis.streams import read_recording
    from shaper_nodes.recordings import BagError, ReadLimits

    folder = tmp_path / "cell_5" / "over"
    _oversized_metadata(folder, ReadLimits().metadata_bytes + 1)
    with pytest.raises(BagError) as refused:
        read_recording(folder)
    (res,) = run_fleet(find_recordings(tmp_path), OPTIONS, None, workers=0).results
    assert res.error == f"BagError: {refused.value}" and "beyond the limit of 16 MiB" in res.error
    assert res.robot == "cell_5"


def test_loose_recordings_are_robots_of_their_own_and_a_moved_recording_changes_robot(tmp_path):
    t, u, a, _ = simulate(cycles=2, rate=250.0, dwell=1.0)
    for name in ("one_arm", "other_arm"):
        write_bag(tmp_path / name, t, u, a)
    cache = Cache(tmp_path / ".fleet_cache")
    run = run_fleet(find_recordings(tmp_path), OPTIONS, cache, workers=0, root=tmp_path)
    assert sorted(r.robot for r in run.results) == ["one_arm", "other_arm"]
    assert run.analysed == 2
    (tmp_path / "cell_4").mkdir()
    (tmp_path / "one_arm").rename(tmp_path / "cell_4" / "one_arm")  # same bytes, cached: the folder decides
    run = run_fleet(find_recordings(tmp_path), OPTIONS, cache, workers=0, root=tmp_path)
    assert run.cached == 2 and sorted(r.robot for r in run.results) == ["cell_4", "other_arm"]
