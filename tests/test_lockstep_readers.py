"""The lockstep arm waits for the readers a run declares; a lost sample is reported.

The sim plant (``plant.model: arm``, lockstep) names its readers in ``lockstep.readers``; each acknowledges
the simulated time it has processed (shaper_nodes.ros.lockstep_reader) and the plant never steps more than
``lockstep.lead`` beyond the slowest. Each reader a run declares (the demo's client, calibrate, the
identifier, the recorder) is paused (SIGSTOP) for 3 s in the middle of a move and continued: the run
completes with the numbers of an unpaused run, to the last digit. A reader that stops acknowledging is
dropped after ``lockstep.reader_timeout`` with one line naming it; a reader the plant does not wait for,
with a shallow queue, loses samples, and its gap check counts exactly the samples missing.
"""

from __future__ import annotations

import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from conftest import ONE_WORKER, SMALL_CALIBRATION_PLANT, SMALL_PLAN, calibrate_config
from control_msgs.action import FollowJointTrajectory
from mcap.reader import make_reader
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.ros.action_client import ResilientActionClient
from shaper_nodes.ros.conversions import time_to_sec
from shaper_nodes.ros.lockstep_reader import AckWatch, LockstepReader, header_stamp, subscribe_draining
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME

pytestmark = pytest.mark.integration

ACTION = "/joint_trajectory_controller/follow_joint_trajectory"
RATE = 500.0
PAUSE = 3.0  # s of SIGSTOP
#: how a lockstep reader reports samples lost (LockstepReader.describe_lost); a goal response lost and recovered from
#: the action's status (ResilientActionClient's warning) is not a lost sample
SAMPLES_LOST = re.compile(r"lost \d+ samples? of ")


def sim(start_node, readers: list[str], **extra):
    declared = {"lockstep.readers": readers} if readers else {}  # (an empty list carries no type)
    return start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "mode": "lockstep", "rate": RATE,
                                                      "task.start": HOME.tolist(), "imu.noise_stddev": 0.01,
                                                      "lockstep_timeout": 60.0, **declared, **extra})


def goal(offset: float, seconds: float, hold: float) -> FollowJointTrajectory.Goal:
    """A move of the elbow by ``offset`` rad in ``seconds``, then ``hold`` s at rest."""
    target = HOME.copy()
    target[2] += offset

    def point(t: float) -> JointTrajectoryPoint:
        return JointTrajectoryPoint(positions=target.tolist(), velocities=[0.0] * 6,
                                    time_from_start=Duration(sec=int(t), nanosec=int(round((t % 1) * 1e9))))
    return FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES),
                                                                 points=[point(seconds), point(seconds + hold)]))


class Mover:
    """A client node that sends goals to the arm's controller and follows /clock."""

    def __init__(self, ctx) -> None:
        self.node = rclpy.create_node("mover", context=ctx)
        self.action = ResilientActionClient(self.node, FollowJointTrajectory, ACTION)
        self.clock = 0.0
        self.node.create_subscription(Clock, "/clock", self._on_clock, 100)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.node)

    def _on_clock(self, msg: Clock) -> None:
        self.clock = max(self.clock, time_to_sec(msg.clock))

    def spin_until(self, cond, what: str, timeout: float = 120.0) -> None:
        end = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < end, f"timed out waiting for {what}"
            self.ex.spin_once(timeout_sec=0.02)

    def move(self, g: FollowJointTrajectory.Goal) -> int:
        """Send ``g``; returns its result's error code."""
        self.spin_until(self.action.server_is_ready, "the controller's action server")
        sent = self.action.send_goal_async(g)
        self.spin_until(sent.done, "the goal response")
        assert sent.result().accepted
        result = sent.result().get_result_async()
        self.spin_until(result.done, "the goal result")
        return int(result.result().result.error_code)


