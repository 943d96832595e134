"""A drift warning (a payload change) starts every move's speed-up again at the planned speed, over DDS.

The learner in ``mode: speed_moves`` (its FollowJointTrajectory proxy in front of a test controller that serves the real
control_msgs interface and records each goal it receives), and a peer named ``identifier`` that publishes the drift
watch's status on ``/diagnostics`` through the identifier's own reporter (``identifier: drift``, as nodes/identifier.py
does; tests/relearn_peer.py, the MRILC relearn test's too), all real nodes in one process. The learner starts from a
state file of two moves that learned to run 1.4 times faster (between a good 1.2 and a failed 1.6). Shown: a goal of a
move runs at its saved factor (the controller receives the motion 1.4 times shorter); at the first WARN every move's
factor starts again from 1 (state file: factor 1, nothing good or failed, no peaks measured, ``drift_warned``), once
per episode; the cycle
under way (its goal ran at 1.4) is not learned from; the next goal of a move runs as planned (factor 1); a restarted
learner reads the episode flag back, and a state file whose flag is not a boolean is refused with one line naming it.

The payload change on the lockstep arm itself, with the identifier's real warning, is the demo's ``payload`` case
(tests/test_demo_payload.py runs it with the LIST learner); this test drives the speed learner's side of it.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from conftest import RESTARTED
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from relearn_peer import Peer
from sensor_msgs.msg import Imu
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import CycleEvent
from shaper_nodes.core.learning.moves import MoveStore, move_key, store_from_doc
from shaper_nodes.core.learning.speed import SpeedLearner, SpeedSettings
from shaper_nodes.ros.conversions import duration_to_sec, sec_to_duration, sec_to_time
from shaper_nodes.ros.diagnostics import OK, WARN

pytestmark = pytest.mark.integration

NAMES = ["j1", "j2"]
MOVES = (([0.0, 0.0], [1.0, 0.5]), ([1.0, 0.5], [0.0, 0.0]))
CONTROLLER = "/speed_test_controller/follow_joint_trajectory"
MOTION = 1.0  # s, the planned motion (a cosine ramp: 1.57 rad/s, 4.9 rad/s^2 at most; ceiling 1.75)
SAVED = 1.4  # the moves' saved factor


def plan(move: int) -> JointTrajectory:
    """The move's planned trajectory: a cosine ramp over MOTION s, then a hold point 0.5 s later."""
    start, goal = (np.asarray(p) for p in MOVES[move])
    t = np.linspace(0.0, MOTION, 21)
    q = start + np.outer(0.5 * (1.0 - np.cos(math.pi * t / MOTION)), goal - start)
    points = [JointTrajectoryPoint(positions=row.tolist(), time_from_start=sec_to_duration(float(ti)))
              for ti, row in zip(t, q, strict=True)]
    points.append(JointTrajectoryPoint(positions=goal.tolist(), time_from_start=sec_to_duration(MOTION + 0.5)))
    return JointTrajectory(joint_names=NAMES, points=points)


def motion_end(traj: JointTrajectory) -> float:
    """The time of the trajectory's last moving point (the one before the hold), s."""
    return duration_to_sec(traj.points[-2].time_from_start)


def state_doc() -> dict:
    """The learner's state file: both moves at factor 1.4, good at 1.2, failed at 1.6."""
    store = MoveStore()
    for start, goal in MOVES:
        entry, _ = store.entry(start, goal)
        sp = SpeedLearner(SpeedSettings(step=0.2, ceiling=2.0))
        sp.factor, sp.good, sp.failed = SAVED, 1.2, 1.6
        sp.record(1.2, {"effort": [50.0, 20.0], "velocity": [1.9, 0.9]})  # (the peaks measured: forgotten too)
        entry.speed_state, entry.cycles = sp.to_dict(), 4
    return {"version": 1, "per_move": "speed", "moves": store.to_doc(),
            "joint_names": {move_key(s, g): NAMES for s, g in MOVES}}


def learner_params(path) -> list[Parameter]:
    values = {"mode": "speed_moves", "state_file": str(path), "end_wait": 0.0, "speed.controller": CONTROLLER,
              "speed.scheduler": "", "speed.frequency_hz": 10.0, "speed.match_timeout": 30.0}
    return [Parameter(k, value=v) for k, v in values.items()]


def event(peer: Peer, kind: int, cycle: int, t: float, move: int) -> None:
    """A cycle event of the move."""
    peer.event(kind, cycle, t, NAMES, *MOVES[move], task="speed")


