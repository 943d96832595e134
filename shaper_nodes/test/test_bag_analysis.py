"""Bag analysis on recordings written by another writer (rosbags directly, standard types only,
no cycle events), damaged recordings, and bad input."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from shaper_nodes.analysis.analyze import Options, analyze
from shaper_nodes.analysis.groups import group_cycles
from shaper_nodes.analysis.report import summary as bag_summary
from shaper_nodes.analysis.report import table as bag_analysis_cli_table
from shaper_nodes.analysis.streams import read_recording
from shaper_nodes.analysis.synthetic import check_segmentation, simulate, simulate_plants, write_bag
from shaper_nodes.cli import analyze_bag as bag_analysis_cli
from shaper_nodes.core.identification import NO_SHAPER_NEEDED, ModeFit
from shaper_nodes.core.shaping.vibration import percentage_vibration, residual_vibration
from shaper_nodes.recordings import Bag, BagError, mcap_chunks
from shaper_nodes.recordings.cdr import (
    JointStateDecoder,
    imu_fast,
    joint_state_efforts,
    joint_state_fast,
    joint_state_motion,
)

STORE = get_typestore(Stores.ROS2_JAZZY)
MODE_HZ, ZETA = 4.0, 0.02
GRAVITY = (0.0, 0.0, 9.81)


@pytest.fixture(scope="module")
def robot_bag(tmp_path_factory):
    """Six back-and-forth moves, IMU with gravity and noise, joint states; no commands, no events."""
    t, u, a, truth = simulate(cycles=6, mode_hz=MODE_HZ, zeta=ZETA, offset=GRAVITY)
    path = tmp_path_factory.mktemp("bags") / "robot"
    write_bag(path, t, u, a, joint_names=("shoulder", "elbow"))
    return path, t, u, a, truth


def test_fast_decoders_agree_with_rosbags():
    Header, Time = STORE.types["std_msgs/msg/Header"], STORE.types["builtin_interfaces/msg/Time"]
    Vec, Quat = STORE.types["geometry_msgs/msg/Vector3"], STORE.types["geometry_msgs/msg/Quaternion"]
    rng = np.random.default_rng(3)
    for frame in ("", "a", "imu_link", "x" * 13):
        imu = STORE.types["sensor_msgs/msg/Imu"](
            header=Header(stamp=Time(sec=1700000000, nanosec=123456789), frame_id=frame),
            orientation=Quat(x=0.1, y=0.2, z=0.3, w=0.9), orientation_covariance=rng.normal(size=9),
            angular_velocity=Vec(x=1.0, y=2.0, z=3.0), angular_velocity_covariance=rng.normal(size=9),
            linear_acceleration=Vec(x=-1.5, y=2.25, z=9.81), linear_acceleration_covariance=rng.normal(size=9))
        t, acc = imu_fast(STORE.serialize_cdr(imu, "sensor_msgs/msg/Imu"))
        assert t == pytest.approx(1700000000.123456789, abs=1e-6)
        assert acc == (-1.5, 2.25, 9.81)
        for names in ((), ("j1",), ("joint_a", "b", "joint_long_name_c")):
            pos = rng.normal(size=len(names))
            js = STORE.types["sensor_msgs/msg/JointState"](
                header=Header(stamp=Time(sec=5, nanosec=7), frame_id=frame), name=list(names), position=pos,
                velocity=rng.normal(size=len(names)), effort=np.zeros(0))
            raw = STORE.serialize_cdr(js, "sensor_msgs/msg/JointState")
            t, got_names, got = joint_state_fast(raw)
            assert t == pytest.approx(5.000000007, abs=1e-12)
            assert got_names == names and np.array_equal(got, pos)
            decoder = JointStateDecoder()
            assert decoder(raw) == (t, got_names, got) and decoder(raw) == (t, got_names, got)  # cached layout
            # the velocities and efforts behind the positions, each present or empty
            for vel, eff in ((js.velocity, np.zeros(0)), (np.zeros(0), rng.normal(size=len(names))),
                             (rng.normal(size=len(names)), rng.normal(size=len(names)))):
                js.velocity, js.effort = vel, eff
                raw = STORE.serialize_cdr(js, "sensor_msgs/msg/JointState")
                decoder(raw)
                assert joint_state_motion(raw, decoder.positions_end) == (tuple(vel), tuple(eff))
                assert joint_state_efforts(raw, decoder.positions_end) == tuple(eff)


def test_synthetic_writer_patches_what_rosbags_reads(robot_bag):
    path, t, u, a, _ = robot_bag
    with Bag(path) as bag:
        imu = bag.deserializer("sensor_msgs/msg/Imu")
        js = bag.deserializer("sensor_msgs/msg/JointState")
        got_imu, got_js = [], []
        for topic, _, _, raw in bag.messages(["/imu/data", "/joint_states"]):
            (got_imu if topic == "/imu/data" else got_js).append(raw)
            if len(got_imu) > 300 and len(got_js) > 300:
                break
    m = imu(got_imu[300])
    assert (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) == tuple(a[300])
    assert m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec == pytest.approx(1.7e9 + t[300], abs=1e-6)
    j = js(got_js[300])
    assert list(j.name) == ["shoulder", "elbow"] and np.array_equal(j.position, [u[300], u[300]])


def test_a_robot_recording_without_events_is_segmented_from_the_motion(robot_bag):
    path, t, _u, a, truth = robot_bag
    rec = read_recording(path)
    assert rec.topics["accel"] == "/imu/data" and rec.topics["events"] == "" and rec.topics["commands"] == ""
    an = analyze(rec, Options(learners=()))
    assert an.segmentation.startswith("motion end of the joint states")
    assert len(an.cycles) == len(truth.move_starts)
    rate = 1.0 / (t[1] - t[0])
    for row, start, end in zip(an.cycles, truth.move_starts, truth.move_ends, strict=True):
        assert abs(row.start - 1.7e9 - start) <= 1.5 / rate
        assert abs(row.motion_end - 1.7e9 - end) <= 1.5 / rate
    # the offset (gravity) is found and removed; the residual matches an independent computation
    assert an.removed_mean
    for k, row in enumerate(an.cycles[:-1]):
        ref = residual_vibration(t, a, truth.move_ends[k], truth.move_starts[k + 1], remove_mean=True)
        assert row.rms == pytest.approx(ref.rms, rel=0.01)
    assert an.modes, an.notes
    assert an.modes[0].hz == pytest.approx(MODE_HZ, rel=0.02)
    assert an.modes[0].zeta == pytest.approx(ZETA, rel=0.2)
    assert an.recommendation is not None and an.recommendation.best is not None
    # unshaped cycles: the predicted residual of the recommendation is V times the measured level
    assert an.predicted["rms_nominal"] == pytest.approx(
        an.recommendation.best.nominal_vibration * float(np.median([r.rms for r in an.cycles])), rel=1e-9)


def test_commands_are_used_for_segmentation_when_recorded(tmp_path):
    t, u, a, truth = simulate(cycles=4, mode_hz=7.0, zeta=0.03, rate=400.0, dwell=2.0)
    write_bag(tmp_path / "bag", t, u, a, imu_topic="/sensors/accel", joints_topic="/arm/joint_states",
              commands_topic="/forward_position_controller/commands", joints_every=4)
    an = analyze(read_recording(tmp_path / "bag"), Options(learners=()))
    assert an.segmentation == "motion end of the commands (/forward_position_controller/commands)"
    assert [round(r.start - 1.7e9, 2) for r in an.cycles] == [round(s, 2) for s in truth.move_starts]
    assert an.modes[0].hz == pytest.approx(7.0, rel=0.02)


def test_cut_mid_chunk_is_analysed_up_to_the_cut_with_what_was_lost(robot_bag, tmp_path):
    path = robot_bag[0]
    full = analyze(read_recording(path), Options(learners=()))
    mcap = next(path.glob("*.mcap"))
    data = mcap.read_bytes()
    second = mcap_chunks(data)[1]
    cut = second[0] + 4000  # 4000 bytes into the second chunk
    (tmp_path / "cut.mcap").write_bytes(data[:cut])
    rec = read_recording(tmp_path / "cut.mcap")
    (dmg,) = rec.damage
    assert dmg.reason.startswith("cut inside a chunk record")
    assert dmg.readable == second[0] and dmg.lost_bytes == cut - second[0]
    assert dmg.lost_time is not None and dmg.lost_time[0] > 0
    an = analyze(rec, Options(learners=()))
    # every cycle that ended before the lost data is exactly as in the whole recording
    before = [r for r in an.cycles if r.end * 1e9 < dmg.lost_time[0] and r.complete]
    assert before
    for r in before:
        same = next(f for f in full.cycles if f.start == r.start)
        assert r.rms == same.rms and r.peak == same.peak
    text = bag_analysis_cli_output([str(tmp_path / "cut.mcap"), "--learners", ""])
    assert "WARNING" in text and "lost" in text and "bytes" in text


def test_a_corrupt_record_skips_its_chunk_and_reading_goes_on(robot_bag, tmp_path):
    path = robot_bag[0]
    data = bytearray(next(path.glob("*.mcap")).read_bytes())
    start, _length = mcap_chunks(bytes(data))[1]
    records = start + 9 + 8 + 8 + 8 + 4 + 4 + 8  # chunk header with no compression name
    struct.pack_into("<Q", data, records + 1, 10**12)  # the chunk's first record claims 1 TB
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    rec = read_recording(tmp_path / "bad.mcap")
    assert rec.damage and rec.damage[0].skipped_chunks
    assert any("read again record by record" in n for n in rec.notes)
    an = analyze(rec, Options(learners=()))
    assert any("gap in the accelerometer data" in r.issue for r in an.cycles)
    assert an.modes[0].hz == pytest.approx(MODE_HZ, rel=0.02)


def test_unknown_types_are_noted_and_empty_or_wrong_bags_are_refused(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("float64 level\nstring label", "acme_msgs/msg/Gauge"))
    t, u, a, _ = simulate(cycles=3)
    write_bag(tmp_path / "ok", t, u, a)
    # a bag with only an unknown type and a string topic: no accelerometer
    with Writer(tmp_path / "wrong", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/gauge", "acme_msgs/msg/Gauge", typestore=store)
        s = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        w.write(c, 1, store.serialize_cdr(store.types["acme_msgs/msg/Gauge"](level=1.0, label="x"),
                                          "acme_msgs/msg/Gauge"))
        w.write(s, 2, store.serialize_cdr(store.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"))
    with pytest.raises(BagError, match=r"no accelerometer topic.*/gauge \[acme_msgs/msg/Gauge\]"):
        read_recording(tmp_path / "wrong")
    with Writer(tmp_path / "empty", version=9, storage_plugin=StoragePlugin.MCAP):
        pass
    with pytest.raises(BagError, match="no topics"):
        read_recording(tmp_path / "empty")
    with pytest.raises(BagError, match="no recording"):
        read_recording(tmp_path / "missing")
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    with pytest.raises(BagError, match=r"not an MCAP file"):
        read_recording(tmp_path / "junk.mcap")
    with pytest.raises(BagError, match="--accel-topic /nope"):
        read_recording(tmp_path / "ok", {"accel": "/nope"})
    assert bag_analysis_cli.main([str(tmp_path / "wrong"), "--no-progress"]) == 2


def test_cli_writes_the_report_folder_and_json(robot_bag, tmp_path, capsys):
    path = robot_bag[0]
    out = tmp_path / "report"
    assert bag_analysis_cli.main([str(path), "--out", str(out), "--json", "--param", "list.highpass_hz=0.5"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["cycles"]) == 6 and doc["modes"][0]["frequency_hz"] == pytest.approx(MODE_HZ, rel=0.02)
    assert doc["recommendation"]["family"] and doc["replays"]["list"]["rows"][0]["action"] == "reference"
    for name in ("report.md", "cycles.csv", "modes.csv", "candidates.csv", "replay_list.csv", "summary.json",
                 "traces.png", "spectrum.png", "sensitivity.png"):
        assert (out / name).stat().st_size > 0, name
    # the recording ran unshaped: LIST takes its first cycle as the reference and learns from no other, so
    # there is no learning curve, and the report says why
    learned = [r for r in doc["replays"]["list"]["rows"] if "skipped" not in r]
    assert len(learned) < 2 and not (out / "learning.png").exists()
    assert f"the LIST replay made {len(learned)} update(s): a learning curve needs two or more" in (
        out / "report.md").read_text()
    assert json.loads((out / "summary.json").read_text()) == doc
    assert "| # | cycle | RMS" in (out / "report.md").read_text()


# ------------------------------------------------------------------------------ helpers
def bag_analysis_cli_output(argv: list[str]) -> str:
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = bag_analysis_cli.main([*argv, "--no-progress"])
    assert code == 0, err.getvalue()
    return out.getvalue() + err.getvalue()


def test_settling_time_into_a_band():
    from shaper_nodes.core.shaping.vibration import settling_time

    t = np.arange(0, 5, 0.001)
    a = np.exp(-t) * np.sin(2 * math.pi * 5 * t)
    st = settling_time(t, a, 0.0, 5.0, 0.1)
    assert st == pytest.approx(math.log(10), abs=0.06)  # envelope e^-t reaches 0.1 at ln 10
    assert math.isnan(settling_time(t, a, 0.0, 1.0, 0.1))  # still outside at the window's end
    assert settling_time(t, 0.01 * a, 0.0, 5.0, 0.1) == 0.0
    with pytest.raises(ValueError, match="band"):
        settling_time(t, a, 0.0, 5.0, -1.0)


def test_monitor_takes_no_sample_stamped_before_the_start():
    """The identifier's monitor takes samples as they arrive; one stamped before START that arrives after it
    (a preroll's ringing, handled after START by a node a few samples behind) is not the cycle's: it would
    refuse the cycle as saturated (the LIST case3 flake, the same in the learner's session)."""
    from shaper_nodes.core.cycles import END, MOTION_END, START, CycleMonitor

    t = np.arange(0, 600) / 200.0
    a = np.where(t > 1.0, np.exp(-(t - 1.0)) * np.sin(30 * (t - 1.0)), 0.0)
    results = []
    for late in (0, 3):
        mon = CycleMonitor()
        mon.event(START, 0, 0.0)
        for k in range(late):  # stamped before START, arriving after it
            mon.add_accel(-(late - k) / 200.0, [5000.0, 0.0, 0.0])
            mon.add_positions(-(late - k) / 200.0, [-1.0])
        for ti, ai in zip(t, a, strict=True):
            mon.add_accel(ti, [ai, 0.0, 0.0])
            mon.add_positions(ti, [min(ti, 1.0)])
        mon.event(MOTION_END, 0, 1.0)
        results.append(mon.event(END, 0, t[-1]))
    clean, late = results
    np.testing.assert_array_equal(late.accel_times, clean.accel_times)
    np.testing.assert_array_equal(late.accel, clean.accel)
    np.testing.assert_array_equal(late.positions, clean.positions)
    assert np.max(np.abs(late.accel)) < 1.0 and late.residual.rms == clean.residual.rms


def test_stamped_monitor_does_not_depend_on_the_order_of_arrival():
    from shaper_nodes.core.cycles import END, MOTION_END, START, CycleMonitor, StampedCycleMonitor

    t, u, a, truth = simulate(cycles=2, rate=200.0, dwell=1.5)
    events = [(truth.move_starts[k], kind, k) for k in range(2) for kind in (START, MOTION_END, END)]
    events = [(s if kind == START else (truth.move_ends[k] if kind == MOTION_END else
                                       (truth.move_starts[1] - 0.01 if k == 0 else t[-1])), kind, k)
              for s, kind, k in events]
    ordered = CycleMonitor()
    expected = []
    stream = sorted([(ti, 0, i) for i, ti in enumerate(t)] + [(te, 1, j) for j, (te, _, _) in enumerate(events)])
    for ti, what, i in stream:
        if what == 0:
            ordered.add_accel(ti, a[i])
            ordered.add_positions(ti, [u[i]])
        else:
            _, kind, k = events[i]
            r = ordered.event(kind, k, ti)
            if r is not None:
                expected.append(r)
    # the same stream, the samples delayed relative to the events by up to 30 samples (in order among
    # themselves, as one topic's messages arrive)
    rng = np.random.default_rng(0)
    delay = np.maximum.accumulate(rng.integers(0, 30, len(stream)) / 200.0)
    late = [(ti + (d if what == 0 else 0.0), what, i, ti) for (ti, what, i), d in zip(stream, delay, strict=True)]
    mon = StampedCycleMonitor()
    got = []
    for _, what, i, ti in sorted(late):
        if what == 0:
            mon.add_accel(ti, a[i])
            mon.add_positions(ti, [u[i]])
        else:
            _, kind, k = events[i]
            mon.event(kind, k, ti)
        got += mon.poll()
    assert len(got) == len(expected) == 2
    for g, e in zip(got, expected, strict=True):
        assert g.residual == e.residual


def test_a_writer_that_never_finished_is_read_as_far_as_it_wrote(tmp_path):
    # rosbags' writer abandoned mid-recording, as a killed recorder leaves it: complete chunks in the
    # file, the chunk being filled lost, no summary, no footer, no metadata.yaml
    t, u, a, _truth = simulate(cycles=8, mode_hz=MODE_HZ, zeta=ZETA)
    written = write_bag(tmp_path / "killed", t, u, a, finish=False)
    assert not (tmp_path / "killed" / "metadata.yaml").exists()
    rec = read_recording(tmp_path / "killed")
    assert 0 < rec.messages_read < written
    assert any("did not finish" in n for n in rec.notes)
    output = bag_analysis_cli_output([str(tmp_path / "killed"), "--learners", ""])
    assert rec.damage and "recording not closed" in output
    an = analyze(rec, Options(learners=()))
    assert len(an.cycles) >= 3 and an.modes[0].hz == pytest.approx(MODE_HZ, rel=0.02)


def test_stamped_monitor_completes_a_cycle_whose_last_samples_were_lost():
    from shaper_nodes.core.cycles import END, MOTION_END, START, StampedCycleMonitor

    for wait, expected in ((60.0, 0), (0.0, 1)):
        mon = StampedCycleMonitor(max_wait=wait)
        mon.event(START, 0, 0.0)
        for k in range(100):
            mon.add_accel(0.01 * k, (np.sin(0.3 * k), 0.0, 0.0))
            mon.add_positions(0.01 * k, [min(0.01 * k, 0.2)])
        mon.event(MOTION_END, 0, 0.2)
        mon.event(END, 0, 1.5)  # the samples up to END never arrive
        assert len(mon.poll()) == expected


def test_stamped_monitor_waits_for_a_backlog_still_coming_in(monkeypatch):
    # a busy machine: END is taken a while before the samples stamped up to it, which keep coming in; the
    # cycle is evaluated with all of them, not with what had come max_wait after END (session 14)
    from shaper_nodes.core import cycles
    from shaper_nodes.core.cycles import END, MOTION_END, START, StampedCycleMonitor

    clock = [0.0]
    monkeypatch.setattr(cycles.time, "monotonic", lambda: clock[0])
    mon = StampedCycleMonitor(max_wait=1.0)
    mon.event(START, 0, 0.0)
    mon.event(MOTION_END, 0, 0.2)
    mon.event(END, 0, 1.0)
    for k in range(101):  # one sample every 0.5 s of wall time: 50 s of backlog, each within max_wait of the last
        clock[0] += 0.5
        mon.add_accel(0.01 * k, (np.sin(0.3 * k), 0.0, 0.0))
        mon.add_positions(0.01 * k, [min(0.01 * k, 0.2)])
        got = mon.poll()
        assert (len(got) == 1) == (k == 100)
    assert got[0].accel.shape[0] == 101
    # a stream that went quiet behind END is given up on max_wait after its last sample
    mon.event(START, 1, 2.0)
    mon.event(END, 1, 3.0)
    mon.add_accel(2.5, (0.0, 0.0, 0.0))
    mon.add_positions(2.5, [0.2])
    clock[0] += 0.9
    assert mon.poll() == []
    clock[0] += 0.2
    assert len(mon.poll()) == 1


# ------------------------------------------------------------------------------ MRILC replay
def _mrilc_recording(path, cycles: int = 3, reference: bool = True, rate: float = 200.0, first_at: int = 200,
                     log_offset_ns: int = 0):
    """Seed 000's loop on the perturbed plant (w = 5, zeta = 0.15) at 200 Hz with u2 = 0 (a run
    without learning), recorded as the sim plant and the conductor publish it: /joint_states
    (y, u), /sim_plant/reference (r_s, stamped at the start of its period), /cycle_events (the
    END logged before the cycle's last samples, as in a lockstep recording), and a tip
    accelerometer (y''). The first cycle starts at sample ``first_at``; messages are logged ``log_offset_ns``
    after their stamp (a recorder's wall clock beside simulated time). Returns the model, and the cycle's r_s,
    y and u (samples x 1)."""
    import pathlib

    from shaper_nodes.analysis.synthetic import trapezoid
    from shaper_nodes.core.learning.mrilc import model as M
    from shaper_nodes.core.learning.mrilc.learner import model_from_params

    model, _ = model_from_params({})
    plant, period = M.mck_plant(5.0, 0.15), 1.0 / rate
    t_path = M.SampledFilter(M.zoh_sampled(M.learning_path(model.c, plant, "command"), period))
    u_r = M.SampledFilter(M.zoh_sampled(M.ct.feedback(model.c, plant), period))  # C / (1 + C P)
    n = 160
    k = np.arange(n) * period
    up, _ = trapezoid(k, 1.0, 5.0, 50.0)
    down, _ = trapezoid(k - 0.4, -1.0, 5.0, 50.0)
    r_s = (up + down)[:, None]
    y, u = t_path(r_s), u_r(r_s)  # u2 = 0: the loop's own response and effort
    acc = np.gradient(np.gradient(y[:, 0], period), period)
    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = pathlib.Path(__file__).resolve().parents[2] / "shaper_msgs" / "msg"
    store.register(get_types_from_msg((msg_dir / "CycleEvent.msg").read_text(), "shaper_msgs/msg/CycleEvent"))
    T = store.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    step_ns = int(round(period * 1e9))
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = {name: writer.add_connection(topic, kind, typestore=store) for name, topic, kind in (
        ("imu", "/tip_imu", "sensor_msgs/msg/Imu"), ("js", "/joint_states", "sensor_msgs/msg/JointState"),
        ("ref", "/sim_plant/reference", "sensor_msgs/msg/JointState"),
        ("ev", "/cycle_events", "shaper_msgs/msg/CycleEvent")) if reference or name != "ref"}

    def write(name, ns, msg, kind):
        writer.write(conn[name], ns + log_offset_ns, store.serialize_cdr(msg, kind))

    def hdr(ns):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="")

    def event(kind, cycle, ns, log_ns=None):
        write("ev", ns if log_ns is None else log_ns, T["shaper_msgs/msg/CycleEvent"](
            header=hdr(ns), event=kind, cycle=cycle, task="round_trip", joint_names=["joint_1"],
            start_positions=np.zeros(1), goal_positions=np.ones(1), start_stamp=[]), "shaper_msgs/msg/CycleEvent")

    try:
        for c in range(cycles):
            first = first_at + c * (n + 100)  # sample index of the cycle's START (1 s, then 0.5 s apart)
            event(0, c, first * step_ns)
            for i in range(n):
                ns = (first + i) * step_ns
                if i == 80:
                    event(1, c, ns)
                if i == n - 3:  # the END, stamped at the last sample, logged before the last samples
                    event(2, c, (first + n - 1) * step_ns, ns)
                write("js", ns, T["sensor_msgs/msg/JointState"](
                    header=hdr(ns), name=["joint_1"], position=y[i], velocity=np.zeros(1), effort=u[i]),
                    "sensor_msgs/msg/JointState")
                if reference:
                    write("ref", ns, T["sensor_msgs/msg/JointState"](
                        header=hdr(ns), name=["joint_1"], position=r_s[i], velocity=np.zeros(0), effort=np.zeros(0)),
                        "sensor_msgs/msg/JointState")
                write("imu", ns, T["sensor_msgs/msg/Imu"](
                    header=hdr(ns), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                    angular_velocity=Vec(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=Vec(x=float(acc[i]), y=0.0, z=0.0),
                    linear_acceleration_covariance=np.zeros(9)), "sensor_msgs/msg/Imu")
    finally:
        writer.close()
    return model, r_s, y, u


def test_mrilc_replay_gives_the_learners_first_update(tmp_path):
    from shaper_nodes.core.learning.mrilc.learner import MrilcLearner

    model, r_s, y, u = _mrilc_recording(tmp_path / "mrilc")
    rec = read_recording(tmp_path / "mrilc")
    assert rec.topics["reference"] == "/sim_plant/reference" and rec.topics["joints"] == "/joint_states"
    assert rec.efforts is not None and np.array_equal(rec.efforts.values[:160], u)
    an = analyze(rec, Options(learners=("mrilc",)))
    rows = an.replays["mrilc"].rows
    direct = MrilcLearner(model, 1).learn(r_s, y, u)
    first = rows[0]
    assert first["iteration"] == 1 and first["action"] == "learn"
    assert first["rms_e"] == pytest.approx(direct.rms_e, rel=1e-12) and direct.rms_e > 1e-3  # off-nominal plant
    assert first["rms_u1"] == pytest.approx(direct.rms_u1, rel=1e-12) and first["rms_u2"] == 0.0
    assert first["residual"] == pytest.approx(direct.residual, rel=1e-12)
    # the later cycles ran with u2 = 0, not with the learned profile
    assert [r["cycle"] for r in rows] == [0, 1, 2]
    assert all("without the learned profile" in r["skipped"] for r in rows[1:])
    # as a recording of a live run: every cycle learned from, in order
    live = analyze(rec, Options(learners=("mrilc",), learner_params={"replay.learned_run": True}))
    assert [r.get("iteration") for r in live.replays["mrilc"].rows] == [1, 2, 3]
    assert live.replays["mrilc"].rows[0]["rms_e"] == first["rms_e"]


def test_mrilc_replay_says_what_is_missing(tmp_path):
    _mrilc_recording(tmp_path / "noref", cycles=1, reference=False)
    rec = read_recording(tmp_path / "noref")
    assert rec.topics["reference"] == "" and rec.efforts is None
    replay = analyze(rec, Options(learners=("mrilc",))).replays["mrilc"]
    assert replay.rows == [] and replay.notes[0].startswith("not possible")
    assert "applied reference" in replay.notes[0] and "cycle events" not in replay.notes[0]
    # bad parameters are reported, not raised
    _mrilc_recording(tmp_path / "ref", cycles=1)
    bad = analyze(read_recording(tmp_path / "ref"), Options(learners=("mrilc",), learner_params={"mrilc.gama": 5}))
    assert "unknown MRILC parameter(s) mrilc.gama" in bad.replays["mrilc"].notes[0]


def test_cli_runs_the_mrilc_replay_and_plots_its_learning_curve(tmp_path, capsys):
    _mrilc_recording(tmp_path / "mrilc", cycles=2)
    code = bag_analysis_cli.main([str(tmp_path / "mrilc"), "--out", str(tmp_path / "report"), "--no-progress",
                                  "--param", "replay.learned_run=true"])
    out = capsys.readouterr().out
    assert code == 0 and "mrilc replay: 2 update(s)" in out
    assert (tmp_path / "report" / "learning_mrilc.png").exists()
    assert "## MRILC replay" in (tmp_path / "report" / "report.md").read_text()
    assert (tmp_path / "report" / "replay_mrilc.csv").read_text().startswith("cycle,action,iteration")


def test_reference_topic_choice():
    from shaper_nodes.analysis.streams import choose_topics
    from shaper_nodes.recordings import TopicInfo

    js = "sensor_msgs/msg/JointState"
    topics = {"/imu": TopicInfo("/imu", "sensor_msgs/msg/Imu", 9), "/arm/reference": TopicInfo("/arm/reference", js, 9)}
    chosen, notes = choose_topics(topics)  # the only JointState topic: the joint states, not a reference
    assert chosen["joints"] == "/arm/reference" and chosen["reference"] == "" and "only JointState" in notes[0]
    topics["/states"] = TopicInfo("/states", js, 3)  # fewer messages, but not a reference by its name
    chosen, _ = choose_topics(topics)
    assert chosen["joints"] == "/states" and chosen["reference"] == "/arm/reference"
    with pytest.raises(BagError, match="--reference-topic /imu has type"):
        choose_topics(topics, {"reference": "/imu"})


# ------------------------------------------------------------------------------ measured joint states (issue 20)
@pytest.mark.parametrize("noise, step", [(0.0, 0.0), (1e-5, 0.0), (3e-5, 0.0), (1e-4, 0.0),
                                         (0.0, 2 * math.pi / 2**20), (1e-5, 2 * math.pi / 2**16)])
def test_noisy_joint_states_are_segmented(tmp_path, noise, step):
    """Joint states with encoder noise up to 1e-4 rad (and encoder steps) at 500 Hz: every move is
    found, its start and end within 1.5 samples plus the time the move takes to leave the noise band
    (6 sigma: at 8 rad/s^2, sqrt(2 x 6 noise / 8) s), and the mode within 1 % (true 4 Hz); the
    recommendation leaves no vibration at the mode."""
    c = check_segmentation(tmp_path, noise, step)
    assert c.moves_found == c.moves_true == 6
    tolerance = 1.5 / 500.0 + math.sqrt(2 * 6 * max(noise, step) / 8.0)
    assert c.start_error <= tolerance and c.end_error <= tolerance, c
    assert c.mode_error < 0.01, c
    assert c.recommended == "zv", c


def test_motion_that_does_not_stand_out_of_the_noise_says_which_option_to_set(tmp_path):
    t, u, a, _ = simulate(cycles=4)
    still = np.zeros_like(u)
    write_bag(tmp_path / "still", t, still, a, joint_noise=1e-4)
    with pytest.raises(BagError, match=r"no motion stands out of the noise.*--motion-threshold"):
        analyze(read_recording(tmp_path / "still"), Options(learners=()))
    # slow moves within the noise of their own speed are found when the threshold is given
    write_bag(tmp_path / "slow", t, u * 1e-3, a, joint_noise=1e-4)
    rec = read_recording(tmp_path / "slow")
    with pytest.raises(BagError, match="--motion-threshold"):
        analyze(rec, Options(learners=()))
    an = analyze(rec, Options(learners=(), motion_threshold=2e-4, settle_tolerance=1e-4))
    assert an.cycles and any("--motion-threshold" in n for n in an.notes)


def test_several_plants_in_one_recording_are_reported_per_group(tmp_path):
    """Three plants (3.5, 5 and 6.5 Hz) four cycles each, one after the other, as the 1-D demo
    records them: three groups of cycles, each with its own mode within 1 % and its own shaper."""
    t, u, a, truths = simulate_plants((3.5, 5.0, 6.5), cycles=4)
    write_bag(tmp_path / "plants", t, u, a, joint_noise=1e-5)
    an = analyze(read_recording(tmp_path / "plants"), Options(learners=()))
    assert len(an.cycles) == 12
    assert [g.rows for g in an.groups] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]]
    for g, truth in zip(an.groups, truths, strict=True):
        assert g.modes[0].hz == pytest.approx(truth.mode_hz, rel=0.01)
        best = g.recommendation.best
        s = best.shaper
        assert float(percentage_vibration(s.amplitudes, s.times, g.modes[0].omega, g.modes[0].zeta)) < 0.005
    assert any("3 groups" in n for n in an.notes)
    text = bag_analysis_cli_table(an)
    assert "group 3.5 Hz (cycles #0-3)" in text and "group 6.5 Hz (cycles #8-11)" in text
    doc = json.loads(json.dumps(bag_summary(an)))
    assert [g["rows"] for g in doc["groups"]] == [g["cycles"] for g in doc["groups"]] == [[0, 1, 2, 3], [4, 5, 6, 7],
                                                                                  [8, 9, 10, 11]]


