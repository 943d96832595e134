"""Goals' records put with their cycles, and the refusal of a cycle whose goal was not shaped as expected
(core/learning/goal_shaping.py)."""

from __future__ import annotations

from shaper_nodes.core.learning.goal_shaping import (
    ACTIVE,
    BEFORE_START,
    FALLBACK,
    KEPT,
    SCHEDULED,
    GoalBook,
    GoalRecord,
    refusal,
)

NAMES = ["a", "b"]
PICK, HOME = [0.5, -0.25], [0.0, 0.0]


def record(how: int, goal: list[float], names: list[str] = NAMES, detail: str = "") -> GoalRecord:
    return GoalRecord(how, detail, tuple(names), tuple(goal), "parameters", 3)


def test_a_fallback_is_refused_by_every_learner_and_active_only_by_those_of_the_scheduler() -> None:
    fell = record(FALLBACK, PICK, detail="no answer from the scheduler: no reply within 2 s")
    why = refusal(fell, scheduled=False)
    assert why == ("its goal was shaped with the active shaper (parameters, revision 3), not for its final pose:"
                   " no answer from the scheduler: no reply within 2 s")
    assert refusal(fell, scheduled=True) == why
    assert "no action.scheduler" in refusal(record(ACTIVE, PICK), scheduled=True)
    assert refusal(record(ACTIVE, PICK), scheduled=False) == ""
    assert refusal(record(SCHEDULED, PICK), scheduled=True) == ""
    assert "does not know" in refusal(record(7, PICK), scheduled=False)


def test_each_record_goes_to_the_cycle_of_its_move_in_either_order() -> None:
    book = GoalBook()
    book.start(0, NAMES, PICK)
    book.shaped(record(FALLBACK, PICK, detail="no answer"))  # while cycle 0 runs
    book.end(0)
    book.shaped(record(SCHEDULED, HOME))  # before cycle 1's START
    book.start(1, NAMES, HOME)
    book.end(1)
    assert "no answer" in book.refusal(0, True)
    assert book.refusal(0, True) == ""  # taken once
    assert book.refusal(1, True) == ""
    assert [r.shaped_with for r in book.records(1)] == []  # taken


def test_a_record_matches_by_the_goal_in_the_starts_joint_order() -> None:
    book = GoalBook()
    book.start(4, ["b", "a"], [PICK[1], PICK[0]])
    book.shaped(record(FALLBACK, PICK))  # the trajectory names a, b
    book.shaped(record(FALLBACK, HOME))  # another move's goal: not this cycle's
    book.end(4)
    assert [r.goal for r in book.records(4)] == [tuple(PICK)]
    book.start(5, ["a", "c"], PICK)  # other joints: no match
    book.shaped(record(FALLBACK, PICK))
    book.end(5)
    assert book.records(5) == []


def test_records_no_start_claimed_are_dropped_at_an_end_and_a_start_claims_the_latest() -> None:
    book = GoalBook()
    book.shaped(record(FALLBACK, PICK))  # a goal whose START never came
    book.start(0, NAMES, HOME)
    book.end(0)  # drops it
    book.start(1, NAMES, PICK)
    book.end(1)
    assert book.records(1) == []
    book.shaped(record(FALLBACK, PICK))
    book.shaped(record(SCHEDULED, PICK))
    book.start(2, NAMES, PICK)
    book.end(2)
    assert [r.shaped_with for r in book.records(2)] == [SCHEDULED]


def test_a_cycle_with_no_record_is_learned_from_and_memory_is_bounded() -> None:
    book = GoalBook()
    book.start(0, NAMES, PICK)
    book.end(0)
    assert book.refusal(0, True) == ""
    assert book.refusal(99, True) == ""  # never seen
    for cycle in range(3 * KEPT):  # STARTs whose END never came, records no one claims
        book.start(cycle, NAMES, PICK)
        book.shaped(record(SCHEDULED, HOME))
    assert len(book._open) <= KEPT and len(book._pending) <= KEPT
    for cycle in range(3 * KEPT):
        book.end(cycle)
    assert len(book._ended) <= KEPT


def stamped(how: int, goal: list[float], stamp: float) -> GoalRecord:
    return GoalRecord(how, "", tuple(NAMES), tuple(goal), "parameters", 3, stamp)


def test_a_stale_record_of_the_same_move_cannot_decide_a_new_cycle() -> None:
    """A restarted learner receives the shaper node's latched records of goals sent before it (session 15): a FALLBACK
    of the move, stamped before the new cycle's START (less BEFORE_START), is not the cycle's, whichever order."""
    book = GoalBook()
    book.shaped(stamped(FALLBACK, PICK, 80.0))  # the latched history: two cycles of the move ago
    book.shaped(stamped(SCHEDULED, HOME, 90.0))
    book.start(0, NAMES, PICK, 100.0)
    assert book.unclaimed == 2  # neither claimed (the stale one, the other move's): dropped at this END
    book.shaped(stamped(FALLBACK, PICK, 99.0))  # delivered late, still older than the START: not this cycle's
    book.shaped(stamped(SCHEDULED, PICK, 100.0))  # this cycle's goal
    book.end(0)
    assert [r.shaped_with for r in book.records(0)] == [SCHEDULED]
    assert book.refusal(0, True) == ""
    # a goal sent just before its START (a motion source that sends the goal first) is the cycle's
    book.shaped(stamped(FALLBACK, PICK, 110.0 - BEFORE_START))
    book.start(1, NAMES, PICK, 110.0)
    book.end(1)
    assert "not for its final pose" in book.refusal(1, False)
    # a record or a START without a stamp is matched by its move alone, as before
    book.shaped(record(FALLBACK, PICK))
    book.start(2, NAMES, PICK, 120.0)
    book.end(2)
    assert [r.shaped_with for r in book.records(2)] == [FALLBACK]
