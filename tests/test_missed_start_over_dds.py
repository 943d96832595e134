"""A listener that misses a cycle's START over DDS still gets the cycle (or says exactly why not): the identifier
in-process, the robot program's cycle events from a publisher of another participant made for the cycle, as
``send_goal --cycle`` makes one per goal (session 13's walk: a listener whose side of the match came late missed
START in 3 of 34 goals, "END without its START").

START is lost (:class:`StartLost`: a START sent before that publisher matched is never sent to a reader that matches
later, and a listener cannot tell it from one never sent); MOTION_END and END go out once it has matched the
identifier, carrying the START's stamp (CycleEvent ``start_stamp``). The identifier stands in for the START it never
received (``events.rule.stood_in``): listening since before START, it measures the cycle as it measures the same
cycle seen from its START; created after START went out, it says that it did not see the window from START and uses
nothing."""

from __future__ import annotations

import math
import pathlib
from collections.abc import Callable

import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Imu
from shaper_stand_in import ShaperStandIn
from test_identifier_node import RATE, Rig, decay, stamp

from shaper_msgs.msg import CycleEvent
from shaper_nodes.ros.cycle_events import set_start_stamp

pytestmark = pytest.mark.integration
MOTION, RING = 0.5, 2.0  # s: START to MOTION_END, MOTION_END to END


class StartLost:
    """The events' publisher of a new participant made for the cycle, as each ``send_goal --cycle`` is a process of
    its own, that loses the cycle's START: it is not sent. A listener cannot tell a START never sent from one sent
    before its reader matched (a volatile writer never sends it to a reader that matches later, which is how
    ``send_goal --cycle`` lost it in session 13's walk); sending it to a publisher that had matched nobody yet was a
    race: discovery sometimes finished between the look at the match count and the write (once in CI, session 17's
    submission). MOTION_END and END go out by this publisher once it has matched the listener."""

    def __init__(self, program: Callable[[], Node]) -> None:
        self.pub = program().create_publisher(CycleEvent, "/cycle_events", 10)

    def publish(self, msg: CycleEvent) -> None:
        if msg.event != CycleEvent.START:
            self.pub.publish(msg)

    def get_subscription_count(self) -> int:
        return self.pub.get_subscription_count()


def imu(rig: Rig, t0: float, t1: float, accel) -> int:
    """Samples stamped from t0 up to (not including) t1 s at RATE, ``accel(t - t0)`` m/s^2 on x; their count."""
    n = int(round((t1 - t0) * RATE))
    for k in range(n):
        msg = Imu()
        msg.header.stamp = stamp(t0 + k / RATE)
        msg.linear_acceleration.x = float(accel(k / RATE))
        rig.imu.publish(msg)
        if k % 20 == 0:
            rig.ex.spin_once(timeout_sec=0.0)
    return n


def event(pub, kind: int, cycle: int, t: float, start: float) -> None:
    msg = CycleEvent(event=kind, cycle=cycle, task="program")
    msg.header.stamp = stamp(t)
    set_start_stamp(msg, start)
    pub.publish(msg)


def seen_cycle(rig: Rig, cycle: int) -> None:
    """The cycle with its START received: START first, then the motion's samples, MOTION_END, the ring, END."""
    start = rig.t
    event(rig.events, CycleEvent.START, cycle, start, start)
    rig.spin_until(lambda: rig.node.monitor.in_cycle, "START")
    sent = imu(rig, start, start + MOTION, lambda t: 0.01 * t)
    event(rig.events, CycleEvent.MOTION_END, cycle, start + MOTION, start)
    sent += imu(rig, start + MOTION, start + MOTION + RING, decay)
    rig.spin_until(lambda: rig.node.monitor.accel_samples >= sent, f"the {sent} samples", timeout=60.0)
    event(rig.events, CycleEvent.END, cycle, start + MOTION + RING, start)
    rig.spin_until(lambda: not rig.node.monitor.in_cycle, "END")
    rig.t = start + MOTION + RING + 1.0


def missed_cycle(rig: Rig, program: Callable[[], Node], cycle: int, before: float = 0.5) -> None:
    """The same cycle, its START lost by a publisher made for it (StartLost); the samples
    from ``before`` s before START."""
    start = rig.t
    pub = StartLost(program)
    event(pub, CycleEvent.START, cycle, start, start)
    # the samples go out after it, stamped from before it on (the topics are apart: stamps, not arrival, count)
    held = imu(rig, start - before, start, lambda t: 0.0) + imu(rig, start, start + MOTION, lambda t: 0.01 * t)
    rig.spin_until(lambda: rig.node.monitor.held_before >= held, f"the {held} samples before MOTION_END")
    rig.spin_until(lambda: pub.get_subscription_count() >= 1, "the identifier matching the program's publisher")
    assert not rig.node.monitor.in_cycle and rig.node.events.rule.stood_in == 0  # START never came
    event(pub, CycleEvent.MOTION_END, cycle, start + MOTION, start)
    rig.spin_until(lambda: rig.node.monitor.in_cycle, "MOTION_END")
    sent = rig.node.monitor.accel_samples + imu(rig, start + MOTION, start + MOTION + RING, decay)
    rig.spin_until(lambda: rig.node.monitor.accel_samples >= sent, f"the {sent} samples", timeout=60.0)
    event(pub, CycleEvent.END, cycle, start + MOTION + RING, start)
    rig.spin_until(lambda: not rig.node.monitor.in_cycle, "END")
    assert rig.node.events.rule.stood_in >= 1  # the START was stood in for: the identifier never received it
    rig.t = start + MOTION + RING + 1.0


