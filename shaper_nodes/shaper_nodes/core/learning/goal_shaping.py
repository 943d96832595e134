"""Which shaper each cycle's goal ran with, and whether a per-move learner may learn from the cycle (ROS-free).

The shaper node says, for each FollowJointTrajectory goal it sends on, what it shaped it with
(shaper_msgs/ShapedGoal on ``<shaper node>/shaped_goals``): for its final pose with the scheduler's shaper
(:data:`SCHEDULED`: the schedule at the goal, times the move's learned factor if the scheduler has one), or with
its active shaper, either because the scheduler's could not be had (:data:`FALLBACK`: no answer, a refusal) or
because it shapes every goal so (:data:`ACTIVE`: no ``action.scheduler``). A per-move learner's cycle is a move
marked on ``/cycle_events``; :class:`GoalBook` puts each goal's record with the cycle whose START named the
goal's last point, and at the cycle's END says why the cycle may not be learned from ("" if it may):
a goal that fell back to the active shaper ran without the move's factor and without the schedule at its goal,
so its residual judges a shaper the learner did not send (session 13's walk: two such cycles were learned from as
cycles of the move's factor).

Records and events come on different topics, in either order: a record that comes before its cycle's START is
kept (at most :data:`KEPT`) and claimed by the START (the latest one matching), a record that comes while its
cycle is open goes to it. A cycle's records are taken when its END comes; the records not claimed by then are
dropped (a goal is shaped before its motion, so before its cycle's END). A cycle with no record (a shaper node
that does not publish them, goals not through its proxy, a record lost) is learned from as before.

A record goes to a cycle only if it was stamped (when the shaper node sent the goal on) at or after the cycle's
START stamp less :data:`BEFORE_START`: the shaper node's ``~/shaped_goals`` is latched (depth 16), so a learner that
starts, or restarts, receives the records of goals sent before it, and a stale FALLBACK of the same move decided the
new cycle (session 15). The stamps compare on one clock: the robot's (or the simulator's simulated time) for both the
cycle events and the shaper node. A record without a stamp is matched by its move alone, as before.
"""

from __future__ import annotations

import collections
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["ACTIVE", "BEFORE_START", "FALLBACK", "KEPT", "MATCH", "SCHEDULED", "GoalBook", "GoalRecord", "refusal"]

#: the ways a goal was shaped (shaper_msgs/ShapedGoal's constants)
SCHEDULED, FALLBACK, ACTIVE = 0, 1, 2
#: rad: how far a goal's last point may be from a START's goal for the goal to be that move's (nodes/move_goals.py)
MATCH = 1e-3
#: records kept before their START, and cycles open at once (ENDs that never came are forgotten beyond it)
KEPT = 64
#: s: how long before its cycle's START a goal's record may be stamped and still be the cycle's (a motion source that
#: sends the goal, then START); a record of an earlier cycle of the same move is older by a whole other move at least
BEFORE_START = 0.5


@dataclass(frozen=True)
class GoalRecord:
    """One goal as the shaper node shaped it: how (:data:`SCHEDULED`, :data:`FALLBACK`, :data:`ACTIVE`), the
    node's detail (why it fell back; the scheduler's summary), its joints and last point (rad), and the shaper's
    source and revision (the active shaper's; revision 0 for the scheduler's)."""

    shaped_with: int
    detail: str
    joint_names: tuple[str, ...]
    goal: tuple[float, ...]
    source: str = ""
    revision: int = 0
    #: when the shaper node sent the goal on, s (its clock: the header stamp); None: not known
    stamp: float | None = None

    def after(self, start: float | None) -> bool:
        """Whether the record may be of a cycle whose START is stamped ``start`` s (None: not known)."""
        return self.stamp is None or start is None or self.stamp >= start - BEFORE_START