def test_a_lost_sample_is_counted_exactly(start_node, ros_context):
    """A reader the plant does not wait for, with a queue of 10, not spun during a move: the samples it lost are
    the gaps in its stamps, each one counted."""
    plant = sim(start_node, [])
    mover = Mover(ros_context)
    reader_node = rclpy.create_node("shallow_reader", context=ros_context)
    reader = LockstepReader(reader_node, {"/tip_imu": 1.0 / (2 * RATE)})
    stamps: list[float] = []

    def on_imu(msg: Imu) -> None:
        stamps.append(time_to_sec(msg.header.stamp))
        reader.took("/tip_imu", stamps[-1])

    shallow = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    reader_node.create_subscription(Imu, "/tip_imu", on_imu, shallow)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(reader_node)
    mover.spin_until(lambda: mover.action.server_is_ready() or not plant.running(), "the action server")
    assert plant.running(), plant.log_path.read_text()
    sent = mover.action.send_goal_async(goal(0.2, 1.0, 0.5))
    end = time.monotonic() + 120.0
    while not stamps:  # the reader takes the move's first samples, then is not spun any more
        assert time.monotonic() < end, "no IMU sample"
        mover.ex.spin_once(timeout_sec=0.01)
        ex.spin_once(timeout_sec=0.01)
    mover.spin_until(sent.done, "the goal response")
    result = sent.result().get_result_async()
    mover.spin_until(result.done, "the goal result")
    while True:  # drain what the reader's queue kept: until 0.5 s bring no sample (the reader's acknowledgement
        n = len(stamps)  # timer runs in between, so one spin that took nothing says nothing)
        quiet = time.monotonic() + 0.5
        while time.monotonic() < quiet:
            ex.spin_once(timeout_sec=0.05)
        if len(stamps) == n:
            break
    ex.shutdown()
    period = 1.0 / (2 * RATE)
    span = round((max(stamps) - min(stamps)) / period) + 1  # the samples published from its first to its last
    missing = span - len(set(stamps))
    assert missing > 0  # a queue of 10 did not hold a 1.5 s move
    assert reader.lost() == {"/tip_imu": missing}
    assert reader.describe_lost() == f"lost {missing} samples of /tip_imu"
    mover.node.destroy_node()
    reader_node.destroy_node()