def test_a_listener_that_missed_start_measures_the_cycle_as_if_it_had_seen_it(ros_context, program):
    rig = Rig(ros_context)
    try:
        rig.t = 10.0
        seen_cycle(rig, 0)
        missed_cycle(rig, program, 1)
        assert rig.node.skipped == [], rig.node.skipped
        (seen, _), (missed, _) = rig.node.cycles
        assert missed.cycle == 1 and missed.start == 13.5 and missed.unseen == ""
        assert len(missed.accel_times) == len(seen.accel_times)
        assert missed.accel_times[0] == missed.start  # its samples from its START on
        assert missed.residual.window_end - missed.residual.window_start == pytest.approx(
            seen.residual.window_end - seen.residual.window_start, abs=1e-9)
        assert missed.residual.rms == pytest.approx(seen.residual.rms, rel=1e-9)
    finally:
        rig.close()


def test_a_listener_started_after_start_says_it_did_not_see_the_window(ros_context, program):
    pub = program().create_publisher(CycleEvent, "/cycle_events", 10)
    event(pub, CycleEvent.START, 0, 10.0, 10.0)  # before the identifier exists
    rig = Rig(ros_context)
    try:
        rig.t = 10.0 + MOTION
        rig.spin_until(lambda: pub.get_subscription_count() >= 1, "the identifier matching the program's publisher")
        event(pub, CycleEvent.MOTION_END, 0, 10.0 + MOTION, 10.0)
        rig.spin_until(lambda: rig.node.monitor.in_cycle, "MOTION_END")
        sent = imu(rig, 10.0 + MOTION, 10.0 + MOTION + RING, decay)
        rig.spin_until(lambda: rig.node.monitor.accel_samples >= sent, f"the {sent} samples", timeout=60.0)
        event(pub, CycleEvent.END, 0, 10.0 + MOTION + RING, 10.0)
        rig.spin_until(lambda: rig.node.skipped, "the cycle's refusal")
        assert not rig.node.cycles
        assert rig.node.skipped == ["cycle 0: its START was missed (stood in for by a later event's start stamp,"
                                    " 10.000 s) and no samples held: the window from START was not seen"]
        # the next cycle, seen from its START, is measured
        rig.t = 20.0
        seen_cycle(rig, 1)
        assert [r.cycle for r, _ in rig.node.cycles] == [1]
    finally:
        rig.close()


def test_bag_play_plays_the_cycle_events_of_a_recording_older_than_start_stamp(start_node, ros_context):
    """The reference recording bags/demo_joint_5hz_none_zvd was made before CycleEvent had ``start_stamp``: its
    recorded bytes do not deserialize as the installed CycleEvent, and bag_play would leave the topic out. They are
    played converted (the field empty), every event as recorded (played in a loop: a whole pass is waited for, the
    first events may go out before the listener's side of the match)."""
    import time

    from rclpy.executors import SingleThreadedExecutor

    from shaper_nodes.recordings import Bag

    bag = pathlib.Path(__file__).resolve().parents[1] / "bags" / "demo_joint_5hz_none_zvd"
    with Bag(bag) as recorded:  # decoded with the recording's own (older) definition
        decode = recorded.deserializer("shaper_msgs/msg/CycleEvent")
        want = [(int(m.event), int(m.cycle)) for m in (decode(raw) for _, _, _, raw in
                                                        recorded.messages(["/cycle_events"]))]
    assert len(want) == 12
    node = rclpy.create_node("listener", context=ros_context)
    got: list[CycleEvent] = []
    node.create_subscription(CycleEvent, "/cycle_events", got.append, 100)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)

    def whole_pass() -> list[CycleEvent] | None:
        seen = [(int(m.event), int(m.cycle)) for m in got]
        for i in range(len(seen) - len(want) + 1):
            if seen[i:i + len(want)] == want:
                return got[i:i + len(want)]
        return None

    try:
        player = start_node("shaper_nodes", "bag_play", {"bag": str(bag), "rate": 50.0, "topics": ["/cycle_events"],
                                                         "wait_for_subscribers": 1, "loop": True})
        deadline = time.monotonic() + 120.0
        while whole_pass() is None:
            assert time.monotonic() < deadline, f"timed out: {[(m.event, m.cycle) for m in got]}"
            executor.spin_once(timeout_sec=0.05)
        player.stop()
    finally:
        executor.shutdown()
        node.destroy_node()
    log = player.log_path.read_text()
    assert "recorded with an older definition: played with the fields added since empty" in log, log
    assert "not played" not in log, log
    played = whole_pass()
    assert played is not None
    assert all(len(m.start_stamp) == 0 and list(m.joint_names) == ["joint_1"] for m in played)