def test_a_drift_warning_starts_every_moves_speed_again_at_the_planned_speed(ros_context, tmp_path):
    from shaper_nodes.nodes.learner import LearnerNode

    path = tmp_path / "learner_state.json"
    path.write_text(json.dumps(state_doc()))
    learner = LearnerNode(context=ros_context, parameter_overrides=learner_params(path))
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(learner)
    peer = Peer(ros_context, CONTROLLER, ex)
    mode = learner.mode
    keys = [move_key(s, g) for s, g in MOVES]
    try:
        peer.spin_until(lambda: peer.node.count_subscribers("/diagnostics") >= 2
                        and peer.events.get_subscription_count() >= 1 and peer.client.server_is_ready()
                        and mode.proxy._client.server_is_ready(),
                        "the learner's subscriptions, its action server, and the controller's seen by it")
        assert [e.speed().factor for e in mode.store] == [SAVED, SAVED] and not mode.drift.warned

        # a cycle under way: its goal runs at the saved factor (the motion 1.4 times shorter at the controller)
        event(peer, CycleEvent.START, 1, 10.0, 0)
        peer.spin_until(lambda: 1 in mode.cycles.open, "the learner's START of cycle 1")
        scaled = peer.run_goal(plan(0))
        assert motion_end(scaled) == pytest.approx(MOTION / SAVED, abs=1e-6)

        # the identifier's WARN: every move starts again at factor 1, once
        peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                " (3 cycles in a row)", [("cycle", "7"), ("mode_hz", "9.7")])
        peer.spin_until(lambda: any("relearning the speed of 2 moves" in m for m in peer.logs),
                        "the learner's log line")
        line = next(m for m in peer.logs if "relearning the speed of 2 moves" in m)
        assert all(k in line for k in keys) and "identifier: drift" in line and "\n" not in line, line
        peer.spin_until(lambda: any(st.name == "learner: moves" and st.message == line for st in peer.statuses),
                        "the relearn's status on /diagnostics")
        doc = json.loads(path.read_text())
        assert doc["drift_warned"] is True
        store, problems = store_from_doc(doc["moves"])
        assert problems == {} and len(store) == 2
        for e in store:
            sp = e.speed()
            assert sp is not None and (sp.factor, sp.good, sp.failed, e.cycles) == (1.0, None, None, 0), e
            assert sp.peaks == {} and sp.cap is None  # the torques measured on the old payload no longer predict

        # the WARN repeated: nothing more; the cycle under way (its goal ran at 1.4) is not learned from
        peer.identifier.publish("drift", WARN, "the mode has drifted out of the active shaper's working band"
                                " (4 cycles in a row)", [("cycle", "8"), ("mode_hz", "9.7")])
        event(peer, CycleEvent.END, 1, 12.0, 0)
        assert peer.report(1) == {"skipped": 1.0}
        assert mode.drift.resets == 1 and sum("relearning" in m for m in peer.logs) == 1

        # the next goal of each move runs as planned (factor 1)
        for cycle, move in ((2, 1), (3, 0)):
            event(peer, CycleEvent.START, cycle, 20.0 + 10 * cycle, move)
            peer.spin_until(lambda c=cycle: c in mode.cycles.open, f"the learner's START of cycle {cycle}")
            sent = peer.run_goal(plan(move))
            assert motion_end(sent) == pytest.approx(MOTION, abs=1e-6)
            assert [duration_to_sec(p.time_from_start) for p in sent.points] == \
                [duration_to_sec(p.time_from_start) for p in plan(move).points]

        # an OK ends the episode (saved), so that a restarted learner acts on the next WARN
        peer.identifier.publish("drift", OK, "cycle 10: the mode is inside the working band")
        peer.spin_until(lambda: not mode.drift.warned, "the OK read")
        assert json.loads(path.read_text())["drift_warned"] is False
    finally:
        ex.shutdown()
        peer.destroy()
        learner.destroy_node()


def test_the_state_files_episode_flag_is_read_back_and_checked(ros_context, tmp_path):
    """A restarted learner takes the saved episode flag (it does not act twice on one warning); a flag that is not
    true or false is refused with one line naming it (in-process)."""
    from shaper_nodes.nodes.learner import LearnerNode

    path = tmp_path / "learner_state.json"
    doc = {**state_doc(), "drift_warned": True}
    path.write_text(json.dumps(doc))
    node = LearnerNode(context=ros_context, parameter_overrides=learner_params(path))
    try:
        assert node.state_problem == "" and node.mode.drift.warned is True
        assert [e.speed().factor for e in node.mode.store] == [SAVED, SAVED]
    finally:
        node.destroy_node()
    path.write_text(json.dumps({**doc, "drift_warned": "yes"}))
    node = LearnerNode(context=ros_context, parameter_overrides=learner_params(path))
    try:
        assert "drift_warned must be true or false, got 'yes'" in node.state_problem
        assert "\n" not in node.state_problem and len(node.mode.store) == 0
    finally:
        node.destroy_node()


def test_an_empty_drift_status_watches_nothing(ros_context, tmp_path):
    """``speed.drift_status: ''`` leaves /diagnostics unwatched (in-process)."""
    from shaper_nodes.nodes.learner import LearnerNode

    node = LearnerNode(context=ros_context, parameter_overrides=[
        *learner_params(tmp_path / "state.json"), Parameter("speed.drift_status", value="")])
    try:
        assert node.mode.drift.status == ""
        assert all(sub.topic_name != "/diagnostics" for sub in node.subscriptions)
    finally:
        node.destroy_node()