def test_a_reader_that_stops_acknowledging_is_dropped_with_one_line(start_node, ros_context):
    """The plant waits for a declared reader that took samples and then stops (not spun): after
    lockstep.reader_timeout it steps on without it, with one line naming it, and the goal completes."""
    plant = sim(start_node, ["/stalled_reader"], **{"lockstep.reader_timeout": 2.0})
    mover = Mover(ros_context)
    reader_node = rclpy.create_node("stalled_reader", context=ros_context)
    reader = LockstepReader(reader_node, {"/tip_imu": None})
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(reader_node)
    ex.spin_once(timeout_sec=0.1)
    reader_node.create_subscription(Imu, "/tip_imu", lambda m: reader.took("/tip_imu", time_to_sec(m.header.stamp)),
                                    QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
    # the plant counts the reader from its announcement: the move starts once the plant's side has matched it
    mover.spin_until(lambda: reader.heard, "the plant's subscription of /stalled_reader's acknowledgements")
    deadline = time.monotonic() + 60.0  # and the announcement taken: the plant holds only for a reader it heard
    while "lockstep: reader /stalled_reader counted" not in plant.log_path.read_text():
        assert time.monotonic() < deadline and plant.running(), plant.log_path.read_text()
        time.sleep(0.05)
    assert mover.move(goal(0.1, 0.5, 0.2)) == 0  # the reader is never spun: the plant waits, then goes on
    log = plant.log_path.read_text()
    lines = [ln for ln in log.splitlines() if "/stalled_reader" in ln and " counted from " not in ln]
    assert len(lines) == 1 and "lockstep.reader_timeout" in lines[0], log
    assert "Traceback" not in log
    assert reader.processed is None  # it took nothing: announced only
    ex.shutdown()
    mover.node.destroy_node()
    reader_node.destroy_node()


def _wait_log(proc, text: str, timeout: float = 120.0) -> str:
    """The line of ``proc``'s log holding ``text``, once it is there."""
    deadline = time.monotonic() + timeout
    while True:
        lines = [ln for ln in proc.log_path.read_text().splitlines() if text in ln]
        if lines:
            return lines[-1]
        assert time.monotonic() < deadline and proc.running(), proc.log_path.read_text()
        time.sleep(0.05)


def test_a_reader_paused_past_the_lease_is_counted_from_the_plants_time_when_back(start_node, ros_context,
                                                                               tmp_path):
    """The recorder (on /tip_imu alone) paused until it leaves the graph (the DDS lease): the plant steps on
    without it, and what it sends meanwhile never reaches it. Continued, it is back with its last acknowledgement,
    behind the plant's time; held at it the plant waited for a sample that never comes, until
    lockstep.reader_timeout (here an hour: the goal during which it came back never ended; session 13's walk, 30 s).
    It is counted from the plant's time, and the goals succeed with it waited for; its recording's hole is reported."""
    plant = sim(start_node, ["/recorder"], **{"lockstep.reader_timeout": 3600.0})
    recorder = start_node("shaper_nodes", "recorder", {"output": str(tmp_path / "bag"), "topics": ["/tip_imu"]})
    _wait_log(plant, "lockstep: reader /recorder counted")
    mover = Mover(ros_context)
    assert mover.move(goal(0.1, 0.5, 0.2)) == 0
    os.kill(recorder.proc.pid, signal.SIGSTOP)
    try:  # the plant holds the move a lead beyond the paused recorder until the lease drops it, then completes it
        assert mover.move(goal(-0.1, 0.5, 0.2)) == 0
        _wait_log(plant, "lockstep: reader /recorder went away")
    finally:
        os.kill(recorder.proc.pid, signal.SIGCONT)
    # back in the graph while the plant rests: its last acknowledgement (kept by the topic) reaches a new subscriber.
    # The plant takes it at the first step after its own participant has matched the recorder's again; that match is
    # the plant's discovery, not the test's (the plant saw none in a whole move on a loaded CI run, stop 48, while the
    # test had the acknowledgement and two statuses): the test moves until the plant says so, every move succeeding
    watch = AckWatch(mover.node, "/recorder")
    mover.spin_until(lambda: watch.announced, "the recorder's acknowledgement, re-sent")
    deadline = time.monotonic() + 120.0
    offset = 0.1
    while True:  # the old rule held the plant at what the recorder took before the pause, for ever
        assert mover.move(goal(offset, 0.5, 0.2)) == 0
        offset = -offset
        back = [ln for ln in plant.log_path.read_text().splitlines() if "lockstep: reader /recorder is back" in ln]
        if back:
            break
        assert time.monotonic() < deadline, "the plant never took the recorder back:\n" + plant.log_path.read_text()
    assert len(back) == 1 and "never reach it" in back[0], back
    assert mover.move(goal(offset, 0.5, 0.2)) == 0  # and a move with it waited for
    log = plant.log_path.read_text()
    assert "reader_timeout" not in log and "Traceback" not in log, log
    mover.node.destroy_node()
    # the recording's hole is reported: at close (it said nothing, session 13), and in the metadata
    recorder.stop()
    closed = _wait_log(recorder, "closed ")
    lost = re.search(r"lost (\d+) samples of /tip_imu \(gaps in the stamps\): the recording has holes", closed)
    assert lost and int(lost.group(1)) > 0, closed
    meta = (tmp_path / "bag" / "metadata.yaml").read_text()
    assert f"shaper_nodes.recorder.lost: /tip_imu={lost.group(1)}" in meta, meta


# ---------------------------------------------------------------------- the readers paused, the numbers the same
def _children(pid: int) -> dict[int, str]:
    """The child processes of ``pid``: pid -> command line."""
    out = {}
    for d in pathlib.Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                out[int(d.name)] = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, IndexError, ValueError):
            continue
    return out


def _pause(pid: int) -> None:
    os.kill(pid, signal.SIGSTOP)
    time.sleep(PAUSE)  # the fault injected: a reader that takes nothing for 3 s (no assertion on timing)
    os.kill(pid, signal.SIGCONT)