# ------------------------------------------------------------------ the LIST learner, its own process
def ring(t: float) -> tuple[float, float, float]:
    """The tool's accelerometer t s after START: gravity, and after the motion a decaying 8 Hz ring (m/s^2)."""
    a = 0.05 * math.exp(-(t - MOTION) / 0.3) * math.sin(2 * math.pi * 8.0 * (t - MOTION)) if t > MOTION else 0.0
    return a, 0.0, 9.81


def learner_cycle(start_node, ros_context, program: Callable[[], Node], state: pathlib.Path, missed: bool):
    """A fresh LIST learner (its own process) and one cycle at 100 s, its START seen or missed (sent before the
    program's new publisher matched the learner); the learner's report of it, and its log."""
    import time

    from rclpy.duration import Duration
    from rclpy.executors import SingleThreadedExecutor

    from shaper_msgs.msg import CycleReport
    from shaper_nodes.ros.lockstep_reader import STREAM_QOS

    side = ShaperStandIn(ros_context, "shaper_side", active=True)  # the shaper node's side the learner talks to
    reports: list = []
    side.node.create_subscription(CycleReport, "/learner/reports", reports.append, 10)
    imu_pub = side.node.create_publisher(Imu, "/tip_imu", STREAM_QOS)
    events = side.node.create_publisher(CycleEvent, "/cycle_events", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(side.node)

    def spin_until(done, what, timeout=120.0):
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            executor.spin_once(timeout_sec=0.05)

    def samples(t0: float, t1: float) -> None:
        for k in range(int(round(t0 * 500)), int(round(t1 * 500)) + 1):
            msg = Imu()
            msg.header.stamp = stamp(100.0 + k / 500)
            msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = ring(k / 500)
            imu_pub.publish(msg)

    try:
        learner = start_node("shaper_nodes", "learner", {"mode": "list", "state_file": str(state),
                                                         "topics.imu_reliable": True, "end_wait": 10.0})
        spin_until(lambda: side.requests and imu_pub.get_subscription_count() and events.get_subscription_count(),
                   "the learner's start-up request and its subscriptions")
        # the active shaper (latched) in the learner's reader: a cycle that starts before it is not learned from
        acked = lambda: side.active.wait_for_all_acked(Duration(seconds=0.1))  # noqa: E731
        spin_until(lambda: side.active.get_subscription_count() and acked(),
                   "the learner's acknowledgement of the active shaper")
        pub = events
        if missed:
            pub = StartLost(program)
        event(pub, CycleEvent.START, 0, 100.0, 100.0)
        samples(-1.0, MOTION)
        spin_until(lambda: pub.get_subscription_count() >= 1, "the learner matching the events' publisher")
        event(pub, CycleEvent.MOTION_END, 0, 100.0 + MOTION, 100.0)
        samples(MOTION + 1 / 500, MOTION + RING)
        event(pub, CycleEvent.END, 0, 100.0 + MOTION + RING, 100.0)
        spin_until(lambda: reports, "the learner's report of the cycle")
        # a clean stop (SIGINT), waited for generously: at load 40 with two hogs a learner once took over 10 s
        assert learner.stop(timeout=60.0) == 0, learner.log_path.read_text()
    finally:
        executor.shutdown()
        side.node.destroy_node()
    return reports[0], learner.log_path.read_text()


def metric(report, name: str) -> float:
    return report.metric_values[list(report.metric_names).index(name)]


def test_the_learner_learns_from_a_cycle_whose_start_it_missed_as_from_the_same_cycle_seen(start_node, ros_context,
                                                                                          program, tmp_path):
    seen, _ = learner_cycle(start_node, ros_context, program, tmp_path / "seen.json", missed=False)
    missed, log = learner_cycle(start_node, ros_context, program, tmp_path / "missed.json", missed=True)
    assert "cycle 0: its START was missed; stood in for by the MOTION_END's start stamp, 100.000 s" in log, log
    for report in (seen, missed):
        assert "skipped" not in report.metric_names, list(report.metric_names)
    assert (missed.window_start, missed.window_end) == (seen.window_start, seen.window_end)
    for name in ("M", "a1_next", "t2_next"):
        assert metric(missed, name) == pytest.approx(metric(seen, name), rel=1e-9), name
