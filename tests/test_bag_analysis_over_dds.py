"""Bag analysis of real recordings, and bag_play feeding a running learner.

- The demo (sim plant, shaper and recorder as processes; the session's shared run, tests/conftest.py's
  ``joint_demo``) records a bag; the analysis of that bag gives the per-cycle residual vibration the demo
  printed, and the sim plant's mode.
- The same recording cut mid-chunk (a killed recorder) is analysed up to the cut.
- A live LIST run is recorded; bag_play then plays the recording into a fresh learner, which
  makes the same per-cycle updates as the live learner did.
"""

from __future__ import annotations

import csv
import math
import os
import re
import struct
import subprocess
import time

import pytest
from shaper_stand_in import ShaperStandIn

from reproductions.common import metric as _metric
from reproductions.list_cases import CASES, LEARNER
from shaper_msgs.msg import CycleEvent
from shaper_nodes.analysis.analyze import Options, analyze
from shaper_nodes.analysis.streams import read_recording
from shaper_nodes.recordings import Bag, mcap_chunks

pytestmark = pytest.mark.integration


def test_demo_recording_analysis_matches_the_demo_and_the_plant(joint_demo, tmp_path):
    out, proc = joint_demo  # the session's demo run (tests/conftest.py), decoded in test_demo_recording.py too
    assert proc["returncode"] == 0, proc["stdout"] + proc["stderr"]
    printed = [float(x) for x in re.findall(r"residual RMS ([0-9.eE+-]+) m/s\^2", proc["stdout"])]
    with open(out / "results.csv") as f:
        per_cycle = [float(v) for row in csv.DictReader(f) for v in row["per_cycle_rms_m_s2"].split()]
    assert len(printed) == len(per_cycle) == 3  # one cycle unshaped, one with ZV, one with ZVD

    an = analyze(read_recording(out / "recording"), Options(learners=()))
    assert an.segmentation == "cycle events (/cycle_events)"
    assert [r.shaper.split()[0] for r in an.cycles] == ["none", "zv", "zvd"]
    # the sim plant's own per-cycle reports (measured in the plant's process, recorded on /cycle_reports)
    with Bag(out / "recording") as bag:
        decode = bag.deserializer("shaper_msgs/msg/CycleReport")
        plant = [decode(raw).residual_rms for _, _, _, raw in bag.messages(["/cycle_reports"])]
    for row, live, shown, own in zip(an.cycles, per_cycle, printed, plant, strict=False):
        assert row.rms == pytest.approx(live, rel=0.01)
        assert row.rms == pytest.approx(shown, rel=0.01)
        assert row.rms == pytest.approx(own, rel=0.01)
    true_hz, true_zeta = 5.0 * 1.3, 0.01  # the demo's plant: nominal 5 Hz, +30 %
    assert an.modes[0].hz == pytest.approx(true_hz, rel=0.02)
    assert an.modes[0].zeta == pytest.approx(true_zeta, rel=0.2)
    best = an.recommendation.best
    assert best is not None and best.nominal_vibration <= 0.05
    assert an.predicted["rms_nominal"] < 0.1 * an.cycles[0].rms

    # the recording cut in the middle of the first chunk that starts after the second cycle's START was
    # recorded (the demo here closes a chunk every 0.1 s: JOINT_DEMO), as a killed recorder leaves it: that
    # cycle's END is lost. Chunks are ordered by log time (when the recorder took a message), which on a busy
    # machine lags the events' stamps, so the chunk is chosen by the START's and END's log times
    with Bag(out / "recording") as bag:
        decode = bag.deserializer("shaper_msgs/msg/CycleEvent")
        logged = [(decode(raw).event, log_ns * 1e-9) for _, _, log_ns, raw in bag.messages(["/cycle_events"])]
    # the second START and the END after it, in recording order (each case of the demo counts its cycles from 0)
    start_logged = [t for kind, t in logged if kind == CycleEvent.START][1]
    end_logged = next(t for kind, t in logged if kind == CycleEvent.END and t > start_logged)
    mcap = next((out / "recording").glob("*.mcap"))
    data = mcap.read_bytes()
    spans = [(pos, length, *(t * 1e-9 for t in struct.unpack_from("<QQ", data, pos + 9)))
             for pos, length in mcap_chunks(data)]
    last, length, _, chunk_end = next(c for c in spans if c[2] > start_logged)
    assert chunk_end < end_logged
    (tmp_path / "cut.mcap").write_bytes(data[: last + length // 2])
    cut = read_recording(tmp_path / "cut.mcap")
    (dmg,) = cut.damage
    assert dmg.reason.startswith("cut inside a chunk record") and dmg.readable == last
    assert dmg.lost_bytes == length // 2 and dmg.lost_time is not None
    partial = analyze(cut, Options(learners=()))
    # the rest band that starts the residual window comes from the position noise measured over the whole
    # recording (analysis.segment), so the cut one may start its first window a sample or two apart
    assert len(partial.cycles) == 1
    assert partial.cycles[0].window_start == pytest.approx(an.cycles[0].window_start, abs=2.5e-3)
    assert partial.cycles[0].rms == pytest.approx(an.cycles[0].rms, rel=5e-3)
    assert any("the recording ends before its END" in n for n in partial.notes)


def test_bag_play_into_a_running_learner_gives_the_live_updates(list_case2_recording, start_node, ros_context,
                                                                tmp_path, domain_id):
    from rclpy.executors import SingleThreadedExecutor

    from shaper_msgs.msg import CycleReport
    from shaper_nodes.ros.launching import NodeProcess

    # 1. a live LIST run (case 2, five cycles), recorded: the session's shared run (tests/conftest.py's
    # list_case2_recording, which test_list_over_dds.py replays offline)
    bag, live, recorder_code = list_case2_recording
    assert recorder_code == 0
    # a live cycle whose accelerometer samples were lost on the way to the learner (best effort, a busy
    # machine) is skipped live but complete in the recording: compare the cycles up to the first such one
    clean = next((k for k, r in enumerate(live) if r.skipped), len(live))
    assert clean >= 2, live  # the reference cycle and at least one learning step

    # the analysis' offline LIST replay of the recording gives the live updates too
    an = analyze(read_recording(bag), Options(learner_params={**LEARNER, **CASES["case2"].learner}))
    offline = an.replays["list"].rows
    assert len(offline) == len(live)
    for row, it in zip(offline[:clean], live[:clean], strict=True):
        assert "M" in row, (row, it)  # (offline skipped a cycle learned live: its reason)
        assert row["M"] == pytest.approx(it.m, rel=1e-9)
        assert (row["a1_next"], row["t2_next"]) == pytest.approx((it.a1_next, it.t2_next), rel=1e-9)

    # 2. a fresh learner, fed by bag_play (no plant, no shaper node)
    stand_in = ShaperStandIn(ros_context, message="accepted (replay)")  # in a replay the active shaper comes from
    # the recording, so the shaper node itself must not run (it would publish its own)
    reports: list = []
    stand_in.node.create_subscription(CycleReport, "/learner/reports", reports.append, 100)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(stand_in.node)

    def spin_until(done, timeout, what):
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            executor.spin_once(timeout_sec=0.05)

    try:
        start_node("shaper_nodes", "learner", {"state_file": str(tmp_path / "replay.json"), **LEARNER,
                                               **CASES["case2"].learner})
        spin_until(lambda: stand_in.requests, 60.0, "the learner's first shaper request")
        env = {"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        player = NodeProcess("shaper_nodes", "bag_play", {
            "bag": str(bag), "rate": 2.0, "min_interval": 0.002, "wait_for_subscribers": 1, "start_delay": 1.0,
            "pause_after_topics": ["/shaper/active_shaper"], "pause_after": 0.8, "await_reports": "/learner/reports",
            "topics": ["/tip_imu", "/cycle_events", "/shaper/active_shaper"]},
            log_path=tmp_path / "bag_play.log", env=env).start()
        try:
            spin_until(lambda: len(reports) >= clean, 120.0, f"{clean} learner reports")
            spin_until(lambda: not player.running(), 60.0, "bag_play to finish")
        finally:
            code = player.stop()
        assert code == 0, (tmp_path / "bag_play.log").read_text()
        assert "done (" in (tmp_path / "bag_play.log").read_text()
    finally:
        executor.shutdown()
        stand_in.node.destroy_node()

    assert len(reports) == len(live)
    for k, (rep, it) in enumerate(zip(reports[:clean], live[:clean], strict=True)):
        assert "skipped" not in rep.metric_names, k
        for name, value in (("M", it.m), ("a1_next", it.a1_next), ("t2_next", it.t2_next), ("phi", it.phi)):
            got = _metric(rep, name)
            # the same samples and the same code: equal up to rounding (the sums' order may differ)
            assert got == pytest.approx(value, rel=1e-9, abs=1e-12) or (math.isnan(got) and math.isnan(value)), \
                (k, name, got, value)


def test_installed_executables_name_a_missing_bag(tmp_path, domain_id):
    from shaper_nodes.ros.launching import NodeProcess, executable

    out = subprocess.run([str(executable("shaper_nodes", "analyze_bag")), str(tmp_path / "nope")],
                         capture_output=True, text=True, timeout=120, env=os.environ)
    assert out.returncode == 2 and "analyze_bag:" in out.stderr and "no recording" in out.stderr
    assert "Traceback" not in out.stderr
    proc = NodeProcess("shaper_nodes", "bag_play", {"bag": str(tmp_path / "nope")}, log_path=tmp_path / "log",
                       env={"ROS_DOMAIN_ID": str(domain_id)}).start()
    proc.proc.wait(timeout=60)
    proc.stop()
    assert proc.proc.returncode == 1
    assert "no recording at" in (tmp_path / "log").read_text()


def test_bag_play_waits_after_each_end_for_the_learners_report(start_node, ros_context, tmp_path):
    """With ``await_reports``, once an END is played the next cycle event waits until a report arrives on that topic,
    while the samples logged just after the END play on; an END that is never reported holds the next event for
    ``await_timeout`` at most, with a warning, then the playback goes on."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64

    from shaper_msgs.msg import CycleEvent, CycleReport
    from shaper_nodes.recordings import BagWriter

    bag = tmp_path / "bag"
    w = BagWriter(bag)
    w.add_topic("/cycle_events", "shaper_msgs/msg/CycleEvent")
    w.add_topic("/level", "std_msgs/msg/Float64")
    t = 1_000_000_000
    for cycle in range(2):  # per cycle: START, a sample, END and a sample logged at the END's time
        w.write("/cycle_events", t, serialize_message(CycleEvent(event=CycleEvent.START, cycle=cycle)))
        w.write("/level", t + 1_000_000, serialize_message(Float64(data=1.0 + cycle)))
        w.write("/cycle_events", t + 2_000_000, serialize_message(CycleEvent(event=CycleEvent.END, cycle=cycle)))
        w.write("/level", t + 2_000_000, serialize_message(Float64(data=10.0 + cycle)))
        t += 3_000_000
    w.write("/cycle_events", t, serialize_message(CycleEvent(event=CycleEvent.START, cycle=2)))
    w.close()
    node = Node("learner_stand_in", context=ros_context)
    got: list[tuple[str, float]] = []
    node.create_subscription(CycleEvent, "/cycle_events", lambda m: got.append(("event", m.event)), 100)
    node.create_subscription(Float64, "/level", lambda m: got.append(("level", m.data)), 100)
    reports = node.create_publisher(CycleReport, "/learner/reports", 100)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)

    def spin_until(done, timeout, what):
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            executor.spin_once(timeout_sec=0.05)

    starts = lambda: got.count(("event", CycleEvent.START))  # noqa: E731
    try:
        player = start_node("shaper_nodes", "bag_play", {
            "bag": str(bag), "rate": 1.0, "min_interval": 0.002, "wait_for_subscribers": 1, "start_delay": 0.5,
            "await_reports": "/learner/reports", "await_timeout": 2.0})
        spin_until(lambda: reports.get_subscription_count() > 0, 60.0, "bag_play's report subscription")
        spin_until(lambda: ("level", 10.0) in got, 60.0, "the sample logged with the first END")
        # what must not come yet: the next START. Given time to come (a wait for something that must not happen),
        # it does not: the player waits for the report.
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert starts() == 1, got
        reports.publish(CycleReport(cycle=0))
        spin_until(lambda: starts() == 2, 60.0, "the START after the reported END")
        spin_until(lambda: not player.running(), 60.0, "bag_play to finish after the unreported END's timeout")
        assert player.stop() == 0
    finally:
        executor.shutdown()
        node.destroy_node()
    log = player.log_path.read_text()
    assert log.count("no report on /learner/reports") == 1 and "for END 2 within 2 s" in log, log
    # each topic in the bag's order (DDS orders a topic's samples, not two topics' against each other: the stand-in's
    # executor took a /level sample after a later /cycle_events one once); the END's sample came before the wait above
    assert [x for x in got if x[0] == "event"][:2] == [("event", CycleEvent.START), ("event", CycleEvent.END)]
    assert [x for x in got if x[0] == "level"][:2] == [("level", 1.0), ("level", 10.0)]
    assert starts() == 3 and "done (/cycle_events: 5, /level: 4)" in log, log
