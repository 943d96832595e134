"""A drift warning (a payload change) drops every move's MRILC correction and restarts its learner, over DDS.

The learner in ``mode: mrilc_moves`` runs as its own process (so that it can be killed with SIGKILL), with the simulated
arm's lifted operator (``sim_plant_node.arm.lifted:arm_operator``, built from each goal as on the arm). The test's peer
(tests/relearn_peer.py, the speed relearn test's too), one real node named ``identifier``, publishes the drift watch's
status on ``/diagnostics`` through the identifier's own reporter (``identifier: drift``, as nodes/identifier.py does),
the cycle events, the tool accelerometer's samples of each move's window (a decaying 8 Hz ring after the motion), serves
the controller's FollowJointTrajectory action (recording each goal it receives) and sends the moves' planned goals to
the learner's proxy. Two moves of the arm, home -> pick and pick -> home, learn a cycle or two each.

Shown: after the moves learned (the controller receives corrected goals), the first WARN drops every move's
correction (one line on /diagnostics names both moves; the state file: no move, ``drift_warned``), once per
episode; the cycle under way (its goal ran with the old correction) is not learned from; each move's next goal
reaches the controller as planned (no correction) and its learner starts again (iteration 1). Killed (SIGKILL)
and started again on the same state file, the learner resumes the relearned state: the same episode's WARN again
changes nothing (the flag was saved), the move that learned after the warning runs with its new correction at
iteration 2 (not the 4 it would have reached without the relearn), the other from scratch.

The payload change on the lockstep arm with the identifier's real warning is the demo's ``payload`` case
(tests/test_demo_payload.py, with the LIST learner); this test drives the MRILC learner's side of it.

Also, on the same rig: a kill -9 during a move (its goal at the controller with the move's correction, half its
residual window measured) resumes every move's correction from its saved state
(:func:`test_a_kill_9_during_a_move_resumes_every_moves_correction_from_its_saved_state`).
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from conftest import RESTARTED
from relearn_peer import Peer
from sensor_msgs.msg import Imu
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import CycleEvent
from shaper_nodes.core.learning.moves import move_key
from shaper_nodes.ros.conversions import sec_to_duration, sec_to_time
from shaper_nodes.ros.diagnostics import OK, WARN
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME, MAX_ACCELERATION, MAX_VELOCITY, PICK, trapezoid_move

pytestmark = pytest.mark.integration

CONTROLLER = "/mrilc_test_controller/follow_joint_trajectory"
MOVES = (trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME))
KEYS = [move_key(m.positions[0], m.positions[-1]) for m in MOVES]
DWELL = 1.5  # s the goal holds its last point after the motion (the arm client's)
WINDOW = 2.0  # s from a move's start the accelerometer's samples cover, and its END (the learner's window: 1.963 s)
INPUTS = ("/cycle_events", "/tip_imu", "/diagnostics")  # the learner's subscriptions


def goal(index: int) -> JointTrajectory:
    """The move's planned goal as the arm client sends it (its points after the start, then the dwell)."""
    m = MOVES[index]
    points = [JointTrajectoryPoint(positions=p.tolist(), velocities=v.tolist(), accelerations=a.tolist(),
                                   time_from_start=sec_to_duration(float(t)))
              for t, p, v, a in zip(m.times[1:], m.positions[1:], m.velocities[1:], m.accelerations[1:], strict=True)]
    points.append(JointTrajectoryPoint(positions=m.positions[-1].tolist(), velocities=[0.0] * 6,
                                       accelerations=[0.0] * 6, time_from_start=sec_to_duration(m.duration + DWELL)))
    return JointTrajectory(joint_names=list(JOINT_NAMES), points=points)


def correction(sent: JointTrajectory, index: int) -> float:
    """The largest difference between the positions the controller received and the planned ones, rad."""
    got = np.array([p.positions for p in sent.points])
    planned = np.array([p.positions for p in goal(index).points])
    assert got.shape == planned.shape
    return float(np.max(np.abs(got - planned)))