class ClockWatch:
    """The latest /clock on a domain, followed by a node spun in a thread.

    Only the latest stamp counts: /clock (one message per step, 500 a simulated second) is taken serialized, its
    stamp read from the bytes, and drained every 20 ms of wall time (``subscribe_draining``) rather than waking the
    thread at every step; the pause then lands 0.3 s of simulated time after the dot, give or take those 20 ms
    (a move lasts over 2 s with its rest)."""

    def __init__(self, domain_id: int) -> None:
        self.ctx = rclpy.context.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.node = rclpy.create_node("clock_watch", context=self.ctx, start_parameter_services=False)
        self.clock = 0.0
        subscribe_draining(self.node, Clock, "/clock", self._on_clock, 100, poll=0.02)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on_clock(self, raw: bytes) -> None:
        self.clock = max(self.clock, header_stamp(raw))

    def _spin(self) -> None:
        while self.ctx.ok():
            try:
                self.ex.spin_once(timeout_sec=0.05)
            except Exception:  # the context shut down under it
                return

    def wait_past(self, t: float, timeout: float = 300.0) -> None:
        end = time.monotonic() + timeout
        while self.clock <= t:
            assert time.monotonic() < end, f"/clock did not pass {t:.3f} s"
            time.sleep(0.01)

    def close(self) -> None:
        self.ctx.try_shutdown()
        self.thread.join(5)
        self.ex.shutdown()
        self.node.destroy_node()