def test_one_plant_is_one_group():
    mode = ModeFit(2 * math.pi * 4.0, 0.02, 0.002, 0.001, 1.0, "fit")
    close = ModeFit(2 * math.pi * 4.04, 0.02, 0.002, 0.001, 1.0, "fit")  # 1 %: the same plant
    far = ModeFit(2 * math.pi * 5.0, 0.02, 0.002, 0.001, 1.0, "fit")
    vague = ModeFit(2 * math.pi * 4.4, 0.02, 2 * math.pi * 0.3, 0.001, 1.0, "fit")  # 10 % but +- 0.3 Hz
    assert group_cycles([(0, [mode]), (1, [close])]) == [[0, 1]]
    assert group_cycles([(0, [mode]), (1, [far]), (2, [close])]) == [[0, 2], [1]]
    assert group_cycles([(0, [mode]), (1, [vague])]) == [[0, 1]]


def test_modes_that_change_with_the_shaper_are_not_called_a_plant_change():
    """The arm demo's recording (one cycle unshaped, then with the calibrated ZV): the unshaped cycle rings at 12.15
    and 20.78 Hz, the shaped one only at 9.95 Hz, as the ZV cancels the others. The headline names the shaper change,
    not a payload, tool or pose change; with one shaper on both sides it is a plant change, as before."""
    from types import SimpleNamespace

    from shaper_nodes.analysis.analyze import CHANGED_DURING, CycleRow, plant_changes
    from shaper_nodes.analysis.groups import ModeGroup

    def mode(hz: float) -> ModeFit:
        return ModeFit(2 * math.pi * hz, 0.03, 0.01, 0.001, 0.1, "fit")

    def row(cycle: int, shaper: str) -> CycleRow:
        return CycleRow(cycle, 0.0, 0.0, 0.0, 1.0, 0.02, 0.1, 500, 0.01, shaper, None)

    groups = [ModeGroup([0], [0], [mode(12.15), mode(20.78)]), ModeGroup([1], [1], [mode(9.951)])]
    zv = "zv (8 imp., 115.5 ms)"
    for shapers, first in ((["none", zv], "MODES CHANGE between cycle 0 and cycle 1 with the shaper (none -> " + zv),
                           (["none", zv + CHANGED_DURING], "MODES CHANGE between cycle 0 and cycle 1 with the shaper"),
                           ([zv, zv], "PLANT CHANGE between cycle 0 and cycle 1 (a payload, tool or pose change)"),
                           (["unknown", zv], "PLANT CHANGE between cycle 0 and cycle 1 (a payload")):
        an = SimpleNamespace(groups=groups, cycles=[row(i, s) for i, s in enumerate(shapers)],
                             ringing_issue=lambda m: "")
        line, = plant_changes(an, groups[1])  # type: ignore[arg-type]
        assert line.startswith(first), line
        assert "modes 12.15 / 20.78 Hz -> 9.951 Hz (lowest -18.1 %)" in line
        assert ("need not be a payload, tool or pose change" in line) == line.startswith("MODES CHANGE")


