"""Per-move learning, the ROS-free parts: the scheduler's corrections per move (matching a goal to its
move, the factor over the schedule, refusals) and the LIST session switching learners between moves."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.cycles import END, MOTION_END, START
from shaper_nodes.core.learning.list.learner import ListLearner
from shaper_nodes.core.learning.list.params import ListConfig, ListParams
from shaper_nodes.core.learning.list.session import ListSession
from shaper_nodes.core.scheduling import MoveCorrections
from shaper_nodes.core.shaping import Mode, Shaper, ShaperError, design

A0, A1 = [0.0, -1.57, 1.57], [1.2, -1.57, 1.57]
B1 = [0.0, -1.0, 0.5]
NAMES = ["j1", "j2", "j3"]


def pair(t2: float, a1: float = 0.6):
    return ListParams(a1, t2).shaper("zv2")


def test_a_goal_gets_its_moves_factor_and_other_moves_get_none():
    moves = MoveCorrections(tolerance=0.01)
    moves.set(NAMES, A0, A1, pair(0.05))
    moves.set(NAMES, A0, B1, pair(0.07))
    assert len(moves) == 2
    # the proxy's start is the goal's first point, a fraction of a milliradian into the move
    found = moves.find(NAMES, [a + 3e-4 for a in A0], A1)
    assert found is not None and found.factor.times[1] == pytest.approx(0.05)
    assert moves.find(NAMES, A0, B1).factor.times[1] == pytest.approx(0.07)
    # the same goal from another start is another move; a goal off by more than the tolerance too
    assert moves.find(NAMES, B1, A1) is None
    assert moves.find(NAMES, A0, [1.2 + 0.02, -1.57, 1.57]) is None
    # names in another order are put in the move's order first
    assert moves.find(["j3", "j1", "j2"], [A0[2], A0[0], A0[1]], [A1[2], A1[0], A1[1]]) is not None
    # unreadable poses match nothing
    assert moves.find(NAMES, [], A1) is None and moves.find(NAMES, [np.nan, 0, 0], A1) is None


def test_the_factor_is_convolved_with_the_schedule_and_none_forgets_it():
    moves = MoveCorrections()
    moves.set(NAMES, A0, A1, pair(0.05, 0.6))
    base = design("zv", [Mode.from_hz(10.0, 0.02), Mode.from_hz(25.0, 0.02)])
    shaped = MoveCorrections.apply(base, moves.find(NAMES, A0, A1).factor)
    assert shaped.family == "custom" and shaped.amplitudes.sum() == pytest.approx(1.0)
    assert shaped.duration == pytest.approx(base.duration + 0.05)
    assert "replaced" in moves.set(NAMES, A0, A1, pair(0.06))
    assert len(moves) == 1 and moves.find(NAMES, A0, A1).factor.times[1] == pytest.approx(0.06)
    assert "forgotten" in moves.set(NAMES, A0, A1, None)
    assert moves.find(NAMES, A0, A1) is None and len(moves) == 0


@pytest.mark.parametrize("args, words", [
    ((NAMES, [], A1), "start pose must be non-empty"),
    ((NAMES, A0, [0.0, np.inf, 0.0]), "goal pose must be non-empty and finite"),
    ((NAMES, A0, [0.0, 1.0]), "2 positions for 3 names"),
    (([], A0, [0.0, 1.0]), "start has 3 positions and its goal 2"),
])
def test_bad_moves_are_refused_with_the_problem_named(args, words):
    with pytest.raises(ShaperError, match=words):
        MoveCorrections().set(*args, pair(0.05))


def test_a_factor_is_two_to_sixteen_impulses_within_a_second_and_the_number_of_moves_is_bounded():
    moves = MoveCorrections(max_moves=2)
    # stacked two-impulse factors convolved (the learner's payback.max_factors): more than two impulses are taken
    moves.set(NAMES, A0, A1, design("zvd", [Mode.from_hz(10.0, 0.0)]))
    many = Shaper(np.full(17, 1.0 / 17), np.arange(17) * 0.01, "custom", (), {})
    with pytest.raises(ShaperError, match="2 to 16 impulses, got 17"):
        moves.set(NAMES, A0, A1, many)
    with pytest.raises(ShaperError, match=r"at most 1 s long, got 1\.5"):
        moves.set(NAMES, A0, A1, pair(1.5))
    moves.set(NAMES, A0, A1, pair(0.05))
    moves.set(NAMES, A0, B1, pair(0.05))
    with pytest.raises(ShaperError, match="already 2 moves"):
        moves.set(NAMES, A1, B1, pair(0.05))
    with pytest.raises(ShaperError, match="tolerance"):
        MoveCorrections(tolerance=0.0)


# ----------------------------------------------------------------------------- the session per move
RATE, W, Z = 200.0, 10.0, 0.05


def run_cycle(session, cycle, t0, amplitude):
    session.on_event(START, cycle, t0, [0.0], [1.0])
    session.on_event(MOTION_END, cycle, t0 + 1.5)
    wd = W * np.sqrt(1 - Z**2)
    for t in np.arange(0.0, 6.0 + 1e-9, 1.0 / RATE):
        x = amplitude * np.exp(-Z * W * (t - 1.5)) * np.sin(wd * (t - 1.5)) if t > 1.5 else 0.0
        session.on_imu(t0 + t, (float(x), 0.0, 0.0))
    return session.on_event(END, cycle, t0 + 6.0)


def test_the_session_learns_each_move_with_its_own_learner():
    config = ListConfig(highpass_hz=0.5)
    learners = {"a": ListLearner(config), "b": ListLearner(config)}
    session = ListSession(ListLearner(config), "zv2", stale_after=0.1)
    t = 0.0
    for cycle, (move, amp) in enumerate([("a", 1.0), ("b", 3.0), ("a", 1.0), ("b", 3.0)]):
        learner = learners[move]
        sent = learner.params if learner.reference is not None else None
        session.switch(learner, sent)
        r = run_cycle(session, cycle, t, amp)
        t += 10.0
        assert r.learned, r.skipped
        assert (r.update.used is None) == (cycle < 2)  # each move's first cycle is its own reference
    # each learner saw only its move's cycles: two updates each, and its own reference's amplitude
    assert [len(learners[k].history) for k in "ab"] == [2, 2]
    assert learners["b"].history[0]["m"] == pytest.approx(3.0 * learners["a"].history[0]["m"], rel=1e-6)


# ----------------------------------------------------------------------------- a factor kept only when it pays
def test_a_factor_worse_than_the_base_stops_the_moves_learning_at_the_best_measured():
    from shaper_nodes.core.learning.moves import MoveStore, keep_when_it_pays

    entry, _ = MoveStore().entry(A0, A1)
    assert keep_when_it_pays(entry, 0.010, False, None) == "learn"  # the reference: the schedule alone
    assert entry.base == entry.best == {"residual_rms": 0.010}
    assert keep_when_it_pays(entry, 0.005, True, 0.005) == "learn"  # better: go on
    assert entry.best == {"residual_rms": 0.005} and entry.base == {"residual_rms": 0.010}
    assert keep_when_it_pays(entry, 0.012, True, 0.005) == "best"  # worse than the base, a factor beat it
    other, _ = MoveStore().entry(A0, B1)
    keep_when_it_pays(other, 0.0003, False, None)
    assert keep_when_it_pays(other, 0.0007, True, 0.0007) == "base"  # no factor beat the schedule alone
    assert other.best == {"residual_rms": 0.0003}
