"""calibrate's wait for the controller's answer to a goal (``Calibrator._await_answer``), on a simulated clock.

Under load the graph can read a live controller's action server out of the graph for ``SERVER_GONE`` s and then in it
again (``test_calibrate_stops.py``'s full-disk test hit it at load 30-40: the run ended early, saying "no answer ...
for 120 s"). The wait must go on when the server is back, and end as gone when it stays out; no real time passes here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from shaper_nodes.nodes import calibrator as calibrator_module
from shaper_nodes.nodes.calibrate_stops import Aborted
from shaper_nodes.nodes.calibrator import SERVER_GONE, Calibrator


class World:
    """A clock that the executor's spin advances, a server out of the graph over [out_from, back_at), and the
    controller's answer at answer_at (None: never)."""

    def __init__(self, out_from: float, back_at: float, answer_at: float | None) -> None:
        self.t = 0.0
        self.out_from, self.back_at, self.answer_at = out_from, back_at, answer_at
        self.last_read = -1.0

    def monotonic(self) -> float:
        return self.t

    def spin_once(self, timeout_sec: float) -> None:
        self.t += timeout_sec

    def server_is_ready(self) -> bool:
        # back in the graph between two reads at the same instant once back_at is reached: the race of the failure
        again = self.t == self.last_read
        self.last_read = self.t
        if self.t < self.out_from:
            return True
        return (self.t >= self.back_at and again) or self.t > self.back_at + 0.1

    def done(self) -> bool:
        return self.answer_at is not None and self.t >= self.answer_at


def calibrator(world: World, monkeypatch) -> Calibrator:
    monkeypatch.setattr(calibrator_module.time, "monotonic", world.monotonic)
    cal = Calibrator.__new__(Calibrator)
    cal.p = SimpleNamespace(timeouts=SimpleNamespace(peer=120.0, server=120.0), action="/controller/follow")
    cal.executor = SimpleNamespace(spin_once=world.spin_once)
    cal.action = SimpleNamespace(server_is_ready=world.server_is_ready)
    cal._absent_since = None
    cal.peer_lost = False
    return cal


def test_a_server_back_in_the_graph_is_waited_for():
    with pytest.MonkeyPatch.context() as mp:
        world = World(out_from=0.5, back_at=0.5 + SERVER_GONE, answer_at=5.0)
        cal = calibrator(world, mp)
        cal._await_answer(SimpleNamespace(done=world.done), "the approach to pose 0 (home)")
        assert world.t >= 5.0 and not cal.peer_lost


def test_a_server_that_stays_out_of_the_graph_is_gone():
    with pytest.MonkeyPatch.context() as mp:
        world = World(out_from=0.5, back_at=1e9, answer_at=None)
        cal = calibrator(world, mp)
        with pytest.raises(Aborted, match="left the graph before it answered"):
            cal._await_answer(SimpleNamespace(done=world.done), "the approach to pose 0 (home)")
        assert world.t < 0.5 + SERVER_GONE + 1.0 and cal.peer_lost


def test_no_answer_from_a_server_in_the_graph_ends_at_the_bound():
    with pytest.MonkeyPatch.context() as mp:
        world = World(out_from=1e9, back_at=1e9, answer_at=None)
        cal = calibrator(world, mp)
        with pytest.raises(Aborted, match="no answer and no feedback from the controller for 120 s"):
            cal._await_answer(SimpleNamespace(done=world.done), "the approach to pose 0 (home)")
        assert world.t >= 120.0 and cal.peer_lost


@pytest.mark.parametrize(("server_ready", "words"), [
    (False, "no FollowJointTrajectory server /controller/follow within 120 s"),
    (True, "no publisher of /tip_imu (the accelerometer) within 120 s"),
])
def test_what_a_move_waited_for_in_vain_is_named(server_ready, words):
    """Before a move calibrate waits for the controller's action server, then for the accelerometer's publisher; a
    wait that ends says which, in words (it said "no a publisher of /tip_imu", "no the FollowJointTrajectory
    server ...": session 11, the accelerometer remapped away)."""
    from shaper_nodes.core.calibration import Waypoint

    with pytest.MonkeyPatch.context() as mp:
        world = World(out_from=1e9, back_at=1e9, answer_at=None)
        cal = calibrator(world, mp)
        cal.names, cal.imu_topic = ["j1"], "/tip_imu"
        cal._fjt = SimpleNamespace(Goal=lambda trajectory: trajectory)
        cal.action = SimpleNamespace(server_is_ready=lambda: server_ready)
        cal._imu_sub = SimpleNamespace(get_publisher_count=lambda: 0)
        with pytest.raises(Aborted) as stop:
            cal.move((Waypoint(0.0, np.zeros(1)), Waypoint(1.0, np.ones(1))), "the approach to pose 0 (home)")
        assert str(stop.value) == words


def test_a_failed_write_while_the_answer_is_awaited_ends_the_wait():
    """A write that fails in a callback (a full disk: the accelerometer's samples are recorded from the approach's
    goal on) while calibrate waits for the controller's answer ends the run with that failure. Before, the wait
    suppressed every Aborted, WriteFailed included: the failure was lost, writing stopped, and the run waited on the
    goal (the full-disk test of test_calibrate_stops.py, with a controller that never ends a goal, for 300 s under
    two hogs, session 18)."""
    from shaper_nodes.nodes.calibrate_stops import WriteFailed

    with pytest.MonkeyPatch.context() as mp:
        world = World(out_from=1e9, back_at=1e9, answer_at=3.0)
        cal = calibrator(world, mp)

        def spin_once(timeout_sec: float) -> None:
            world.spin_once(timeout_sec)
            if world.t >= 1.0:  # the 2 MB limit reached while the goal's answer is on its way
                raise WriteFailed(OSError(27, "File too large"), "/cal/recording/pose_000.partial/pose_000.mcap")

        cal.executor = SimpleNamespace(spin_once=spin_once)
        with pytest.raises(WriteFailed, match=r"cannot write /cal/recording/pose_000\.partial/pose_000\.mcap"):
            cal._await_answer(SimpleNamespace(done=world.done), "the approach to pose 0 (home)")
        assert world.t < 1.1 and not cal.peer_lost
