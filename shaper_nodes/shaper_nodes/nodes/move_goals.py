"""A FollowJointTrajectory goal matched to the move whose cycle START announced it: the per-move learners' glue.

A per-move learner that serves its own FollowJointTrajectory proxy (:mod:`.learner_moves_mrilc`, :mod:`.learner_speed`)
gets each move twice: its START on ``/cycle_events`` (the move's start and goal poses: its identity) and its goal on
the action. The two come on different topics, in either order. :func:`await_match` waits, bounded, for the START
whose goal pose is the goal's last point (within :data:`MATCH` rad, :func:`goal_matches`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

__all__ = ["MATCH", "POLL", "await_match", "goal_matches"]

#: rad: how far a goal's last point may be from a START's goal for the goal to be that move's
MATCH = 1e-3
#: s between two looks for the START
POLL = 0.01
T = TypeVar("T")


def goal_matches(goal: np.ndarray, last: np.ndarray, atol: float = MATCH) -> bool:
    """Whether a goal whose last point is ``last`` (rad) is the move whose START named ``goal`` (rad)."""
    g, q = np.asarray(goal, dtype=float), np.asarray(last, dtype=float)
    return g.shape == q.shape and bool(np.allclose(g, q, atol=atol, rtol=0))


async def await_match(node: Any, pending: Callable[[], T | None], timeout: float) -> T | None:
    """What ``pending()`` returns once it returns something (the cycle of the goal's START), looking every
    :data:`POLL` s of wall time for up to ``timeout`` s without blocking the node's executor (``node.sleep``);
    None if it never did."""
    import time

    deadline = time.monotonic() + float(timeout)
    while True:
        found = pending()
        if found is not None or time.monotonic() >= deadline:
            return found
        await node.sleep(POLL)
