"""Which cycle a per-move learner's goal belongs to, when the goal and its START come in either order, or the START
never came (ROS-free).

The per-move learners that serve their own FollowJointTrajectory proxy (nodes/learner_moves_mrilc.py,
nodes/learner_speed.py) change a goal by its move (a correction, a time-scaling factor) before sending it on, so a
goal must be matched to its move when it comes, and the cycle must know what its goal ran with when it ends. The
move's identity comes with the cycle's START on ``/cycle_events`` (its start and goal poses), on another topic than
the goal. :class:`MoveCycles` keeps the open cycles and matches a goal:

- to the cycle of the latest START, while that cycle is open, no goal was matched to it yet, and its goal pose is
  the goal's last point (within :data:`MATCH` rad): the START came first, as a motion source sends it;
- else, at once, to a move already known whose start and goal poses are the goal's first and last points (within
  :data:`MATCH` rad each): an *early* cycle, waiting for its START. The next START (received, or stood in for by a
  later event's start stamp: core/cycles.py ``MissedStarts``) of that move claims it; a START of another move drops
  it, and so does an END, but that of the cycle open when the goal came (the next cycle's goal may pass the END of
  the one before it, which waits for its last samples). So a goal whose START the learner missed (a listener that
  matched late: ``send_goal --cycle`` sends MOTION_END and END only once the goal succeeded, so the stand-in comes
  after the goal) still runs with its move's correction or factor, and its cycle learns from it;
- else not yet (a move not known: its first cycle; the caller waits for its START, bounded, as before).

A stood-in START whose samples do not reach back to its stamp is refused by the caller
(:func:`~shaper_nodes.core.cycles.unseen_window`, the rule every listener uses).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Generic, Protocol, TypeVar

import numpy as np

__all__ = ["KEPT", "MATCH", "MoveCycles", "goal_matches", "unmatched"]

#: rad: how far a goal's first and last points may be from a move's start and goal poses for the goal to be its
MATCH = 1e-3
#: cycles open at once (ENDs that never came are forgotten beyond it)
KEPT = 64


class _Cycle(Protocol):
    key: str
    start: float
    goal: np.ndarray


C = TypeVar("C", bound=_Cycle)


def unmatched(first_cycle: bool, went: str) -> str:
    """Why a cycle whose START was missed is not learned from when its goal, come before the stand-in, was matched to
    no cycle: the move was not known then (its first cycle), or it was and the goal's first and last points are not
    its start and goal poses (a goal that leaves out its start point, a jog): an early goal is matched by both.
    ``went``: how the goal went instead (the learner's words)."""
    why = ("matched no move known then (the move's first cycle)" if first_cycle else
           f"did not match its move: an early goal is matched by its first and last points, within {MATCH:g} rad of"
           " the move's start and goal poses")
    return f"its START was missed and its goal, which came before the stand-in, {why}: {went}"


def goal_matches(goal: Sequence[float] | np.ndarray, last: Sequence[float] | np.ndarray, atol: float = MATCH) -> bool:
    """Whether a goal whose last point is ``last`` (rad) is the move whose START named ``goal`` (rad)."""
    g, q = np.asarray(goal, dtype=float), np.asarray(last, dtype=float)
    return g.shape == q.shape and g.size > 0 and bool(np.allclose(g, q, atol=atol, rtol=0))


class MoveCycles(Generic[C]):
    """The open cycles of a per-move learner and its goals' matching (module docstring).

    Parameters
    ----------
    free : callable
        Whether a cycle may still take a goal (none matched to it yet, not refused).
    make : callable
        ``make(key, goal)``: a new cycle of the move ``key`` for an early goal (its start stamp NaN until its START).
    """

    def __init__(self, free: Callable[[C], bool], make: Callable[[str, np.ndarray], C]) -> None:
        self._free, self._make = free, make
        #: cycle index -> its cycle, from its START to its END
        self.open: dict[int, C] = {}
        self._last: C | None = None
        self._early: C | None = None
        self._during: C | None = None  # the cycle open when the early goal came
        #: early goals claimed by their START so far, and those claimed by a stood-in START
        self.claimed = 0
        self.claimed_stood_in = 0

    @property
    def early(self) -> C | None:
        """The cycle of a goal that came before its START (None: none)."""
        return self._early

    def started(self, cycle: int, cyc: C, stood_in: bool = False) -> C:
        """A START (``stood_in``: made from a later event's start stamp) of the move ``cyc.key``, its cycle ``cyc``
        made by the caller: an early goal's cycle of that move is taken instead (its start set from ``cyc``).
        Returns the cycle kept."""
        early, self._early, self._during = self._early, None, None
        if early is not None and early.key == cyc.key:
            early.start = cyc.start
            cyc = early
            self.claimed += 1
            self.claimed_stood_in += int(stood_in)
        self.open[int(cycle)] = self._last = cyc
        while len(self.open) > KEPT:
            self.open.pop(next(iter(self.open)))
        return cyc

    def ended(self, cycle: int) -> C | None:
        """A cycle's END: its cycle (None: its START was not seen nor stood in for); an early goal not claimed by
        then is dropped (it was no cycle's), unless it came while this cycle was open (the next cycle's)."""
        cyc = self.open.pop(int(cycle), None)
        if cyc is None or cyc is not self._during:
            self._early = None
        self._during = None
        if cyc is self._last:
            self._last = None
        return cyc

    def for_goal(self, first: Sequence[float] | np.ndarray, last: Sequence[float] | np.ndarray,
                 moves: Iterable[tuple[str, Sequence[float], Sequence[float]]]) -> C | None:
        """The cycle a goal whose first and last points are ``first`` and ``last`` (rad) belongs to, None if none
        yet (module docstring). ``moves``: the moves known, (key, start, goal) each."""
        cyc = self._last
        if cyc is not None and self._free(cyc) and goal_matches(cyc.goal, last) and any(
                c is cyc for c in self.open.values()):
            return cyc
        known = [key for key, start, goal in moves if goal_matches(start, first) and goal_matches(goal, last)]
        if len(known) != 1:  # none (a move's first cycle), or poses too close to tell: its START decides
            return None
        self._early = self._make(known[0], np.asarray(last, dtype=float))
        self._during = cyc if cyc is not None and any(c is cyc for c in self.open.values()) else None
        return self._early
