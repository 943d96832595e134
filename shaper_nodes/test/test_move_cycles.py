"""A per-move learner's goal matched to its cycle when its START comes after it or never comes (stood in for at
MOTION_END): core/learning/move_cycles.py, without rclpy."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START, MissedStarts, unseen_window
from shaper_nodes.core.learning.move_cycles import KEPT, MATCH, MoveCycles

A, B, C = [0.0, 0.0], [1.0, 0.5], [0.2, -0.3]


@dataclass
class Cyc:
    key: str
    start: float
    goal: np.ndarray
    taken: bool = False


def book() -> MoveCycles[Cyc]:
    return MoveCycles(lambda c: not c.taken, lambda key, goal: Cyc(key, math.nan, goal))


def known(*moves: tuple[str, list[float], list[float]]):
    return list(moves)


def test_a_goal_after_its_start_takes_the_starts_cycle_once() -> None:
    cycles = book()
    assert cycles.for_goal(A, B, []) is None  # no START, no move known: wait for the START
    opened = cycles.started(0, Cyc("ab", 10.0, np.array(B)))
    got = cycles.for_goal(A, B, [])
    assert got is opened
    got.taken = True
    assert cycles.for_goal(A, B, []) is None  # taken: a second goal is not this cycle's
    assert cycles.for_goal(A, C, []) is None  # another goal pose
    assert cycles.ended(0) is opened and cycles.ended(0) is None


def test_a_goal_of_a_known_move_whose_start_was_missed_is_claimed_by_the_stand_in() -> None:
    """send_goal --cycle: START lost, the goal, then MOTION_END and END (carrying the START's stamp) once it ran."""
    cycles, rule = book(), MissedStarts()
    moves = known(("ab", A, B), ("ba", B, A))
    for ev in rule.events(START, 0, 10.0, 10.0) + rule.events(END, 0, 12.0, 10.0):
        if ev.kind == START:
            cycles.started(0, Cyc("ab", ev.t, np.array(B))).taken = True
        else:
            cycles.ended(0)
    # cycle 1 of the move: its START missed; its goal comes first, at once matched to the known move
    early = cycles.for_goal(np.array(A) + 0.5 * MATCH, np.array(B) - 0.5 * MATCH, moves)
    assert early is not None and early.key == "ab" and math.isnan(early.start) and cycles.early is early
    early.taken = True  # (the goal ran with the move's factor)
    handled = rule.events(MOTION_END, 1, 21.0, 20.0)
    assert [(e.kind, e.t, e.stood_in) for e in handled] == [(START, 20.0, True), (MOTION_END, 21.0, False)]
    kept = cycles.started(1, Cyc("ab", handled[0].t, np.array(B)), stood_in=True)
    assert kept is early and kept.start == 20.0 and kept.taken  # the cycle knows what its goal ran with
    assert (cycles.claimed, cycles.claimed_stood_in) == (1, 1) and cycles.early is None
    assert cycles.ended(1) is early


def test_an_early_goal_goes_only_to_a_start_of_its_move_and_not_past_an_end() -> None:
    moves = known(("ab", A, B), ("cb", C, B))
    cycles = book()
    assert cycles.for_goal(A, C, moves) is None  # no known move ends there
    assert cycles.for_goal([0.1, 0.1], B, moves) is None  # ends at B, but starts elsewhere: not known
    early = cycles.for_goal(A, B, moves)
    assert early is not None and early.key == "ab"
    other = cycles.started(0, Cyc("cb", 30.0, np.array(B)))  # a START of another move: the early goal is not its
    assert other is not early and cycles.early is None
    other.taken = True  # (its goal came)
    cycles.ended(0)
    early = cycles.for_goal(A, B, moves)  # no cycle open
    assert early is not None and early is not other and early.key == "ab"
    cycles.ended(5)  # an END drops a goal no START claimed (it was no cycle's)
    fresh = cycles.started(1, Cyc("ab", 40.0, np.array(B)))
    assert fresh is not early and cycles.claimed == 0
    # an ended cycle takes no goal (the latest START's cycle is free, but over)
    cycles.ended(1)
    assert cycles.for_goal(A, B, []) is None


def test_the_next_cycles_goal_passing_the_end_of_the_cycle_before_is_kept_for_its_start() -> None:
    """The END of a cycle waits for its last samples (``end_wait``): the next cycle's goal may come meanwhile, before
    that END and the next START are handled."""
    moves = known(("ab", A, B), ("ba", B, A))
    cycles = book()
    cycles.started(0, Cyc("ba", 10.0, np.array(A))).taken = True
    early = cycles.for_goal(A, B, moves)  # cycle 1's goal, cycle 0 still open
    assert early is not None and early.key == "ab"
    early.taken = True
    cycles.ended(0)
    assert cycles.early is early
    assert cycles.started(1, Cyc("ab", 20.0, np.array(B))) is early and early.start == 20.0
    # an early goal that came with no cycle open, or while another one was, does not pass an END
    cycles.ended(1)
    assert cycles.for_goal(A, B, moves) is not None
    cycles.ended(7)
    assert cycles.early is None


def test_two_known_moves_too_close_to_tell_leave_the_goal_to_its_start() -> None:
    near = [A[0] + 0.5 * MATCH, A[1]]
    assert book().for_goal(A, B, known(("ab", A, B), ("nb", near, B))) is None


def test_open_cycles_are_bounded() -> None:
    cycles = book()
    for cycle in range(3 * KEPT):  # ENDs that never came
        cycles.started(cycle, Cyc("ab", float(cycle), np.array(B)))
    assert len(cycles.open) == KEPT


def test_a_stand_in_whose_samples_begin_after_its_stamp_is_named() -> None:
    """The rule the MRILC and speed learners apply to a stood-in START (their buffers keep max_cycle_duration s)."""
    assert unseen_window(20.0, 19.5) == ""
    assert "the window from START was not seen" in unseen_window(20.0, 20.5)
    assert "no samples held" in unseen_window(20.0, None)
