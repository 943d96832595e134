"""MRILC (seed 000) through the ROS graph: sim plant (mck_pid), shaper and learner as processes.

The driver runs one cycle at a time (a unit step and back) and reads the learner's reports. The
learner node in-process with peers that answer: a state file that cannot be used starts it afresh.
"""

from __future__ import annotations

import json
import math
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from reproductions.mrilc_cases import JOINT, NOMINAL, PERTURBED, RATE, plant_params, run_learning, run_shaper_only
from shaper_msgs.msg import FeedforwardProfile
from shaper_msgs.srv import SetFeedforward, SetShaper
from shaper_nodes.nodes.learner import LearnerNode
from shaper_nodes.ros.lockstep_reader import AckWatch
from sim_plant_node.clients.conductor import Conductor

pytestmark = pytest.mark.integration


def test_mrilc_400_iterations_on_the_perturbed_plant(starter, ros_context):
    start = starter
    nominal = run_shaper_only(NOMINAL, 2, start, ros_context)
    start.stop_all()
    assert [r.action for r in nominal] == ["hold", "hold"]
    rows = run_learning(PERTURBED, 400, start, ros_context)
    assert [r.iteration for r in rows] == list(range(1, 401)), [r for r in rows if r.action == "skipped"][:3]
    assert all(r.action == "learn" for r in rows)
    assert rows[399].rms_e <= 0.02 * rows[0].rms_e, (rows[0].rms_e, rows[399].rms_e)
    # the feedback effort falls as the learned effort takes over (the paper's Fig. 11)
    assert rows[399].rms_u1 < rows[0].rms_u1 and rows[399].rms_u2 > 0
    assert min(r.rms_u1 for r in rows[:50]) < rows[0].rms_u1
    # ZVD + MRILC on the perturbed plant vibrates like ZVD alone on the nominal plant
    assert abs(rows[399].residual - nominal[-1].residual) <= 0.2 * nominal[-1].residual, (
        rows[399].residual, nominal[-1].residual)


def test_learner_refuses_a_gain_that_fails_the_check(start_node, tmp_path):
    proc = start_node("shaper_nodes", "learner", {"mode": "mrilc", "mrilc.rate": RATE, "mrilc.gamma": 25.0})
    deadline = time.monotonic() + 60.0
    while proc.running() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not proc.running()
    assert proc.proc.returncode != 0
    log = proc.log_path.read_text()
    assert "learning refused" in log and "w=5 zeta=0.15" in log and "largest P-type gamma" in log


def test_bad_feedforward_profiles_are_refused_and_the_plant_keeps_running(start_node, ros_context):
    start_node("sim_plant_node", "sim_plant", {"joint_names": JOINT, "rate": RATE, "mode": "lockstep",
                                               **plant_params(NOMINAL)})
    conductor = Conductor(context=ros_context)
    try:
        cli = conductor.create_client(SetFeedforward, "/sim_plant/set_feedforward")
        conductor.spin_until(cli.service_is_ready, 30.0, "set_feedforward")

        def send(**fields):
            base = dict(source="test", injection="effort", joint_names=JOINT, sample_period=1.0 / RATE,
                        data=[0.0, 0.1])
            base.update(fields)
            return conductor.call(cli, SetFeedforward.Request(profile=FeedforwardProfile(**base)))

        assert send().success
        for fields, why in [({"joint_names": ["elbow"]}, "joint names"), ({"sample_period": 0.001}, "sample period"),
                            ({"data": [0.0, float("nan")]}, "non-finite value at index 1"),
                            ({"injection": "torque"}, "injection must be")]:
            resp = send(**fields)
            assert not resp.success and why in resp.message, resp.message
        assert send(injection="command", data=[]).success  # an empty profile clears it
    finally:
        conductor.close()


def test_profile_is_saved_and_reloaded(starter, ros_context, tmp_path):
    start = starter
    state = tmp_path / "mrilc.json"
    first = run_learning(PERTURBED, 3, start, ros_context, {"state_file": str(state), "mrilc.law": "robust"})
    start.stop_all()
    assert [r.iteration for r in first] == [1, 2, 3] and state.exists()
    again = run_learning(PERTURBED, 1, start, ros_context, {"state_file": str(state), "mrilc.law": "robust"})
    assert again[0].iteration == 4
    assert again[0].rms_e < first[2].rms_e < first[0].rms_e  # it went on from the saved profile