def accelerometer(peer: Peer, t0: float, index: int, upto: float) -> None:
    """The tool accelerometer of move ``index`` started at ``t0``, every ms up to ``upto`` s after it: gravity, and
    after the motion a decaying 8 Hz ring."""
    end = float(MOVES[index].duration)
    for k in range(int(round(upto / 1e-3)) + 1):  # every ms, as the learner's grid
        t = 1e-3 * k
        msg = Imu()
        msg.header.stamp = sec_to_time(t0 + t)
        ring = 0.05 * math.exp(-(t - end) / 0.4) * math.sin(2 * math.pi * 8.0 * (t - end)) if t > end else 0.0
        msg.linear_acceleration.x, msg.linear_acceleration.z = ring, 9.81 + 0.5 * ring
        peer.imu.publish(msg)


def event(peer: Peer, kind: int, cycle: int, t: float, index: int) -> None:
    """A cycle event of move ``index``."""
    m = MOVES[index]
    peer.event(kind, cycle, t, JOINT_NAMES, m.positions[0], m.positions[-1])


def finish_cycle(peer: Peer, cycle: int, index: int) -> dict[str, float]:
    """The rest of a cycle after its goal: the accelerometer's window, MOTION_END, END; the learner's report."""
    t0 = 100.0 + 10.0 * cycle
    accelerometer(peer, t0, index, WINDOW)
    event(peer, CycleEvent.MOTION_END, cycle, t0 + float(MOVES[index].duration), index)
    event(peer, CycleEvent.END, cycle, t0 + WINDOW, index)
    return peer.report(cycle)


def run_cycle(peer: Peer, cycle: int, index: int, before_end=None,
              sent: list[JointTrajectory] | None = None) -> tuple[dict[str, float], float]:
    """One move as one cycle (START, its goal through the learner's proxy, the accelerometer's window, END); the
    learner's report (name -> value) and how far the goal the controller received is from the plan (rad).
    ``before_end`` runs after the goal, before the END; ``sent`` gets what the controller received."""
    event(peer, CycleEvent.START, cycle, 100.0 + 10.0 * cycle, index)
    got = peer.run_goal(goal(index), f"the goal of cycle {cycle}")
    if sent is not None:
        sent.append(got)
    if before_end is not None:
        before_end()
    return finish_cycle(peer, cycle, index), correction(got, index)


def learner_params(state) -> dict:
    """The learner's parameters (its own process), its state in ``state``."""
    return {"mode": "mrilc_moves", "state_file": str(state), "topics.imu_reliable": True, "end_wait": 10.0,
            "mrilc_moves.operator": "sim_plant_node.arm.lifted:arm_operator", "mrilc_moves.controller": CONTROLLER,
            "mrilc_moves.velocity": [MAX_VELOCITY], "mrilc_moves.acceleration": [MAX_ACCELERATION],
            "mrilc_moves.match_timeout": 30.0, "mrilc_moves.action_timeout": 60.0}