def test_samples_stamped_0_among_stamped_ones_are_left_out(tmp_path):
    """The lockstep sim plant stamps its joint states at rest 0 before its first step, then simulated time; a
    recording begun before the first move had them timed by their log time (wall clock, 1.8e9 s), far from the
    others, and the whole recording came out as one move from there (session 11). They are left out, with a note;
    a stream stamped 0 throughout (IMU here) is still timed by its log times."""
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def hdr(ns: int):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="")

    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        imu = w.add_connection("/tip_imu", "sensor_msgs/msg/Imu", typestore=store)
        js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        log0 = 1_795_929_383 * 10**9
        for k in range(5):  # at rest before the first step: stamped 0
            w.write(js, log0 + k * 10**8, store.serialize_cdr(T["sensor_msgs/msg/JointState"](
                header=hdr(0), name=["j"], position=np.zeros(1), velocity=np.zeros(0), effort=np.zeros(0)),
                "sensor_msgs/msg/JointState"))
        for k in range(1, 201):  # simulated time, 2 ms a step; the IMU unstamped
            ns = k * 2_000_000
            w.write(js, log0 + 10**9 + ns, store.serialize_cdr(T["sensor_msgs/msg/JointState"](
                header=hdr(ns), name=["j"], position=np.array([1e-3 * k]), velocity=np.zeros(0), effort=np.zeros(0)),
                "sensor_msgs/msg/JointState"))
            w.write(imu, log0 + 10**9 + ns, store.serialize_cdr(T["sensor_msgs/msg/Imu"](
                header=hdr(0), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                angular_velocity=Vec(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=np.zeros(9),
                linear_acceleration=Vec(x=float(k), y=0.0, z=0.0), linear_acceleration_covariance=np.zeros(9)),
                "sensor_msgs/msg/Imu"))
    rec = read_recording(tmp_path / "bag")
    assert rec.joints is not None and len(rec.joints.t) == 200
    assert rec.joints.t[0] == pytest.approx(0.002) and rec.joints.t[-1] == pytest.approx(0.4)
    assert any("/joint_states: 5 sample(s) stamped 0 left out" in n for n in rec.notes), rec.notes
    assert len(rec.accel.t) == 200 and rec.accel.t[0] == pytest.approx(1_795_929_384.002)  # log times
    assert not any(n.startswith("/tip_imu") and "stamped 0" in n for n in rec.notes)


def test_settling_is_measured_to_the_noise_floor(tmp_path):
    """A well damped mode decays into the accelerometer noise within the window: with a band asked
    for below the noise (0.001 m/s^2 against 0.01 m/s^2 noise) every cycle still settles, into a band of
    6 x the measured noise, and the notes say so."""
    t, u, a, _ = simulate(cycles=4, zeta=0.15, noise=0.01)
    write_bag(tmp_path / "damped", t, u, a)
    an = analyze(read_recording(tmp_path / "damped"), Options(learners=(), band="0.001"))
    assert an.accel_noise == pytest.approx(0.01, rel=0.15)
    # decay from about 11 m/s^2 to 6 x 0.01 at 4 Hz, damping 0.15: ln(11 / 0.06) / (0.15 x 2 pi 4) = 1.4 s
    assert all(1.0 < r.settling_time < 2.0 for r in an.cycles), [r.settling_time for r in an.cycles]
    assert any("settling band" in n and "accelerometer noise" in n for n in an.notes)


def test_the_recommendation_keeps_zv_for_a_well_known_mode_and_prints_its_rule(robot_bag, capsys):
    """The robot recording's mode is known to about 1e-5 (relative): the recommended shaper leaves no
    vibration at it (ZV), not SI that would leave 4 % to save a few % of the delay; the CLI prints the
    rule with its numbers."""
    path = robot_bag[0]
    assert bag_analysis_cli.main([str(path), "--learners", ""]) == 0
    out = capsys.readouterr().out
    rule = next(line for line in out.splitlines() if line.startswith("rule:"))
    assert "0.5 %" in rule and "5 %" in rule and "20 %" in rule and "zv (" in rule
    assert out.count("recommended: zv") == 1
    assert bag_analysis_cli.main([str(path), "--learners", "", "--min-saving", "0", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    shortest = min((c for c in doc["candidates"] if c["meets_target"]), key=lambda c: c["duration_s"])
    assert doc["recommendation"]["family"] == shortest["family"] and "0 %" in doc["rule"]


def test_a_mode_that_does_not_ring_gets_no_shaper_and_the_option_sets_the_limit(tmp_path, capsys):
    """A plant damped at 0.5: its residual is a transient that dies within a period. The analysis reports the mode
    but recommends no shaper ("no residual vibration above the noise"); --max-damping 0.6 makes it a ringing mode
    again, with a shaper. The lightly damped robot recording's mode is used."""
    t, u, a, _ = simulate(cycles=4, zeta=0.5, noise=0.01)
    write_bag(tmp_path / "damped", t, u, a)
    an = analyze(read_recording(tmp_path / "damped"), Options(learners=()))
    assert an.modes and an.modes[0].zeta == pytest.approx(0.5, rel=0.05)
    assert an.recommendation is not None and an.recommendation.best is None
    assert NO_SHAPER_NEEDED in an.recommendation.rule
    doc = bag_summary(an)
    assert doc["no_shaper_needed"] and doc["recommendation"] is None
    assert doc["modes"][0]["not_used"].startswith("does not ring")
    assert "does not ring: damping 0.5 > 0.3; not used for the shaper" in bag_analysis_cli_table(an)
    assert bag_analysis_cli.main([str(tmp_path / "damped"), "--learners", "", "--max-damping", "0.6", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["recommendation"] is not None and not doc["no_shaper_needed"] and doc["modes"][0]["not_used"] == ""


def test_a_group_recommendation_leaves_out_the_heavily_damped_fit():
    """The analysis' per-group recommendation on the fits of the arm's production recording (cycle 0): the heavily
    damped fit (30.8 Hz, 0.54) is left out, the lightly damped one (9.91 Hz, 0.032) kept; a group of heavily damped
    or noise-floor fits only gets none."""
    from shaper_nodes.analysis.analyze import _group_recommendation

    light = ModeFit(2 * math.pi * 9.912, 0.032, 2 * math.pi * 0.038, 0.0037, 0.2, "fit")
    heavy = ModeFit(2 * math.pi * 30.8, 0.537, 2 * math.pi * 1.4, 0.021, 0.5, "fit")
    rec = _group_recommendation([heavy, light], Options(), 0.01)
    assert rec is not None and rec.best is not None and rec.modes == (light,)
    assert [m for m, _ in rec.not_ringing] == [heavy]
    s = rec.best.shaper
    assert float(percentage_vibration(s.amplitudes, s.times, light.omega, light.zeta)) < 0.005
    weak = ModeFit(2 * math.pi * 9.912, 0.032, 2 * math.pi * 0.038, 0.0037, 0.008, "fit")
    for fits in ([heavy], [heavy, weak]):
        rec = _group_recommendation(fits, Options(), 0.01)
        assert rec is not None and rec.best is None and NO_SHAPER_NEEDED in rec.rule
    assert _group_recommendation([heavy, light], Options(max_damping=0.6), 0.01).modes[0] is heavy


# ------------------------------------------------------------------------------ bounded reading
def _mcap_with_one_chunk(path, payload: bytes, compression: str) -> None:
    """A closed MCAP file whose single chunk holds one message of ``payload`` (written by mcap's writer)."""
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}[compression]
    with open(path, "wb") as f:
        w = McapWriter(f, compression=kind, chunk_size=len(payload) + 1024)
        w.start()
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel("/blob", "cdr", sid)
        w.add_message(cid, 1, payload, 1)
        w.finish()


@pytest.fixture()
def no_inflation(monkeypatch):
    """Count every chunk inflated (through recordings' inflate, which the record scan and rosbags both use)."""
    from shaper_nodes.recordings import bounds, recovery

    calls: list[int] = []
    real = bounds.inflate

    def counted(data, compression, declared):
        calls.append(declared)
        return real(data, compression, declared)

    monkeypatch.setattr(bounds, "inflate", counted)  # rosbags' decompressors, bounded
    monkeypatch.setattr(recovery, "inflate", counted)  # the record scan
    return calls


def test_a_huge_metadata_yaml_is_refused_before_it_is_parsed(robot_bag, tmp_path):
    folder = tmp_path / "huge_meta"
    folder.mkdir()
    mcap = next(robot_bag[0].glob("*.mcap"))
    (folder / mcap.name).write_bytes(mcap.read_bytes())
    with open(folder / "metadata.yaml", "wb") as f:  # 109 MiB, sparse: made at once
        f.write(b"rosbag2_bagfile_information:\n  version: 9\n")
        f.truncate(109 * 2**20)
    with pytest.raises(BagError, match=r"metadata.yaml is 109 MiB, beyond the limit of 16 MiB"):
        read_recording(folder)
    text = bag_analysis_cli_output_err([str(folder), "--no-progress"])
    assert "metadata.yaml is 109 MiB, beyond the limit of 16 MiB" in text
    # a larger limit, asked for, lets it through to the parser (which finds it broken: NUL bytes)
    assert "beyond the limit" not in bag_analysis_cli_output_err([str(folder), "--max-metadata-mib", "200"])


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_declaring_a_huge_size_is_refused_before_it_is_inflated(tmp_path, compression, no_inflation):
    path = tmp_path / "bomb.mcap"
    _mcap_with_one_chunk(path, b"\x00\x01\x00\x00" + b"\x00" * 32 * 1024, compression)
    data = bytearray(path.read_bytes())
    ((start, _),) = mcap_chunks(bytes(data))
    struct.pack_into("<Q", data, start + 9 + 16, 3_435_973_837)  # the declared uncompressed size: 3.2 GiB
    path.write_bytes(bytes(data))
    with pytest.raises(BagError, match=rf"chunk at offset {start} declares 3.2 GiB uncompressed, beyond the limit"
                                       r" of 256 MiB \(not inflated"):
        read_recording(path)
    with pytest.raises(BagError, match=rf"chunk at offset {start} declares 3.2 GiB"):
        Bag(path, recover=True)  # the record scan refuses it too
    assert no_inflation == []


def test_a_zip_bomb_chunk_is_refused_by_its_compression_ratio(tmp_path, no_inflation):
    from shaper_nodes.recordings import ReadLimits

    path = tmp_path / "zeros.mcap"
    _mcap_with_one_chunk(path, bytes(64 * 2**20), "zstd")  # 64 MiB of zeros: a few kB compressed
    assert path.stat().st_size < 2**20
    with pytest.raises(BagError, match=r"declares 64 MiB uncompressed from .* of zstd data, a ratio of \d+ beyond"
                                       r" the limit of 1000 \(not inflated\)"):
        read_recording(path)
    with pytest.raises(BagError, match=r"declares 64 MiB uncompressed, beyond the limit of 16 MiB"):
        read_recording(path, limits=ReadLimits(chunk_bytes=16 * 2**20, compression_ratio=1e6))
    assert no_inflation == []


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_inflation_stops_at_the_size_a_chunk_declares(compression):
    import lz4.frame
    import zstandard

    from shaper_nodes.recordings import ChunkTooLarge, inflate
    from shaper_nodes.recordings.bounds import bound_rosbags_decompressors

    data = bytes(8 * 2**20)
    packed = zstandard.compress(data) if compression == "zstd" else lz4.frame.compress(data)
    assert inflate(packed, compression, len(data)) == data
    with pytest.raises(ChunkTooLarge, match="inflates beyond the 4096 bytes the chunk declares"):
        inflate(packed, compression, 4096)
    bound_rosbags_decompressors()  # what rosbags' reader inflates with, once a Bag has opened one
    from rosbags.rosbag2 import storage_mcap

    with pytest.raises(ChunkTooLarge):
        storage_mcap.DECOMPRESSORS[compression](packed, 4096)


def test_a_file_cut_anywhere_says_it_was_not_closed(robot_bag, tmp_path):
    data = next(robot_bag[0].glob("*.mcap")).read_bytes()
    chunks = mcap_chunks(data)
    texts = {}
    for cut in (0, 5, 8, 20, chunks[0][0] + 100, chunks[1][0] + 4000, len(data) - 10):
        path = tmp_path / f"cut_{cut}.mcap"
        path.write_bytes(data[:cut])
        try:
            rec = read_recording(path)
            texts[cut] = " ".join(rec.notes) + " " + " ".join(d.reason for d in rec.damage)
        except BagError as err:
            texts[cut] = str(err)
        assert "not an MCAP" not in texts[cut] and "empty bag" not in texts[cut], texts[cut]
        assert "not closed" in texts[cut] or "cut inside" in texts[cut], texts[cut]
    assert "is empty (0 bytes): recording not closed" in texts[0]
    assert "ends after 5 of the 8 bytes of the MCAP magic" in texts[5]
    assert "nothing readable before the damage" in texts[20]
    assert "recording not closed (no summary/footer): 0 complete chunk(s)" in texts[chunks[0][0] + 100]
    assert "recording not closed (no summary/footer): 1 complete chunk(s)" in texts[chunks[1][0] + 4000]


def test_random_bytes_are_not_an_mcap_file(tmp_path):
    path = tmp_path / "noise.mcap"
    path.write_bytes(np.random.default_rng(1).bytes(4096))
    with pytest.raises(BagError, match=r"not an MCAP file \(its first bytes are [0-9a-f ]+, the MCAP magic is"
                                       r" 89 4d 43 41 50 30 0d 0a\)"):
        read_recording(path)


def bag_analysis_cli_output_err(argv: list[str]) -> str:
    """What the CLI prints on stderr (it exits 2 here: the recording is refused)."""
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert bag_analysis_cli.main(argv) == 2
    return err.getvalue()


# ------------------------------------------------------------------------------ figures
def _traces_drawn(ax) -> list:
    """The cycle traces of a traces panel (its vertical window markers have two points)."""
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]


def _vertical_lines_at(ax) -> list[float]:
    return [float(ln.get_xdata()[0]) for ln in ax.get_lines()
            if len(ln.get_xdata()) == 2 and ln.get_xdata()[0] == ln.get_xdata()[1]]


def test_figures_of_three_plants_are_per_group_on_a_log_band_around_the_modes(tmp_path):
    import matplotlib.pyplot as plt

    from shaper_nodes.analysis.report import MAX_TRACES_PER_PANEL, figures, write_report

    t, u, a, _truths = simulate_plants((3.5, 5.0, 6.5), cycles=4)
    write_bag(tmp_path / "plants", t, u, a, joint_noise=1e-5)
    an = analyze(read_recording(tmp_path / "plants"), Options())
    assert len(an.groups) == 3
    figs = figures(an)
    try:
        panels = [ax for ax in figs["traces.png"].axes if _traces_drawn(ax)]
        assert len(panels) == 3  # one traces panel per group, its cycles only
        for ax, g in zip(panels, an.groups, strict=True):
            assert len(_traces_drawn(ax)) == len(g.rows) <= MAX_TRACES_PER_PANEL
            assert ax.get_title(loc="left").startswith(g.label)
        spec, sens = figs["spectrum.png"].axes
        assert spec.get_xscale() == "log" and sens.get_xscale() == "log"
        hz = sorted(m.hz for g in an.groups for m in g.modes)
        lo, hi = spec.get_xlim()
        assert lo == pytest.approx(0.2 * hz[0], rel=1e-6)
        assert hi == pytest.approx(min(5 * hz[-1], an.spectrum[0][-1]), rel=1e-6)
        for f in hz:  # every group's mode marked on both panels
            assert any(abs(x - f) < 1e-9 for x in _vertical_lines_at(spec))
            assert any(abs(x - f) < 1e-9 for x in _vertical_lines_at(sens))
        curves = [ln for ln in sens.get_lines() if len(ln.get_xdata()) > 2]
        assert len(curves) == 3  # each group's recommended shaper's V(f)
        for ln, g in zip(curves, an.groups, strict=True):  # each V(f) is near zero at its group's mode
            f, v = np.asarray(ln.get_xdata()), np.asarray(ln.get_ydata())
            assert v[np.argmin(abs(f - g.modes[0].hz))] < 100 * an.options.target
        tolerance = [ln for ln in sens.get_lines() if list(ln.get_ydata()) == [100 * an.options.target] * 2]
        assert tolerance
    finally:
        for fig in figs.values():
            plt.close(fig)
    write_report(an, tmp_path / "report")
    for name in ("traces.png", "spectrum.png", "sensitivity.png"):
        assert (tmp_path / "report" / name).stat().st_size > 0


def test_one_plant_traces_are_capped_and_there_is_no_learning_figure_without_learning(tmp_path):
    import matplotlib.pyplot as plt

    from shaper_nodes.analysis.report import MAX_TRACES_PER_PANEL, figures, write_report

    t, u, a, _ = simulate(cycles=MAX_TRACES_PER_PANEL + 4, mode_hz=MODE_HZ, zeta=ZETA)
    write_bag(tmp_path / "one", t, u, a)
    an = analyze(read_recording(tmp_path / "one"), Options(learners=(), band_hz=(1.0, 30.0)))
    figs = figures(an)
    try:
        (panel,) = [ax for ax in figs["traces.png"].axes if _traces_drawn(ax)]
        assert len(_traces_drawn(panel)) == MAX_TRACES_PER_PANEL
        assert f"{MAX_TRACES_PER_PANEL} of {MAX_TRACES_PER_PANEL + 4} cycles" in panel.get_title(loc="left")
        spec = figs["spectrum.png"].axes[0]
        assert spec.get_xscale() == "log" and spec.get_xlim() == pytest.approx((1.0, 30.0))  # the band asked for
        assert not any(name.startswith("learning") for name in figs)
    finally:
        for fig in figs.values():
            plt.close(fig)
    write_report(an, tmp_path / "report")
    assert not list((tmp_path / "report").glob("learning*.png"))
    assert "No learning plot: no learner replay was asked for" in (tmp_path / "report" / "report.md").read_text()


def test_commands_in_lockstep_blocks_are_skipped_with_the_reason(tmp_path):
    # a recording of the sim plant's lockstep.block exchange: a Float64MultiArray with layout [samples, joints]
    # carries several samples and no time for each; it is not read as one command, and the notes say why
    Imu, F64 = STORE.types["sensor_msgs/msg/Imu"], STORE.types["std_msgs/msg/Float64MultiArray"]
    Layout, Dim = STORE.types["std_msgs/msg/MultiArrayLayout"], STORE.types["std_msgs/msg/MultiArrayDimension"]
    Header, Time = STORE.types["std_msgs/msg/Header"], STORE.types["builtin_interfaces/msg/Time"]
    Quat, Vec = STORE.types["geometry_msgs/msg/Quaternion"], STORE.types["geometry_msgs/msg/Vector3"]
    writer = Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    c_imu = writer.add_connection("/tip_imu", "sensor_msgs/msg/Imu", typestore=STORE)
    c_cmd = writer.add_connection("/forward_position_controller/commands", "std_msgs/msg/Float64MultiArray",
                                  typestore=STORE)
    for k in range(200):
        ns = 1_700_000_000_000_000_000 + k * 10_000_000
        imu = Imu(header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="tool0"),
                  orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.full(9, -1.0),
                  angular_velocity=Vec(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=np.zeros(9),
                  linear_acceleration=Vec(x=math.sin(k / 5), y=0.0, z=9.81), linear_acceleration_covariance=np.zeros(9))
        writer.write(c_imu, ns, STORE.serialize_cdr(imu, "sensor_msgs/msg/Imu"))
        if k % 25 == 0:
            block = F64(layout=Layout(dim=[Dim(label="samples", size=25, stride=50), Dim(label="joints", size=2,
                                                                                          stride=2)], data_offset=0),
                        data=np.zeros(50))
            writer.write(c_cmd, ns, STORE.serialize_cdr(block, "std_msgs/msg/Float64MultiArray"))
    writer.close()
    rec = read_recording(tmp_path / "bag")
    assert rec.commands is None or len(rec.commands) == 0
    assert any("/forward_position_controller/commands: 8 message(s) could not be decoded" in n
               and "a block of 25 samples" in n for n in rec.notes), rec.notes


def test_a_cycle_event_stamped_0_among_stamped_ones_is_at_time_0_not_at_its_log_time(tmp_path):
    """A lockstep simulator's clock starts at 0: the first goal's START (send_goal --cycle) is stamped 0, which
    alone would read as "no stamp" and be timed by the recorder's wall clock; among stamped events it is time 0."""
    _mrilc_recording(tmp_path / "zero", cycles=2, reference=False, first_at=0, log_offset_ns=1_795_000_000 * 10**9)
    rec = read_recording(tmp_path / "zero")
    assert any("/cycle_events: 1 event(s) stamped 0 among stamped ones" in n for n in rec.notes), rec.notes
    an = analyze(rec, Options(learners=()))
    assert an.segmentation == "cycle events (/cycle_events)"
    assert [r.start for r in an.cycles] == [0.0, pytest.approx(260 / 200.0)]
    assert all(r.samples > 0 and not r.issue for r in an.cycles)


def test_a_recording_with_no_mode_gets_its_figures_without_a_warning(tmp_path):
    """A well-shaped recording (the accelerometer's noise alone after every move, as the owner's walk of
    session 15 recorded through the calibrated shaper) identifies no mode: its report is written with no
    matplotlib warning (the spectrum's legend had no entry to show) and the spectrum says no mode was found."""
    import warnings

    import matplotlib.pyplot as plt

    from shaper_nodes.analysis.report import figures, write_report

    t, u, _a, _ = simulate(cycles=4)
    quiet = np.random.default_rng(3).normal(0.0, 0.01, (len(t), 3))
    write_bag(tmp_path / "quiet", t, u, quiet)
    an = analyze(read_recording(tmp_path / "quiet"), Options(learners=()))
    assert not an.modes
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        figs = figures(an)
        try:
            texts = [x.get_text() for x in figs["spectrum.png"].axes[0].texts]
            assert "no mode identified in this band" in texts
        finally:
            for fig in figs.values():
                plt.close(fig)
        write_report(an, tmp_path / "report")
    assert (tmp_path / "report" / "spectrum.png").stat().st_size > 0