def imu_window(peer: Peer, t0: float, motion: float, upto: float) -> float:
    """The accelerometer up to ``upto`` s after a move's start ``t0``, at 250 Hz: gravity, and after the ``motion`` s
    a decaying 8 Hz ring of 0.05 m/s^2 (well within 0.05 mm at 10 Hz: 0.197 m/s^2); the last sample's stamp, s."""
    for k in range(int(upto * 250) + 1):
        t = k / 250
        msg = Imu()
        msg.header.stamp = sec_to_time(t0 + t)
        ring = 0.05 * math.exp(-(t - motion) / 0.3) * math.sin(2 * math.pi * 8.0 * (t - motion)) if t > motion else 0.0
        msg.linear_acceleration.x, msg.linear_acceleration.z = ring, 9.81
        peer.imu.publish(msg)
    return t0 + t


def test_a_kill_9_during_a_move_resumes_every_move_from_its_saved_state(start_node, ros_context, tmp_path):
    """The learner (its own process) is killed with SIGKILL during a move: after its goal was accepted and reached
    the controller, which is still running it, and before the move's residual window ended. Started again on the same
    state file, every move resumes at its saved factor. The interrupted cycle is not learned from, which is right:
    the factor its goal ran with, its START and half its accelerometer window were in the killed process; the state
    saved at the last END is the state before the cycle, as if it had not run. Its END, arriving at the restarted
    learner, is reported skipped (END without its START), and the move's next cycle runs at the saved factor. The
    kill and the restart are :meth:`relearn_peer.Peer.kill_during_move` (the LIST and MRILC per-move learners' kill
    tests too): the state file not written since the goal reached the controller, the client's result of the goal
    never from the killed learner, ``STATUS_UNKNOWN`` from the restarted one."""
    state = tmp_path / "learner_state.json"
    params = {"mode": "speed_moves", "state_file": str(state), "end_wait": 10.0, "topics.imu_reliable": True,
              "speed.controller": CONTROLLER, "speed.scheduler": "", "speed.frequency_hz": 10.0,
              "speed.match_timeout": 30.0, "speed.action_timeout": 60.0, "speed.step": 0.2}
    inputs = ("/cycle_events", "/tip_imu")
    learner = start_node("shaper_nodes", "learner", params)
    peer = Peer(ros_context, CONTROLLER, imu=True)

    def cycle(number: int, move: int, factor: float) -> dict[str, float]:
        """One move as one cycle at ``factor`` (checked at the controller); the learner's report."""
        t0 = 100.0 + 10.0 * number
        event(peer, CycleEvent.START, number, t0, move)
        motion = motion_end(peer.run_goal(plan(move), f"the goal of cycle {number}"))
        assert motion == pytest.approx(MOTION / factor, abs=1e-6), (number, motion)
        end = imu_window(peer, t0, motion, motion + 1.2)
        event(peer, CycleEvent.END, number, end, move)  # (the END's wait: the samples up to it came)
        got = peer.report(number)
        assert got["speed_factor"] == pytest.approx(factor) and got["ok"] == 1.0, got
        return got

    def moves() -> dict:
        return json.loads(state.read_text())["moves"]["moves"]

    keys = [move_key(s, g) for s, g in MOVES]
    try:
        peer.spin_until(lambda: peer.learner_up(inputs, set()), "the learner's subscriptions and action server")
        for number, move, factor in ((0, 0, 1.0), (1, 1, 1.0), (2, 0, 1.2)):
            cycle(number, move, factor)
        saved = moves()
        assert [saved[k]["speed"]["factor"] for k in keys] == pytest.approx([1.4, 1.2])
        assert [saved[k]["cycles"] for k in keys] == [2, 1]

        # cycle 3, pick -> home at 1.2: killed while the controller runs its goal, half its window measured (the
        # window runs to motion + 1.0 s); started again on the same state file
        t0 = 130.0
        event(peer, CycleEvent.START, 3, t0, 1)
        restart = functools.partial(start_node, "shaper_nodes", "learner", params, env=RESTARTED)
        sent = peer.kill_during_move(learner, restart, inputs, plan(1),
                                     lambda g: imu_window(peer, t0, motion_end(g), motion_end(g) + 0.5), state,
                                     "the goal of cycle 3")
        motion = motion_end(sent)
        assert motion == pytest.approx(MOTION / 1.2, abs=1e-6)
        assert moves() == saved  # the state file: as at the last END
        # the interrupted cycle's accelerometer (the restarted learner had none of it) and END: not learned from
        event(peer, CycleEvent.END, 3, imu_window(peer, t0, motion, motion + 1.2), 1)
        assert peer.report(3) == {"skipped": 1.0}
        # every move resumes from its saved state: home -> pick at 1.4, pick -> home at 1.2 (its interrupted cycle
        # neither raised nor lowered it)
        assert cycle(4, 0, 1.4)["factor_next"] == pytest.approx(1.6)
        assert cycle(5, 1, 1.2)["factor_next"] == pytest.approx(1.4)
        after = moves()
        assert [after[k]["speed"]["factor"] for k in keys] == pytest.approx([1.6, 1.4])
        assert [after[k]["cycles"] for k in keys] == [3, 2]
        assert [h["factor"] for h in after[keys[1]]["speed"]["history"]] == pytest.approx([1.0, 1.2])
    finally:
        peer.destroy()