def test_a_drift_warning_drops_every_moves_correction_and_a_kill_9_resumes_the_relearned_state(
        start_node, ros_context, tmp_path):
    state = tmp_path / "learner_state.json"
    params = learner_params(state)
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, CONTROLLER, imu=True)

    def up(before: set[bytes]) -> bool:
        return peer.learner_up(INPUTS, before)

    def saved() -> dict:
        return json.loads(state.read_text())

    try:
        peer.spin_until(lambda: up(set()), "the learner's subscriptions and action server")

        # each move learns: its first goal goes as planned, its second with its correction
        first = [run_cycle(peer, 0, 0), run_cycle(peer, 1, 1)]
        assert [(m["iteration"], m["max_correction_rad"], moved) for m, moved in first] == [(1.0, 0.0, 0.0)] * 2
        m, moved = run_cycle(peer, 2, 0)
        assert m["iteration"] == 2.0 and m["max_correction_rad"] > 0.0 and moved > 0.0 and m["limit_excess"] == 0.0
        assert sorted(saved()["moves"]) == sorted(KEYS) and saved()["drift_warned"] is False

        # pick -> home runs with its correction; the identifier's WARN comes before its END
        def warn() -> None:
            peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                    " (3 cycles in a row)", [("cycle", "7"), ("mode_hz", "7.1")])
            peer.spin_until(lambda: peer.status("learner: moves", 1, "relearning the correction of 2 moves")
                            is not None, "the relearn's status on /diagnostics")
            peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                    " (4 cycles in a row)", [("cycle", "8"), ("mode_hz", "7.1")])

        m, moved = run_cycle(peer, 3, 1, warn)
        assert moved > 0.0  # its goal ran with the correction dropped at the WARN: not learned from
        assert m == {"skipped": 1.0}, m
        relearned = peer.status("learner: moves", 1, "relearning the correction of 2 moves")
        assert relearned is not None
        line = relearned.message
        assert all(k in line for k in KEYS) and "identifier: drift" in line and "\n" not in line, line
        doc = saved()
        assert doc["moves"] == {} and doc["drift_warned"] is True  # every move's learner dropped, saved with it

        # home -> pick's next goal goes as planned, its learner from scratch; the repeated WARN changed nothing
        m, moved = run_cycle(peer, 4, 0)
        assert (m["iteration"], m["max_correction_rad"], moved) == (1.0, 0.0, 0.0), (m, moved)
        assert sum("relearning" in s.message for s in peer.statuses if s.name == "learner: moves") == 1
        doc = saved()
        assert list(doc["moves"]) == [KEYS[0]] and doc["moves"][KEYS[0]]["learner"]["cycle"] == 2
        assert doc["drift_warned"] is True

        # kill -9, and start again on the same state file
        before = peer.learner_subscriptions(INPUTS)
        assert learner.proc is not None
        learner.proc.kill()
        learner.proc.wait(timeout=30)
        peer.statuses.clear()
        start_node("shaper_nodes", "learner", params, env=RESTARTED)
        peer.spin_until(lambda: up(before), "the restarted learner's subscriptions and action server")
        # the same episode's WARN: nothing (the flag was saved); its OK ends the episode (saved)
        peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                " (5 cycles in a row)", [("cycle", "9"), ("mode_hz", "7.1")])
        peer.identifier.publish("drift", OK, "cycle 10: the mode is inside the working band")
        peer.spin_until(lambda: saved()["drift_warned"] is False, "the OK's save")
        assert list(saved()["moves"]) == [KEYS[0]]

        # home -> pick resumes its relearned state (iteration 2, corrected); pick -> home starts from scratch
        m, moved = run_cycle(peer, 5, 0)
        assert m["iteration"] == 2.0 and m["max_correction_rad"] > 0.0 and moved > 0.0, (m, moved)
        m, moved = run_cycle(peer, 6, 1)
        assert (m["iteration"], m["max_correction_rad"], moved) == (1.0, 0.0, 0.0), (m, moved)
        assert not any(s.name == "learner: moves" and "relearning" in s.message for s in peer.statuses)
        peer.spin_until(lambda: any(f"move {KEYS[0]}: resumes at cycle 2 from its saved state" in line
                                    for line in peer.logs), "the restarted learner's line of the move it resumed")
    finally:
        peer.destroy()


def test_the_episode_flag_is_checked_and_an_empty_status_watches_nothing(ros_context, tmp_path):
    """A saved flag that is not true or false is refused with one line naming it; ``mrilc_moves.drift_status: ''``
    leaves /diagnostics unwatched (in-process)."""
    from rclpy.parameter import Parameter

    from shaper_nodes.nodes.learner import LearnerNode

    path = tmp_path / "state.json"
    path.write_text(json.dumps({"version": 1, "per_move": "mrilc", "moves": {}, "drift_warned": "yes"}))
    params = [Parameter("mode", value="mrilc_moves"), Parameter("state_file", value=str(path)),
              Parameter("mrilc_moves.operator", value="sim_plant_node.arm.lifted:arm_operator")]
    node = LearnerNode(context=ros_context, parameter_overrides=params)
    try:
        assert "drift_warned must be true or false, got 'yes'" in node.state_problem
        assert "\n" not in node.state_problem and node.mode.moves == {} and node.mode.drift.warned is False
    finally:
        node.destroy_node()
    path.write_text(json.dumps({"version": 1, "per_move": "mrilc", "moves": {}, "drift_warned": True}))
    node = LearnerNode(context=ros_context, parameter_overrides=[
        *params, Parameter("mrilc_moves.drift_status", value="")])
    try:
        assert node.state_problem == "" and node.mode.drift.warned is True and node.mode.drift.status == ""
        assert all(sub.topic_name != "/diagnostics" for sub in node.subscriptions)
    finally:
        node.destroy_node()


