"""LIST through the ROS graph: seed 003's four cases, restart from the save file, bag replay, and
a state file that can neither be loaded nor moved aside (no crash loop).

Sim plant, shaper and learner run as separate processes in lockstep; the test drives cycles
one at a time through the public services and reads the learner's reports.
"""

from __future__ import annotations

import json
import math
import shutil
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from reproductions.list_cases import CASES, LEARNER, run_case
from shaper_msgs.srv import SetShaper
from shaper_nodes.analysis.replay import replay

pytestmark = pytest.mark.integration
CYCLES = 11  # cycle 0 unshaped (reference), cycles 1..10 learning
# every run here reads only the learner's reports (run_case's measure=False: the driver takes no accelerometer or joint
# state sample; the shared runs of tests/conftest.py too, but for the recorded one)


def shaped(rows):
    return [r for r in rows if not r.skipped and not math.isnan(r.a1)]


@pytest.mark.parametrize("name", ["case1", "case2", "case3"])
def test_list_reduces_residual_vibration_tenfold(name, request, tmp_path):
    if name == "case1":  # the session's shared run (tests/conftest.py), which test_restart_... resumes from
        _, rows = request.getfixturevalue("list_case1_run")
    else:
        rows = run_case(CASES[name], CYCLES, request.getfixturevalue("start_node"),
                        request.getfixturevalue("ros_context"), tmp_path / "state.json", measure=False)
    assert not any(r.skipped for r in rows), rows
    assert math.isnan(rows[0].a1)  # the reference cycle ran unshaped
    m1, m10 = rows[1].m, rows[10].m
    assert m10 <= 0.10 * m1, [round(r.m, 5) for r in rows]


def test_list_with_saturation_never_ends_above_its_best(start_node, ros_context, tmp_path):
    # ten learning cycles, then the learner is told to hold (~/hold): the last cycle runs with the
    # best parameters found, whatever the last trial was
    rows = run_case(CASES["case4"], CYCLES + 1, start_node, ros_context, tmp_path / "state.json", hold_after=CYCLES,
                    measure=False)
    ms = [r.m for r in shaped(rows)]
    assert len(ms) >= CYCLES - 1, rows
    assert rows[-1].action == "hold"
    assert ms[-1] <= min(ms) * (1 + 1e-6), ms
    assert ms[-1] < 0.25 * rows[1].m  # and learning did help (the paper: M fell, then rose at the 7th)


def test_restart_resumes_from_the_saved_shaper(list_case1_run, start_node, ros_context, tmp_path):
    # the first run: the session's shared run of case 1 from a fresh state (tests/conftest.py's list_case1_run,
    # eleven cycles, its plant, shaper and learner stopped after it); its state file copied, as the learner writes it
    saved_state, first = list_case1_run
    state = tmp_path / "state.json"
    shutil.copyfile(saved_state, state)
    saved = json.loads(state.read_text())
    assert saved["version"] == 1
    # a new learner process (and plant and shaper) with the same state file resumes: its first
    # cycle runs with the parameters the last update chose, not unshaped
    again = run_case(CASES["case1"], 2, start_node, ros_context, state, measure=False)
    assert again[0].a1 == pytest.approx(first[-1].a1_next, abs=1e-12)
    assert again[0].t2 == pytest.approx(first[-1].t2_next, abs=1e-12)
    assert again[0].m < first[1].m


def test_corrupt_save_file_is_reported_and_ignored(start_node, ros_context, tmp_path):
    state = tmp_path / "state.json"
    state.write_text('{"version": 1, "structure": "zv2", "learner": {"params": [0.5')
    rows = run_case(CASES["case1"], 2, start_node, ros_context, state, measure=False)
    assert math.isnan(rows[0].a1)  # started afresh: reference cycle first
    assert (tmp_path / "state.json.corrupt").exists()
    logs = "".join(p.read_text() for p in tmp_path.glob("learner-*.log"))
    assert "not loaded" in logs


def test_replaying_the_recorded_bag_gives_the_live_updates(list_case2_recording):
    """The offline replay of a recorded live run (case 2, five cycles; the session's shared run, tests/conftest.py's
    ``list_case2_recording``, which test_bag_analysis_over_dds.py plays into a learner) gives the live updates."""
    bag, rows, recorder_code = list_case2_recording
    assert recorder_code == 0  # the recorder finalised the bag
    results = replay(bag, LEARNER)
    learned = [r for r in results if r.update is not None]
    assert len(learned) == len(rows)
    for live, offline in zip(rows, learned, strict=True):
        assert offline.update.m == pytest.approx(live.m, rel=1e-12, abs=1e-15)
        assert offline.update.next.a1 == pytest.approx(live.a1_next, rel=1e-12)
        assert offline.update.next.t2 == pytest.approx(live.t2_next, rel=1e-12)


class AnsweringShaper(Node):
    """Plays the shaper node's ``~/set_shaper``: accepts every request and keeps it."""

    def __init__(self, context) -> None:
        super().__init__("shaper", context=context)
        self.requests: list = []
        self.create_service(SetShaper, "~/set_shaper", self._on_set)

    def _on_set(self, request, response):
        self.requests.append(request)
        response.success, response.message = True, "accepted"
        return response


def test_a_state_file_that_cannot_be_loaded_nor_moved_aside_never_stops_the_learner(start_node, ros_context,
                                                                                    tmp_path):
    """A state file nested 100k deep (json.loads recurses out) in a folder where it cannot be moved
    aside: the learner starts afresh, twice (no crash loop), and says why each time."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    (folder / "state.json.corrupt").mkdir()  # a folder that is not empty: not even root can move the file there
    (folder / "state.json.corrupt" / "keep").write_text("")
    state = folder / "state.json"
    state.write_text("[" * 100_000 + "]" * 100_000)
    folder.chmod(0o555)  # read-only as well (root is not stopped by it; the folder above is)
    shaper = AnsweringShaper(ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(shaper)
    try:
        for start in range(2):
            proc = start_node("shaper_nodes", "learner", {"state_file": str(state), "service_timeout": 30.0})
            seen = len(shaper.requests)
            deadline = time.monotonic() + 60.0
            while len(shaper.requests) == seen:
                assert proc.running(), f"start {start}: the learner exited"
                assert time.monotonic() < deadline, f"start {start}: no start-up request from the learner"
                ex.spin_once(timeout_sec=0.05)
            # started afresh: the identity shaper, so that the next cycle runs unshaped as the reference
            assert shaper.requests[seen].shaper.family == "none"
            assert proc.running(), proc.log_path.read_text()
            code = proc.stop()
            log = proc.log_path.read_text()
            assert code == 0, log
            assert "nested too deeply" in log and "could not be moved aside" in log, log
            assert "starting afresh" in log and state.exists()
    finally:
        folder.chmod(0o755)
        ex.shutdown()
        shaper.destroy_node()