def _run_demo(out: pathlib.Path, domain_id: int, pauses: list[str]) -> str:
    """``demo --cases none`` into ``out``; after the k-th move's progress dot, once the arm has moved 0.3 s of
    simulated time further (in the middle of the next move: each lasts over 2 s with its rest), the k-th process of
    ``pauses`` ('client': the demo itself, else a node executable's name) is paused for 3 s. Returns its stdout."""
    watch = ClockWatch(domain_id) if pauses else None  # (the unpaused run waits for no simulated time)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = subprocess.Popen([sys.executable, "-m", "sim_plant_node.demo", "--cases", "none", "--out", str(out)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=0)
    assert proc.stdout is not None
    chunks: list[str] = []
    dots = threading.Semaphore(0)

    def read() -> None:
        """Releases ``dots`` once per progress dot: a dot after the case's "... cycles " and before the "(" of its
        time, outside the nodes' log lines (from "[WARN]" etc. to the line's end: under load the conductor warns
        in the middle of the progress line, and its time stamp has a dot)."""
        assert proc.stdout is not None
        progress = log = False
        while ch := proc.stdout.read(1):
            chunks.append(ch)
            tail = "".join(chunks[-7:])
            if ch == "\n":
                log = False
            elif tail.endswith(("[DEBUG]", "[INFO]", "[WARN]", "[ERROR]", "[FATAL]")):
                log = True
            elif tail == "cycles " and not log:
                progress = True
            elif progress and not log and ch == "(":
                progress = False
            elif progress and not log and ch == ".":
                dots.release()
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        for who in pauses:
            assert watch is not None and dots.acquire(timeout=300), "".join(chunks)
            watch.wait_past(watch.clock + 0.3)
            if who == "client":
                _pause(proc.pid)
                continue
            (pid,) = [p for p, cmd in _children(proc.pid).items() if f"{who} " in cmd or cmd.endswith(who)]
            _pause(pid)
        code = proc.wait(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
        reader.join(10)
        proc.stdout.close()
        if watch is not None:
            watch.close()
    text = "".join(chunks)
    assert code == 0, text
    return text


def _stream(bag: pathlib.Path, topic: str) -> list[bytes]:
    """The serialized messages of ``topic`` in the recording folder ``bag``, in the order written, from the first
    step on (the joint states at rest before the first move, republished every 0.1 s of wall time, are recorded or
    not by when the recorder's subscription matched) to the end of the run (the last cycle event; the plant may
    take a few steps more while the demo stops its nodes, as many as the wall time lets it), and a repeat of the
    message before left out (the same at rest between moves)."""
    (path,) = bag.glob("*.mcap")
    with open(path, "rb") as f:
        end = max(header_stamp(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/cycle_events"]))
    out: list[bytes] = []
    with open(path, "rb") as f:
        for _, _, m in make_reader(f).iter_messages(topics=[topic], log_time_order=False):
            if 0 < header_stamp(m.data) <= end + 1e-9 and (not out or m.data != out[-1]):
                out.append(m.data)
    return out


def test_the_demo_client_identifier_and_recorder_paused_give_the_unpaused_numbers(tmp_path, domain_id,
                                                                                  another_domain_id):
    quiet = _run_demo(tmp_path / "quiet", domain_id, [])
    paused = _run_demo(tmp_path / "paused", another_domain_id, ["client", "identifier", "recorder"])
    for text in (quiet, paused):
        assert "Samples lost: none" in text, text
        assert "Traceback" not in text
    a, b = tmp_path / "quiet", tmp_path / "paused"
    for folder in (a, b):  # the plant waited for every reader: none dropped
        assert "without it" not in (folder / "arm-sim_plant.log").read_text()
    assert (b / "results.csv").read_text() == (a / "results.csv").read_text()
    table = [ln for ln in paused.splitlines() if ln.startswith("| none |")]
    assert table and table == [ln for ln in quiet.splitlines() if ln.startswith("| none |")]
    # the recorder's recording: every IMU sample and joint state, the same bytes
    for topic in ("/tip_imu", "/joint_states"):
        qa, qb = _stream(a / "recording", topic), _stream(b / "recording", topic)
        assert len(qa) > 1000 and qb == qa, topic
    # from the first step on: the demo waited for the recorder's subscriptions before the first goal
    assert header_stamp(_stream(a / "recording", "/tip_imu")[0]) == pytest.approx(1.0 / (2 * RATE), abs=1e-9)
    # the identifier's measure of the cycle
    def measured(folder: pathlib.Path) -> list[str]:
        log = (folder / "arm-identifier.log").read_text()
        return [ln.split("]: ", 1)[-1] for ln in log.splitlines() if "residual RMS" in ln]
    assert measured(a) and measured(b) == measured(a)


def test_calibrate_paused_gives_the_unpaused_report(start_node, tmp_path, domain_id, small_calibration):
    """calibrate paused for 3 s in the middle of its first approach gives the report of the session's uninterrupted
    run (tests/conftest.py's ``small_calibration``: the same plan against the same plant, noise-free, which waits
    for calibrate), to the last digit."""
    quiet, run = small_calibration
    assert run["returncode"] == 0, run["log"]
    assert not SAMPLES_LOST.search(run["log"]), run["log"]
    assert "without it" not in run["plant_log"]  # the plant waited for calibrate, never dropped it
    plant = start_node("sim_plant_node", "sim_plant", SMALL_CALIBRATION_PLANT)
    out = tmp_path / "paused"
    # the watch sees the plant's /clock publisher before calibrate starts: calibrate can be done in 4 s of wall
    # time, less than a late discovery took under load (the watch then never saw the clock move)
    watch = ClockWatch(domain_id)
    try:
        deadline = time.monotonic() + 120.0
        while watch.node.count_publishers("/clock") == 0:
            assert time.monotonic() < deadline, "the watch saw no /clock publisher"
            time.sleep(0.05)
    except BaseException:
        watch.close()
        raise
    proc = start_node("shaper_nodes", "calibrate", SMALL_PLAN, params_file=calibrate_config(),
                      args=["--execute", "--out", str(out), *ONE_WORKER])
    try:  # in the middle of the first pose's approach: 0.3 s of simulated time after its recording began
        deadline = time.monotonic() + 300.0
        while not list((out / "recording").glob("*.partial")):
            assert proc.running() and time.monotonic() < deadline, proc.log_path.read_text()
            time.sleep(0.05)
        watch.wait_past(watch.clock + 0.3)
        _pause(proc.proc.pid)
    finally:
        watch.close()
    code = proc.proc.wait(timeout=600)
    log = proc.log_path.read_text()
    assert code == 0, log
    assert not SAMPLES_LOST.search(log), log
    proc.stop()
    assert "without it" not in plant.log_path.read_text()  # the plant waited for calibrate, never dropped it
    report = json.loads((out / "report.json").read_text())
    assert report == json.loads((quiet / "report.json").read_text())
    assert np.isfinite(report["poses"][0]["modes"][0]["frequency_hz"])
