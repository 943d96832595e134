"""A FollowJointTrajectory goal matched to the move whose cycle START announced it, and the goals recorded per move
(:class:`GoalRecorder`, the payback rule's planned commands): the per-move learners' glue.

A per-move learner that serves its own FollowJointTrajectory proxy (:mod:`.learner_moves_mrilc`, :mod:`.learner_speed`)
gets each move twice: its START on ``/cycle_events`` (the move's start and goal poses: its identity) and its goal on
the action. The two come on different topics, in either order. :func:`await_match` waits, bounded, for the START
whose goal pose is the goal's last point (within :data:`MATCH` rad, :func:`goal_matches`).
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from trajectory_msgs.msg import JointTrajectory

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.learning.move_cycles import MATCH, goal_matches
from shaper_nodes.core.learning.speed import motion_end_index
from shaper_nodes.ros.conversions import trajectory_arrays

__all__ = ["KEPT_GOALS", "MATCH", "POLL", "GoalRecorder", "Planned", "await_match", "goal_matches"]

#: s between two looks for the START
POLL = 0.01
T = TypeVar("T")
#: goals kept by :class:`GoalRecorder` (the latest of each move is the one used)
KEPT_GOALS = 32


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


def load_moves(node: Any, doc: dict[str, Any]) -> tuple[Any, dict[str, list[str]]]:
    """A per-move learner's saved moves (``doc["moves"]``) and their joint names (``doc["joint_names"]``), entry by
    entry: a broken entry is left out (its move starts afresh) and reported on ``node`` (``state_problem``, the
    ``state_file`` status at ERROR). Returns the :class:`~shaper_nodes.core.learning.moves.MoveStore` and the joint
    names of the moves kept; raises :class:`~shaper_nodes.core.learning.moves.MoveError` for joint names that are
    not lists of names."""
    from shaper_nodes.core.learning.moves import MoveError, store_from_doc
    from shaper_nodes.ros.diagnostics import ERROR

    store, problems = store_from_doc(doc["moves"])
    names = doc.get("joint_names") or {}
    if not isinstance(names, dict) or not all(isinstance(n, list) and all(isinstance(x, str) for x in n)
                                              for n in names.values()):
        raise MoveError("joint_names must map each move to a list of joint names")
    if problems:
        text = "; ".join(f"move {k}: {why}" for k, why in problems.items())
        node.state_problem = f"{len(problems)} move entr{'y' if len(problems) == 1 else 'ies'} left out" \
                             f" (they start afresh): {text}"
        node.diagnostics.report("state_file", ERROR, node.state_problem)
    return store, {k: list(n) for k, n in names.items() if k in store}


@dataclass(frozen=True)
class Planned:
    """A goal's planned waypoints in the order of the cycle event's joints: times (N,) s from its start,
    positions (N, J) rad, velocities (N, J) rad/s or None."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None


class GoalRecorder:
    """The goals seen by the learner's proxy (its ``shape`` callable: checked, recorded, sent on unchanged)."""

    def __init__(self) -> None:
        self._goals: collections.deque[tuple[list[str], np.ndarray, dict[str, np.ndarray]]] = \
            collections.deque(maxlen=KEPT_GOALS)

    def record(self, traj: JointTrajectory) -> JointTrajectory:
        """The goal request's check (its arrays readable, :class:`InputError` if not) and its record."""
        names = list(traj.joint_names)
        times, fields = trajectory_arrays(traj, names, True)
        if len(times) < 2:
            raise InputError("empty", "a goal needs at least two points to be a move")
        self._goals.append((names, times, fields))
        return traj

    def lookup(self, names: list[str], start: np.ndarray, goal: np.ndarray) -> Planned | None:
        """The latest goal from ``start`` to ``goal`` (rad, in the order of ``names``), None if none was seen: its
        motion only (the points that hold the final pose after it left out: the settling is the motion's), from the
        start pose at 0 s (a goal's first point comes after it, as for joint_trajectory_controller)."""
        q0 = np.asarray(start, dtype=float)
        for got, times, fields in reversed(self._goals):
            if sorted(got) != sorted(names):
                continue
            order = [got.index(n) for n in names]
            q = fields["positions"][:, order]
            if not (goal_matches(q0, q[0]) and goal_matches(np.asarray(goal), q[-1])):
                continue
            v = fields.get("velocities")
            v = np.zeros_like(q) if v is None else v[:, order]
            n = max(motion_end_index(q), 1) + 1
            t, q, v = times[:n], q[:n], v[:n]
            if t[0] > 0.0:
                t, q, v = np.r_[0.0, t], np.vstack([q0, q]), np.vstack([np.zeros_like(q0), v])
            return Planned(t, q, v)
        return None
