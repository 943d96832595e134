"""The identifier's drift watch against the shaper each move ran with, asked of the scheduler (``watch.scheduler``).

A shaper node that shapes each goal through the scheduler (its ``action.scheduler``) does not change its
active shaper: every goal is shaped with the schedule's shaper at the goal's final pose (and the learner's
factor for that move, if one is set). Rated against the active shaper (the identity, by default), no cycle
would ever be watched. With ``watch.scheduler`` set, the identifier asks that scheduler, at each cycle's
START, for the shaper of the cycle's move (``<scheduler>/shaper_at`` with the START's joint names, its goal
as ``pose`` and its start as ``start``: exactly what the shaper node's proxy asks for the move's goal), and
rates the cycle's mode against that shaper once the cycle has ended. The call does not block the node (a
:class:`~shaper_nodes.ros.shaper_client.PendingCall`, polled at the cycle's end); a cycle whose START named no
joints, whose scheduler did not answer by its end, or which the scheduler gave no shaper for, is not rated
(the reason on the log; the count of cycles in a row outside the band is left as it was).

Each move has its own :class:`~shaper_nodes.core.identification.drift.DriftWatch` (its key: the START's start
and goal, :func:`~shaper_nodes.core.learning.moves.move_key`), so the count of cycles in a row outside the band
is the move's own: a cycle of another move whose mode did not drift (a payload moves some modes far more
than others) neither ends the count nor, once a move warns, the warning. The status ``identifier: drift`` is
WARN while any move's watch warns (:meth:`MoveShapers.drifted`), OK when none does. Each move's watch keeps
its own baseline (the modes of the move's first ``watch.baseline_cycles`` watched cycles), for the node's
life: a mode outside the band present since then is not drift (:mod:`shaper_nodes.core.identification.drift`).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable

from rclpy.node import Node
from sensor_msgs.msg import JointState

from shaper_msgs.msg import CycleEvent
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import ShaperAt
from shaper_nodes.core.identification.drift import DriftWatch
from shaper_nodes.core.learning.moves import MoveError, move_key
from shaper_nodes.ros.diagnostics import Diagnostics
from shaper_nodes.ros.shaper_client import PendingCall, ServiceClient

#: cycles whose question is kept until their end (older ones, never ended, are dropped)
MAX_PENDING = 64


class MoveShapers:
    """The shaper each cycle's move ran with, from the scheduler's ``~/shaper_at`` (module docstring).

    Parameters
    ----------
    node : Node
        The identifier node.
    scheduler : str
        Fully qualified name of the scheduler node.
    timeout : callable returning float
        Longest wait for the scheduler's answer, s of wall time.
    diagnostics : Diagnostics
        Where a call that times out is reported.
    new_watch : callable returning DriftWatch
        A move's watch (its ``confirm`` and baseline), made at the move's first rated cycle.
    """

    def __init__(self, node: Node, scheduler: str, timeout: Callable[[], float], diagnostics: Diagnostics,
                 new_watch: Callable[[], DriftWatch]) -> None:
        self.client = ServiceClient(node, ShaperAt, f"{scheduler.rstrip('/')}/shaper_at", timeout, diagnostics)
        self._asked: OrderedDict[int, tuple[PendingCall | str, str]] = OrderedDict()
        self.new_watch = new_watch
        #: per move key, its drift watch
        self.watches: dict[str, DriftWatch] = {}

    def on_start(self, msg: CycleEvent) -> None:
        """A cycle's START: ask the scheduler for the shaper of its move (not awaited)."""
        cycle = int(msg.cycle)
        names, start, goal = list(msg.joint_names), list(msg.start_positions), list(msg.goal_positions)
        if not names or len(goal) != len(names):
            self._keep(cycle, "", f"its START names {len(names)} joints and {len(goal)} goal positions: no move to ask"
                              f" {self.client.srv_name} about")
            return
        req = ShaperAt.Request(pose=JointState(name=names, position=goal),
                               start=JointState(name=names if len(start) == len(names) else [],
                                                position=start if len(start) == len(names) else []))
        try:
            key = move_key(start if len(start) == len(goal) else goal, goal)
        except MoveError as err:
            self._keep(cycle, "", f"its move cannot be identified: {err}")
            return
        self._keep(cycle, key, self.client.start(req))

    def _keep(self, cycle: int, key: str, asked: PendingCall | str) -> None:
        self._asked[cycle] = (asked, key)
        while len(self._asked) > MAX_PENDING:
            self._asked.popitem(last=False)

    def shaper(self, cycle: int) -> tuple[ShaperMsg | None, str, DriftWatch | None]:
        """The shaper ``cycle``'s move ran with and the move's watch, or None, why it is not known, None."""
        kept = self._asked.pop(cycle, None)
        if kept is None:
            return None, "its START was not seen", None
        asked, key = kept
        if isinstance(asked, str):
            return None, asked, None
        answer = asked.result()
        if answer is None:
            return None, f"{self.client.srv_name} had not answered by the cycle's end", None
        if answer.response is None:
            return None, answer.error, None
        if not answer.response.success:
            return None, f"{self.client.srv_name} gave no shaper for its move: {answer.response.message}", None
        if key not in self.watches:
            self.watches[key] = self.new_watch()
        return answer.response.shaper, "", self.watches[key]

    def drifted(self) -> list[str]:
        """The moves whose watch warns (their keys)."""
        return [key for key, watch in self.watches.items() if watch.warning]
