"""The learner's corrections kept per move, over the schedule. Free of ROS (the scheduler node wraps it).

A move is a point-to-point motion from a start pose to a goal pose (a FollowJointTrajectory goal
through the shaper node's proxy). With per-move learning, the learner learns two-impulse
factors per move from that move's own residual window and sends them, convolved (one factor, or
several stacked: at most :data:`MAX_FACTOR_IMPULSES` impulses, :data:`MAX_FACTOR_DURATION` s),
with the move's start and goal; :class:`MoveCorrections` keeps it, and the shaper for a goal of that move is the
schedule's shaper at the goal pose convolved with the factor (:meth:`MoveCorrections.apply`).
The schedule still follows the pose underneath: only the factor is the move's. A move with no
factor gets the schedule alone.

Matching a request to a move: the learner's poses come from the cell's cycle events (the taught
start and goal), the proxy's from the goal's trajectory (its first point, one sample into the
move, and its last). They are the same move when every joint of both poses is within
``tolerance`` (rad or m); the nearest such move is taken. Joint names, when both sides give
them, put the request's positions in the move's order first.

Why a factor, and why per move rather than per region: a move ends at one pose, so its factor
is learned and applied at that pose only, whatever the rule base's regions; the factor
convolved with the schedule is the policy the region corrections already have for schedules on
several modes (core/scheduling/scheduler.py), so that the move's first cycle, run with the
schedule alone, is the learner's reference cycle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.shaping.families import convolve
from shaper_nodes.core.shaping.types import Shaper, ShaperError

__all__ = ["MAX_FACTOR_DURATION", "MAX_FACTOR_IMPULSES", "MAX_MOVES", "MOVE_TOLERANCE", "MoveCorrection",
           "MoveCorrections"]

#: most moves a scheduler keeps a correction for (a request for another is refused)
MAX_MOVES = 1000
#: most impulses of a move's correction: up to four two-impulse factors convolved (the learner's stacked factors)
MAX_FACTOR_IMPULSES = 16
#: longest move's correction, s (its delay adds to the schedule's on every goal of the move)
MAX_FACTOR_DURATION = 1.0
#: default largest joint difference between a request's poses and a move's for them to match, rad or m
#: (the proxy's first point is one sample into the move: 0.3 mrad on the demo's moves)
MOVE_TOLERANCE = 0.01


@dataclass(frozen=True)
class MoveCorrection:
    """One move's correction: joint names (may be empty), start and goal (rad or m), the factor."""

    names: tuple[str, ...]
    start: np.ndarray
    goal: np.ndarray
    factor: Shaper


def _pose(what: str, positions: Sequence[float], names: Sequence[str]) -> np.ndarray:
    q = np.asarray(positions, dtype=float).reshape(-1)
    if q.size == 0 or not np.all(np.isfinite(q)):
        raise ShaperError(f"the move's {what} pose must be non-empty and finite, got {list(positions)!r}")
    if names and len(names) != q.size:
        raise ShaperError(f"the move's {what} pose has {q.size} positions for {len(names)} names")
    return q


class MoveCorrections:
    """The learner's factor per move (module docstring).

    Parameters
    ----------
    tolerance : float
        Largest joint difference for a request to match a move, rad or m (> 0).
    max_moves : int
        Most moves kept.
    """

    def __init__(self, tolerance: float = MOVE_TOLERANCE, max_moves: int = MAX_MOVES) -> None:
        if not (np.isfinite(tolerance) and tolerance > 0):
            raise ShaperError(f"move tolerance must be finite and > 0, got {tolerance!r}")
        self.tolerance = float(tolerance)
        self.max_moves = int(max_moves)
        self._moves: list[MoveCorrection] = []

    def __len__(self) -> int:
        return len(self._moves)

    def set(self, names: Sequence[str], start: Sequence[float], goal: Sequence[float],
            factor: Shaper | None) -> str:
        """Keep ``factor`` for the move ``start`` -> ``goal`` (None: forget the move's factor); returns what
        was done, in a few words.

        Raises
        ------
        ShaperError
            Poses empty, non-finite, of different sizes or not matching ``names``; a factor that is
            not 2 to :data:`MAX_FACTOR_IMPULSES` impulses or longer than :data:`MAX_FACTOR_DURATION`; a new
            move beyond ``max_moves``.
        """
        names = tuple(str(n) for n in names)
        q0, q1 = _pose("start", start, names), _pose("goal", goal, names)
        if q0.size != q1.size:
            raise ShaperError(f"the move's start has {q0.size} positions and its goal {q1.size}")
        if factor is not None and not 2 <= len(factor) <= MAX_FACTOR_IMPULSES:
            raise ShaperError(f"a move's correction is two-impulse factors convolved, 2 to {MAX_FACTOR_IMPULSES}"
                              f" impulses, got {len(factor)}")
        if factor is not None and factor.times[-1] > MAX_FACTOR_DURATION:
            raise ShaperError(f"a move's correction is at most {MAX_FACTOR_DURATION:g} s long, got"
                              f" {factor.times[-1]:.4g} s")
        i = self._find(names, q0, q1)
        if factor is None:
            if i is None:
                return "no correction kept for this move: the schedule alone"
            del self._moves[i]
            return "the move's correction forgotten: the schedule alone"
        entry = MoveCorrection(names, q0, q1, factor)
        if i is not None:
            self._moves[i] = entry
            return "the move's correction replaced"
        if len(self._moves) >= self.max_moves:
            raise ShaperError(f"already {self.max_moves} moves kept (the most): a new move is refused")
        self._moves.append(entry)
        return f"a new move's correction kept ({len(self._moves)} moves)"

    def find(self, names: Sequence[str], start: Sequence[float], goal: Sequence[float]) -> MoveCorrection | None:
        """The move that ``start`` -> ``goal`` is (module docstring), or None. Poses that cannot be
        read (empty, non-finite, sizes) match no move."""
        try:
            q0, q1 = _pose("start", start, names), _pose("goal", goal, names)
        except ShaperError:
            return None
        if q0.size != q1.size:
            return None
        i = self._find(tuple(names), q0, q1)
        return None if i is None else self._moves[i]

    def _find(self, names: tuple[str, ...], q0: np.ndarray, q1: np.ndarray) -> int | None:
        best, best_d = None, np.inf
        for i, m in enumerate(self._moves):
            a, b = q0, q1
            if names and m.names and names != m.names:
                if set(m.names) - set(names):
                    continue
                order = [names.index(n) for n in m.names]
                a, b = q0[order], q1[order]
            if a.size != m.start.size:
                continue
            d = max(float(np.max(np.abs(a - m.start))), float(np.max(np.abs(b - m.goal))))
            if d <= self.tolerance and d < best_d:
                best, best_d = i, d
        return best

    @staticmethod
    def apply(base: Shaper, factor: Shaper) -> Shaper:
        """The scheduled shaper ``base`` convolved with a move's ``factor`` (family "custom", base's modes)."""
        amps, times = convolve((base.amplitudes, base.times), (factor.amplitudes, factor.times))
        return Shaper(amps, times, "custom", base.modes)