def corrected(index: int, saved: dict) -> np.ndarray:
    """The positions of move ``index``'s planned goal with the correction of its learner as ``saved`` in the state
    file (its coefficients on the move's B-splines, the learner's default plan settings), rad."""
    from shaper_nodes.core.learning.mrilc.plan import PlanSettings, plan_move
    from shaper_nodes.ros.conversions import duration_to_sec

    traj = goal(index)
    t = np.array([duration_to_sec(p.time_from_start) for p in traj.points])
    q, v, a = (np.array([getattr(p, f) for p in traj.points]) for f in ("positions", "velocities", "accelerations"))
    plan = plan_move(t, q, v, a, MOVES[index].positions[0], PlanSettings())
    dq, _, _ = plan.profile.correction(np.asarray(saved["learner"]["coefficients"], dtype=float))
    return q + dq


def test_a_kill_9_during_a_move_resumes_every_moves_correction_from_its_saved_state(start_node, ros_context, tmp_path):
    """The learner is killed (SIGKILL) while a goal of a move runs at the controller with the move's correction and half
    its residual window is measured (:meth:`relearn_peer.Peer.kill_during_move`: the controller finishes the goal,
    the state file was not written since the last END and parses, the client's result never comes from the killed
    server, and the restarted learner answers the goal's result ``STATUS_UNKNOWN``, no hang). Started again on the
    same state file: the interrupted cycle's END is not learned from (END without its START); each move's next
    goal reaches the controller with the correction saved in the state file (its coefficients on the move's
    B-splines added to the plan), the same points as before the kill, and its learner resumes at the iteration
    after its last saved one."""
    state = tmp_path / "learner_state.json"
    params = learner_params(state)
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, CONTROLLER, imu=True)
    sent: list[JointTrajectory] = []

    def saved() -> dict:
        return json.loads(state.read_text())["moves"]

    try:
        peer.spin_until(lambda: peer.learner_up(INPUTS, set()), "the learner's subscriptions and action server")
        for cycle, index, iteration in ((0, 0, 1.0), (1, 1, 1.0), (2, 0, 2.0)):
            m, _ = run_cycle(peer, cycle, index, sent=sent)
            assert m["iteration"] == iteration and m["limit_excess"] == 0.0, (cycle, m)
        before = saved()
        assert [before[k]["learner"]["cycle"] for k in KEYS] == [3, 2]

        # cycle 3, home -> pick with its correction: killed while the controller runs its goal, half its window
        t0 = 130.0
        event(peer, CycleEvent.START, 3, t0, 0)
        half = float(MOVES[0].duration) + 0.5 * (WINDOW - float(MOVES[0].duration))
        restart = functools.partial(start_node, "shaper_nodes", "learner", params, env=RESTARTED)
        killed = peer.kill_during_move(learner, restart, INPUTS, goal(0), lambda _: accelerometer(peer, t0, 0, half),
                                       state, "the goal of cycle 3")
        assert saved() == before  # the interrupted cycle not learned from
        want = [corrected(i, before[k]) for i, k in enumerate(KEYS)]
        got = np.array([p.positions for p in killed.points])
        assert correction(killed, 0) > 0.0
        np.testing.assert_allclose(got, want[0], rtol=0, atol=1e-12)
        assert finish_cycle(peer, 3, 0) == {"skipped": 1.0}  # the interrupted cycle's END at the restarted learner

        # every move resumes from its saved state: its saved correction at the controller, the next iteration
        for cycle, index, iteration in ((4, 0, 3.0), (5, 1, 2.0)):
            m, moved = run_cycle(peer, cycle, index, sent=sent)
            assert m["iteration"] == iteration and moved > 0.0 and m["limit_excess"] == 0.0, (cycle, m)
            got = np.array([p.positions for p in sent[-1].points])
            np.testing.assert_allclose(got, want[index], rtol=0, atol=1e-12)
        assert [p.positions for p in sent[-2].points] == [p.positions for p in killed.points]
        for k in KEYS:
            peer.spin_until(lambda k=k: any(f"move {k}: resumes at cycle" in line for line in peer.logs),
                            f"the restarted learner's line of move {k}")
        assert [saved()[k]["learner"]["cycle"] for k in KEYS] == [4, 3]
    finally:
        peer.destroy()