def refusal(record: GoalRecord, scheduled: bool) -> str:
    """Why a cycle whose goal was shaped as ``record`` says may not be learned from ("" if it may).

    Parameters
    ----------
    record : GoalRecord
        How the goal was shaped.
    scheduled : bool
        Whether the learner's goals must be shaped by the scheduler (its move factors live there): then a goal
        shaped with the active shaper as configured (:data:`ACTIVE`) is refused too. A goal that fell back
        (:data:`FALLBACK`) is refused by every per-move learner.
    """
    active = f"the active shaper ({record.source or 'unknown'}, revision {record.revision})"
    if record.shaped_with == FALLBACK:
        return f"its goal was shaped with {active}, not for its final pose: {record.detail or 'no reason given'}"
    if record.shaped_with == ACTIVE and scheduled:
        return (f"its goal was shaped with {active}: the shaper node has no action.scheduler, so the move's factor"
                " and the schedule at its goal were not applied")
    if record.shaped_with not in (SCHEDULED, ACTIVE):
        return f"its goal was shaped in a way this learner does not know (shaped_with {record.shaped_with})"
    return ""


def _matches(record: GoalRecord, names: Sequence[str], goal: Sequence[float]) -> bool:
    """Whether ``record``'s last point is ``goal`` (in the order of ``names``; empty names: the record's order)."""
    rec_names = list(record.joint_names)
    if names and rec_names:
        if sorted(rec_names) != sorted(names):
            return False
        last = [record.goal[rec_names.index(n)] for n in names]
    else:
        last = list(record.goal)
    g, q = np.asarray(goal, dtype=float), np.asarray(last, dtype=float)
    return g.shape == q.shape and g.size > 0 and bool(np.allclose(g, q, atol=MATCH, rtol=0))


class GoalBook:
    """The goals' records per cycle (module docstring). Feed it every cycle event as it is received
    (:meth:`start`, :meth:`end`) and every record (:meth:`shaped`); ask :meth:`refusal` at the END's handling."""

    def __init__(self) -> None:
        self._pending: collections.deque[GoalRecord] = collections.deque(maxlen=KEPT)
        #: open cycles: cycle -> (joint names, goal, records, START stamp)
        self._open: dict[int, tuple[list[str], list[float], list[GoalRecord], float | None]] = {}
        #: ended cycles' records, until asked
        self._ended: dict[int, list[GoalRecord]] = {}

    def start(self, cycle: int, names: Sequence[str], goal: Sequence[float], stamp: float | None = None) -> None:
        """A cycle's START (received, or stood in for) stamped ``stamp`` s: the move's joints and goal (rad); it
        claims the latest record that came before it stamped from its START on (module docstring)."""
        claimed = [r for r in self._pending if _matches(r, names, goal) and r.after(stamp)][-1:]
        for r in claimed:
            self._pending.remove(r)
        self._open[int(cycle)] = (list(names), [float(x) for x in goal], claimed, stamp)
        while len(self._open) > KEPT:
            self._open.pop(next(iter(self._open)))

    def shaped(self, record: GoalRecord) -> None:
        """A goal's record: to the latest open cycle of its move, else kept for a START to come."""
        for names, goal, records, stamp in reversed(list(self._open.values())):
            if _matches(record, names, goal) and record.after(stamp):
                records.append(record)
                return
        self._pending.append(record)

    def end(self, cycle: int) -> None:
        """A cycle's END: its records are kept for :meth:`refusal`; records no START claimed are dropped."""
        opened = self._open.pop(int(cycle), None)
        if opened is not None:
            self._ended[int(cycle)] = opened[2]
            while len(self._ended) > KEPT:
                self._ended.pop(next(iter(self._ended)))
        self._pending.clear()

    @property
    def unclaimed(self) -> int:
        """Records kept for a START to come."""
        return len(self._pending)

    def records(self, cycle: int) -> list[GoalRecord]:
        """The records of an ended cycle (without taking them)."""
        return list(self._ended.get(int(cycle), ()))

    def refusal(self, cycle: int, scheduled: bool) -> str:
        """Why the ended ``cycle`` may not be learned from, "" if it may (or has no record); taken once."""
        for record in self._ended.pop(int(cycle), ()):
            why = refusal(record, scheduled)
            if why:
                return why
        return ""