def test_a_recorded_mrilc_run_replays_offline_to_the_live_updates(starter, ros_context, tmp_path):
    """The bag analysis' MRILC replay of a recorded live run gives the live learner's updates."""
    from shaper_nodes.analysis.analyze import Options, analyze
    from shaper_nodes.analysis.streams import read_recording

    start = starter
    bag = tmp_path / "bag"
    topics = ["/tip_imu", "/joint_states", "/sim_plant/reference", "/cycle_events"]
    recorder = start("shaper_nodes", "recorder", {"output": str(bag), "use_sim_time": True, "topics": topics})
    watch: list[AckWatch] = []

    def before(conductor) -> None:  # the plant waits for the recorder (lockstep.readers), from the first step on
        watch.append(AckWatch(conductor, "/recorder"))
        watch[0].wait_subscribed(conductor.spin_until, topics, 60.0)

    def after(conductor, reports) -> None:  # every sample up to the last cycle's residual window recorded
        watch[0].wait_processed(conductor.spin_until, reports[-1].window_end, 120.0)

    live = run_learning(PERTURBED, 3, start, ros_context, measure=True, plant={"lockstep.readers": ["/recorder"]},
                        before=before, after=after)
    assert recorder.stop() == 0
    start.stop_all()
    assert [r.action for r in live] == ["learn"] * 3
    rec = read_recording(bag)
    params = {"mrilc.rate": RATE, "joint_names": JOINT}
    for learned_run, expected in ((True, 3), (False, 1)):
        replay = analyze(rec, Options(learners=("mrilc",), learner_params={**params, "replay.learned_run": learned_run}
                                      )).replays["mrilc"]
        rows = [r for r in replay.rows if "skipped" not in r]
        assert len(rows) == expected, replay
        for row, it in zip(rows, live, strict=False):
            assert row["iteration"] == it.iteration
            assert (row["rms_e"], row["rms_u1"], row["rms_u2"], row["residual"]) == pytest.approx(
                (it.rms_e, it.rms_u1, it.rms_u2, it.residual), rel=1e-12)


class Peers(Node):
    """Plays the shaper node's ``~/set_shaper`` and the plant's ``/sim_plant/set_feedforward``:
    both accept every request and keep it."""

    def __init__(self, context) -> None:
        super().__init__("shaper", context=context)
        self.shapers: list = []
        self.profiles: list = []
        self.create_service(SetShaper, "~/set_shaper", self._on_shaper)
        self.create_service(SetFeedforward, "/sim_plant/set_feedforward", self._on_profile)

    def _on_shaper(self, request, response):
        self.shapers.append(request)
        response.success, response.message = True, "accepted"
        return response

    def _on_profile(self, request, response):
        self.profiles.append(request.profile)
        response.success, response.message = True, "installed"
        return response


def _saved(history=None, best_profile=None) -> dict:
    """A learner node's MRILC state after one iteration at 200 Hz, one joint (edited by the cases)."""
    profile = [[0.01 * k] for k in range(8)]
    learner = {"joints": 1, "iteration": 2, "holding": False, "grew": 0, "last_rms": 0.1, "profile": profile,
               "best_rms": 0.1, "best_profile": best_profile or [[0.0]] * 8,
               "history": history or [[1, 0.1, math.nan, 0.0, "learn"]], "max_rms": 0.1}
    return {"version": 1, "mode": "mrilc", "saved_at": 1.0, "joint_names": JOINT, "sample_period": 1.0 / 200.0,
            "injection": "effort", "learner": learner}


@pytest.mark.parametrize("case, doc, movable, words", [
    ("a good state (the control)", _saved(), True, ""),
    ("history entry [[]]", _saved(history=[[]]), False, "history entry 0 must be"),
    ("NaN best profile", _saved(best_profile=[[0.0]] * 7 + [[math.nan]]), True, "best_profile has a non-finite"),
    ("NaN best profile, read-only folder", _saved(best_profile=[[math.nan]] * 8), False, "non-finite"),
])
def test_the_learner_starts_afresh_from_a_state_it_cannot_use(ros_context, tmp_path, case, doc, movable, words):
    folder = tmp_path / "state"
    folder.mkdir()
    state = folder / "mrilc.json"
    state.write_text(json.dumps(doc))  # NaN as the JSON token NaN, as the learner writes it
    if not movable:
        (folder / "mrilc.json.corrupt").mkdir()  # a folder that is not empty: the file cannot be moved there
        (folder / "mrilc.json.corrupt" / "keep").write_text("")
        folder.chmod(0o555)
    peers = Peers(ros_context)
    params = {"mode": "mrilc", "state_file": str(state), "joint_names": JOINT, "mrilc.rate": 200.0}
    node = None
    ex = SingleThreadedExecutor(context=ros_context)
    try:
        for _ in range(2 if not movable else 1):  # where the file stays, the next start refuses it again
            node = LearnerNode(context=ros_context, parameter_overrides=[Parameter(k, value=v)
                                                                         for k, v in params.items()])
            ex.add_node(node)
            ex.add_node(peers)
            seen = len(peers.profiles)
            deadline = time.monotonic() + 30.0
            while len(peers.profiles) == seen:
                assert time.monotonic() < deadline, "no profile installed"
                ex.spin_once(timeout_sec=0.05)
            installed = peers.profiles[seen]
            if not words:  # the control: resumed at iteration 2 with the saved profile
                assert node.state_problem == "" and installed.iteration == 2 and len(installed.data) == 8
                break
            assert words in node.state_problem, node.state_problem
            assert node.diagnostics.counts["state_file"] == 1
            assert installed.iteration == 1 and list(installed.data) == []  # afresh: no profile
            assert node.mode.session.learner.iteration == 1
            assert state.exists() != movable
            assert ("moved to" in node.state_problem) == movable
            ex.remove_node(node)
            node.destroy_node()
            node = None
    finally:
        folder.chmod(0o755)
        ex.shutdown()
        if node is not None:
            node.destroy_node()
        peers.destroy_node()
