"""send_goal against the simulated arm's joint_trajectory_controller emulation, over DDS (the real action).

The ``send_goal`` executable runs as a process, as a user runs it; the sim plant (arm, lockstep) serves
``/joint_trajectory_controller/follow_joint_trajectory``. Each outcome is one line naming it: success with
the controller's code and text, a rejection, an abort with the controller's code (its name) and text, a
server or joint states that never come, bad input.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState

from shaper_nodes.cli.send_goal import main, trajectory_points
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME

ACTION = "/joint_trajectory_controller/follow_joint_trajectory"
GOAL = [0.3, -1.57, 1.8, -1.8, -1.57, 0.0]


def sim(start_node, **extra):
    return start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "mode": "lockstep", "rate": 500.0,
                                                      "task.start": HOME.tolist(), **extra})


def send_goal(start_node, args: list[str], timeout: float = 300.0) -> tuple[int, str]:
    proc = start_node("shaper_nodes", "send_goal", {}, args=args)
    try:
        code = proc.proc.wait(timeout=timeout)
    finally:
        proc.stop()
    return code, proc.log_path.read_text()


def goal_args(positions=GOAL, joints=JOINT_NAMES, *extra: str) -> list[str]:
    return ["--action", ACTION, "--joints", *joints, "--positions", *[str(p) for p in positions],
            "--duration", "1.5", *extra]


def joint_states(ros_context, until, timeout: float = 120.0) -> np.ndarray:
    """The arm's positions from the first joint state for which ``until`` holds."""
    node = rclpy.create_node("probe", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    got: list[np.ndarray] = []

    def on_state(msg):
        q = np.array([msg.position[list(msg.name).index(j)] for j in JOINT_NAMES])
        if until(q):
            got.append(q)

    node.create_subscription(JointState, "/joint_states", on_state, 10)
    try:
        deadline = time.monotonic() + timeout
        while not got:
            assert time.monotonic() < deadline, "no joint state as expected"
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
    return got[0]


def test_a_goal_from_the_present_pose_succeeds_and_the_arm_gets_there(start_node, ros_context):
    sim(start_node)
    code, log = send_goal(start_node, goal_args(GOAL, JOINT_NAMES, "--from-current", "--hold", "0.5"))
    assert code == 0, log
    assert "send_goal: sending 3 point(s) over 2 s to " + ACTION in log, log
    assert "send_goal: succeeded: error_code 0 (SUCCESSFUL) 'Goal successfully reached!'" in log, log
    q = joint_states(ros_context, lambda q: np.allclose(q, GOAL, atol=1e-3))
    assert q == pytest.approx(GOAL, abs=1e-3)
    # a goal of one point: the controller interpolates from where the arm is, and the goal is reached
    code, log = send_goal(start_node, goal_args(HOME.tolist()))
    assert code == 0 and "sending 1 point(s) over 1.5 s" in log and "succeeded" in log, log
    # a joint the controller does not have: rejected, and the line says so
    code, log = send_goal(start_node, goal_args(GOAL, [*JOINT_NAMES[:-1], "gripper_joint"]))
    assert code == 1, log
    assert f"send_goal: rejected: {ACTION} rejected the goal" in log, log


def test_cycle_marks_the_goal_on_cycle_events_stamped_on_the_sims_clock(start_node, ros_context):
    """``--cycle N``: START before the goal at the stamp of the arm's joint states at rest (the lockstep sim does
    not step between goals, so the motion starts there), MOTION_END --duration and END --duration + --hold
    later, each naming the task, the joints, the start pose and the goal, as a learner per move wants them."""
    from shaper_msgs.msg import CycleEvent

    sim(start_node)
    node = rclpy.create_node("probe", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    events: list[CycleEvent] = []
    states: list[tuple[float, np.ndarray]] = []

    def on_state(msg):
        states.append((msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec,
                       np.array([msg.position[list(msg.name).index(j)] for j in JOINT_NAMES])))

    node.create_subscription(CycleEvent, "/cycle_events", events.append, 10)
    node.create_subscription(JointState, "/joint_states", on_state, 1000)
    deadline = time.monotonic() + 120.0
    while not states:  # the arm at rest, seen before the goal
        assert time.monotonic() < deadline, "no joint state of the arm at rest"
        executor.spin_once(timeout_sec=0.05)
    proc = start_node("shaper_nodes", "send_goal", {}, args=goal_args(
        GOAL, JOINT_NAMES, "--from-current", "--hold", "0.5", "--cycle", "3", "--task", "pick"))
    try:
        deadline = time.monotonic() + 300.0
        while proc.proc.poll() is None or len(events) < 3:
            assert time.monotonic() < deadline, f"send_goal and its three marks: {events}"
            executor.spin_once(timeout_sec=0.05)
        log = proc.log_path.read_text()
        assert proc.proc.returncode == 0 and "succeeded" in log, log
        assert [e.event for e in events] == [CycleEvent.START, CycleEvent.MOTION_END, CycleEvent.END]
        t = [e.header.stamp.sec + 1e-9 * e.header.stamp.nanosec for e in events]
        assert t[1] - t[0] == pytest.approx(1.5, abs=1e-6) and t[2] - t[0] == pytest.approx(2.0, abs=1e-6)
        assert f"marked cycle 3 of 'pick' on /cycle_events: START at {t[0]:.3f} s" in log, log
        for e in events:
            assert e.cycle == 3 and e.task == "pick" and list(e.joint_names) == list(JOINT_NAMES)
            assert list(e.start_positions) == pytest.approx(HOME.tolist(), abs=1e-3)
            assert list(e.goal_positions) == pytest.approx(GOAL, abs=1e-12)
        # the motion starts at START on the sim's clock: at rest at HOME up to it, moving after it
        deadline = time.monotonic() + 60.0
        while not states or states[-1][0] < t[2] - 0.01:
            assert time.monotonic() < deadline, "joint states up to the END"
            executor.spin_once(timeout_sec=0.05)
        before = [q for ts, q in states if ts <= t[0]]
        after = [q for ts, q in states if t[0] + 0.2 <= ts <= t[1]]
        assert before and np.allclose(before[-1], before[0], atol=1e-9), (t, [ts for ts, _ in states[:5]], len(states))
        assert after and np.max(np.abs(after[-1] - before[-1])) > 0.05
        at_end = [q for ts, q in states if ts >= t[2] - 0.01]
        assert at_end and at_end[0] == pytest.approx(GOAL, abs=1e-2)
    finally:
        proc.stop()
        executor.shutdown()
        node.destroy_node()


def test_cycle_marks_reach_every_subscriber_in_the_graph(start_node, domain_id):
    """Three subscribers of /cycle_events, each its own DDS participant (as the learner, the identifier and the
    recorder are), started just before the goal: each gets MOTION_END and END, and the cycle's START, either itself
    or as the START's stamp the later marks carry (a listener send_goal's graph did not name yet when START went
    out: the learners stand in for it, ros/cycle_events.py). START waits until every subscriber the graph names has
    matched, for CycleMarks' settle time (the rule: the unit test below); a listener discovered later than that can
    still miss it (session 15: one of three, once, in a suite on two busy cores), which is why the marks repeat it."""
    from shaper_msgs.msg import CycleEvent

    def start_of(m: CycleEvent) -> tuple[int, int]:
        stamp = m.start_stamp[0] if m.start_stamp else m.header.stamp
        return stamp.sec, stamp.nanosec

    sim(start_node)
    listeners = []
    for k in range(3):
        ctx = rclpy.context.Context()
        rclpy.init(context=ctx, domain_id=domain_id)
        node = rclpy.create_node(f"listener_{k}", context=ctx, start_parameter_services=False)
        got: list[tuple[int, tuple[int, int]]] = []
        node.create_subscription(CycleEvent, "/cycle_events", lambda m, got=got: got.append((m.event, start_of(m))),
                                 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        listeners.append((ctx, node, ex, got))
    proc = start_node("shaper_nodes", "send_goal", {}, args=goal_args(
        GOAL, JOINT_NAMES, "--from-current", "--hold", "0.5", "--cycle", "0"))
    try:
        deadline = time.monotonic() + 300.0
        # until the sender is done and every listener has the cycle's END (the last mark)
        while proc.proc.poll() is None or any(not got or got[-1][0] != CycleEvent.END for *_, got in listeners):
            assert time.monotonic() < deadline, [got for *_, got in listeners]
            for _, _, ex, _ in listeners:
                ex.spin_once(timeout_sec=0.01)
        assert proc.proc.returncode == 0, proc.log_path.read_text()
        assert "WARNING" not in proc.log_path.read_text()
        events = [[e for e, _ in got] for *_, got in listeners]
        for seen in events:
            assert seen in ([CycleEvent.START, CycleEvent.MOTION_END, CycleEvent.END],
                            [CycleEvent.MOTION_END, CycleEvent.END]), events
        assert any(seen[0] == CycleEvent.START for seen in events), events  # START went out, and was heard
        starts = {stamp for *_, got in listeners for _, stamp in got}
        assert len(starts) == 1, [got for *_, got in listeners]  # one cycle start, the same for every listener
    finally:
        proc.stop()
        for ctx, node, ex, _ in listeners:
            ex.shutdown()
            node.destroy_node()
            ctx.try_shutdown()


def test_start_waits_until_every_subscriber_the_graph_names_has_matched_for_the_settle_time(monkeypatch):
    """CycleMarks.matched_all, the rule START waits on, with the graph and the clock played: not before one
    subscriber, not at the first match, not before every subscriber the graph names has matched, and only after
    SETTLE s of that; a subscriber the graph names later starts the wait again."""
    from types import SimpleNamespace

    from shaper_nodes.cli import cycle_marks

    clock = [100.0]
    monkeypatch.setattr(cycle_marks.time, "monotonic", lambda: clock[0])
    graph = {"matched": 0, "named": 0}
    marks = object.__new__(cycle_marks.CycleMarks)
    marks.pub = SimpleNamespace(get_subscription_count=lambda: graph["matched"])
    marks.node = SimpleNamespace(count_subscribers=lambda topic: graph["named"])
    marks.spec, marks._matched_since = cycle_marks.CycleSpec(0, "task"), None

    def after(dt: float, **state: int) -> bool:
        clock[0] += dt
        graph.update(state)
        return marks.matched_all()

    assert not after(0.0)  # nobody
    assert not after(1.0, named=3, matched=1)  # the first match
    assert not after(1.0, matched=3)  # every one named: the settle time starts
    assert not after(cycle_marks.SETTLE - 0.01)
    assert not after(0.005, named=4)  # a fourth named: not every one matched
    assert not after(0.1, matched=4)  # matched again: the settle time starts again
    assert not after(cycle_marks.SETTLE - 0.01)
    assert after(0.02)


def test_an_aborted_goal_prints_the_controllers_code_its_name_and_its_text(start_node):
    sim(start_node, **{"jtc.trajectory_tolerance": [1e-6]})  # every move violates the path tolerance
    code, log = send_goal(start_node, goal_args(GOAL, JOINT_NAMES, "--from-current"))
    assert code == 1, log
    assert ("send_goal: aborted: error_code -4 (PATH_TOLERANCE_VIOLATED) 'Aborted due to path tolerance"
            " violation'") in log, log


def test_what_does_not_come_is_named_in_one_line(start_node):
    code, log = send_goal(start_node, goal_args(GOAL, JOINT_NAMES, "--timeout", "3"))
    assert code == 1 and log.strip().splitlines()[-1] == (
        f"send_goal: no FollowJointTrajectory server {ACTION} within 3 s"), log
    code, log = send_goal(start_node, goal_args(GOAL, JOINT_NAMES, "--from-current", "--timeout", "3"))
    assert code == 1 and log.strip().splitlines()[-1] == (
        f"send_goal: no joint states naming {', '.join(JOINT_NAMES)} on /joint_states within 3 s"), log


@pytest.mark.parametrize(("stop", "answer"), [("SIGINT", "delivered"), ("SIGINT", "lost"), ("SIGTERM", "delivered"),
                                              ("timeout", "lost")])
def test_a_goal_out_is_cancelled_at_the_controller_on_ctrl_c_or_a_wait_run_out(start_node, ros_context, stop,
                                                                                answer):
    """The controller (a test peer on the real action) accepts the goal and runs it until cancelled. Ctrl-C
    (SIGINT) or SIGTERM cancels it; with the controller's answer to the goal lost (and its status: the client
    cannot learn it was accepted), Ctrl-C or ``--timeout`` running out on the answer cancels it by the goal id it
    was sent with."""
    import signal

    from test_calibrate_stops import StuckController, wait_for

    peer = StuckController(ros_context, mute=answer == "lost")
    try:
        proc = start_node("shaper_nodes", "send_goal", {}, args=goal_args(GOAL, JOINT_NAMES, "--timeout", "10"))
        wait_for(lambda: peer.goals >= 1, "the goal at the controller", proc=proc)
        if answer == "delivered":  # the answer in at send_goal (it asked for the result), not only the goal out
            wait_for(peer.answered, "send_goal's request for the goal's result", proc=proc)
            assert "send_goal: accepted by " in proc.log_path.read_text()
        if stop != "timeout":  # (pytest's workers ignore SIGINT, and so do the processes they start, unless they
            proc.proc.send_signal(getattr(signal, stop))  # handle it: a background job of a shell the same)
        code = proc.proc.wait(timeout=120.0)
        log = proc.log_path.read_text()
        wait_for(lambda: peer.cancels >= 1, "the cancel at the controller", proc=proc)
        assert peer.cancels == 1 and "Traceback" not in log, log
        line = log.strip().splitlines()[-1]
        head = (f"send_goal: cancelled by {stop}" if stop != "timeout"
                else f"send_goal: no answer from {ACTION} to the goal within 10 s")
        assert code == {"SIGINT": 130, "SIGTERM": 143, "timeout": 1}[stop], log
        assert line == head + "; the goal was cancelled at the controller" + (
            " (by its goal id: its answer had not come)" if answer == "lost" else ""), log
    finally:
        peer.close()


VALID = {"--positions": [str(p) for p in GOAL], "--duration": ["1"]}


@pytest.mark.parametrize(("change", "words"), [
    ({"--positions": ["0", "1"]}, "--positions needs one value per joint (6), got 2"),
    ({"--positions": ["0", "1", "2", "3", "4", "nan"]}, "--positions: 'nan' is not finite"),
    ({"--positions": ["0", "1", "2", "3", "4", "x"]}, "--positions: 'x' is not a number"),
    ({"--duration": ["0"]}, "--duration must be finite and > 0, got '0'"),
    ({"--hold": ["-1"]}, "--hold must be >= 0, got -1"),
    ({"--cycle": ["2"]}, "--cycle needs --hold > 0"),
    ({"--cycle": ["-1"], "--hold": ["1"]}, "--cycle must be >= 0, got '-1'"),
])
def test_bad_input_is_one_line_and_exit_2_before_anything_starts(capsys, change, words):
    argv = ["send_goal", "--action", ACTION, "--joints", *JOINT_NAMES]
    argv += [x for key, values in {**VALID, **change}.items() for x in (key, *values)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err


def test_the_trajectory_starts_at_the_present_pose_ends_at_rest_and_holds():
    pts = trajectory_points([1.0, 2.0], 2.0, start=[0.0, 0.5], hold=1.5)
    assert pts == [(0.0, [0.0, 0.5]), (2.0, [1.0, 2.0]), (3.5, [1.0, 2.0])]
    assert trajectory_points([1.0], 2.0) == [(2.0, [1.0])]
    assert math.isclose(trajectory_points([1.0], 0.25, hold=0.0)[-1][0], 0.25)
