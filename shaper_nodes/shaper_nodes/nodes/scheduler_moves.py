"""The scheduler node's per-move corrections: ``~/set_move_shaper`` and the move of a ``~/shaper_at`` request.

With per-move learning (the learner's ``list.per_move``), the learner sends each move's learned
two-impulse factor (or its stacked factors, convolved) with the move's start and goal poses
(shaper_msgs/SetMoveShaper); the scheduler keeps it (:class:`shaper_nodes.core.scheduling.MoveCorrections`,
ROS-free) and applies it whenever a ``~/shaper_at`` request names that move (its ``start`` and ``pose`` within
``move_tolerance`` of the move's): the schedule's shaper at the goal pose convolved with the
factor. A request without ``start``, or of a move with no factor, gets what it got before (the
schedule, times the region's correction). Nothing is sent to the shaper node: the factor applies
to the goals the shaper node's proxy shapes for their final pose (its ``action.scheduler``).
The corrections live in memory; the learner keeps them in its state file and sends them all
again when it starts (so a restarted scheduler gets them back from a restarted learner).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.node import Node

from shaper_msgs.srv import SetMoveShaper, ShaperAt
from shaper_nodes.core.scheduling import MoveCorrections
from shaper_nodes.core.shaping import Shaper, ShaperError
from shaper_nodes.ros.conversions import shaper_from_msg
from shaper_nodes.ros.qos import SERVICE_QOS


class MoveService:
    """``~/set_move_shaper`` on ``node``, and the move's shaper for ``~/shaper_at`` (module docstring)."""

    def __init__(self, node: Node, tolerance: float) -> None:
        self.node = node
        self.moves = MoveCorrections(tolerance)
        node.create_service(SetMoveShaper, "~/set_move_shaper", self._on_set, qos_profile=SERVICE_QOS)

    def _on_set(self, req: SetMoveShaper.Request, resp: SetMoveShaper.Response) -> SetMoveShaper.Response:
        source = req.shaper.source.strip()
        if source != "learner":
            resp.success, resp.message = False, f"move corrections come from the learner only, not {source!r}"
            return resp
        names = list(req.start.name)
        if list(req.goal.name) != names:
            resp.success, resp.message = False, "refused: the move's start and goal name different joints"
            return resp
        try:
            learned = shaper_from_msg(req.shaper)
            factor = None if learned.family == "none" else learned
            what = self.moves.set(names, req.start.position, req.goal.position, factor)
        except (ShaperError, ValueError) as err:
            resp.success, resp.message = False, f"refused: {err}"
            return resp
        if factor is not None:
            what += (f": factor T2 = {factor.times[1]:.4f} s, A1 = {factor.amplitudes[0]:.4f}" if len(factor) == 2 else
                     f": factors convolved, {len(factor)} impulses over {factor.times[-1]:.4f} s")
        self.node.get_logger().info(f"learner, move to [{', '.join(f'{x:.3f}' for x in req.goal.position)}]: {what}")
        resp.success, resp.message = True, what
        return resp

    def shaper(self, req: ShaperAt.Request, base: Shaper, scheduled: Callable[[], Shaper]) -> tuple[Shaper, str]:
        """The shaper for a ``~/shaper_at`` request for which the schedule gives ``base`` (with the region's
        correction; ``scheduled()``: without it), and a note for its message ("" when the request names no move)."""
        start: Any = req.start
        if not len(start.position):
            return base, ""
        names = list(start.name) or list(req.pose.name)
        if list(start.name) and list(start.name) != list(req.pose.name):
            return base, "; the move's start names other joints than the pose: no move correction"
        found = self.moves.find(names, start.position, req.pose.position)
        if found is None:
            return base, "; a move with no learned correction: the schedule alone"
        f = found.factor
        what = (f"factor (T2 {f.times[1]:.4f} s, A1 {f.amplitudes[0]:.4f})" if len(f) == 2 else
                f"factors ({len(f)} impulses over {f.times[-1]:.4f} s)")
        return MoveCorrections.apply(scheduled(), f), f"; the move's learned {what} over the schedule"
