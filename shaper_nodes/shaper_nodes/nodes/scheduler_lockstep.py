"""The scheduler as a lockstep reader of the plant's joint states (its parameter ``lockstep``).

On a robot (and by default) the scheduler evaluates the rule base on its ``period`` timer at the latest pose
and the shaper node applies a new shaper when the request arrives: the wall clock runs for every node alike.
In a lockstep simulation the plant steps as fast as it can, and the lockstep covers the plant and the shaper's
command stream only: the simulated time at which a retune reached the shaper depended on how fast the
scheduler's process took /joint_states, woke on /clock and got its request across, so a loaded machine (or a
scheduler paused for a second) retuned the shaper at other poses and moved the residuals of
reproductions/scheduler_cases.py's case (c) from run to run (session 13, H5).

With ``lockstep`` true the scheduler is one more reader of the plant (ros/lockstep_reader.py, the plant's
``lockstep.readers``, with ``lockstep.lead`` one period): it takes every joint state in order, evaluates the
rule base at the first pose stamped at or after each multiple of ``period`` (simulated time, the pose's stamp;
the rate limit counts on the same stamps), and acknowledges a pose only once the shaper node answered the
request decided on it. The plant, which never steps more than one period beyond that acknowledgement, asks the
shaper for the next step only after the retune is in: each retune takes effect at the step after the pose it
was computed from, whatever the load. Its cost: one round trip through DDS per step and per retune.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from shaper_nodes.ros.lockstep_reader import LockstepReader

__all__ = ["MODES_QOS", "STREAM", "LockstepPoses"]

#: ~/mode_estimate in lockstep: latched as on a robot (a late subscriber gets the latest), and deep, so that a
#: recorder that subscribes as deep takes every estimate of a run (the plant does not wait for it); depth 1, a
#: slow recorder missed some, and the reproduction's plot of the modes changed with the load
MODES_QOS = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: the stream name the acknowledgements count (the joint states)
STREAM = "joint_states"
#: slack on a pose's stamp against a multiple of ``period``, s (stamps are whole ns; period a decimal)
_EPS = 1e-9


class LockstepPoses:
    """The poses in order and their acknowledgements (see the module docstring).

    Parameters
    ----------
    node : rclpy Node
        The scheduler (its acknowledgements go out on ``<node>/lockstep_ack``).
    period : float
        Simulated s between two evaluations of the rule base.
    tick : callable
        ``tick(z, stamp, now)``: evaluate at premises ``z`` (stamp ``(sec, nanosec)``, ``now`` s) and send the
        shaper if due; returns False when a shaper is due but cannot go yet (set_shaper not settled: tried again).
    in_flight : callable
        Whether a request decided on a pose is still unanswered (polled; its pose is acknowledged once answered).
    unsent : callable
        Whether no shaper was sent yet (then every pose is evaluated).
    """

    def __init__(self, node: Any, period: float, tick: Callable[[list[float], tuple[int, int], float], bool],
                 in_flight: Callable[[], bool], unsent: Callable[[], bool]) -> None:
        self.reader = LockstepReader(node)
        self.period = float(period)
        self._tick, self._in_flight, self._unsent = tick, in_flight, unsent
        self._poses: deque[tuple[list[float], tuple[int, int]]] = deque()  # appended by the feed's thread
        self._index = -1            # the last multiple of period evaluated at
        self._unacked: float | None = None  # the pose taken whose request is in flight, s

    def put(self, z: list[float], stamp: tuple[int, int]) -> None:
        """On the feed's thread: a pose taken (then wake the node, which calls :meth:`drain`)."""
        self._poses.append((z, stamp))

    def drain(self) -> None:
        """On the node's executor: the poses taken, in order, each evaluated if a period began with it (every one
        while no shaper was sent yet) and acknowledged once its request (if any) is answered. Stops at a
        request in flight or a shaper that cannot go yet; called again on the answer (or the retry timer)."""
        while True:
            if self._in_flight():
                return
            if self._unacked is not None:
                self.reader.took(STREAM, self._unacked)
                self._unacked = None
            if not self._poses:
                return
            z, (sec, nanosec) = self._poses[0]
            now = sec + 1e-9 * nanosec
            index = math.floor(now / self.period + _EPS)
            if (index > self._index or self._unsent()) and not self._tick(z, (sec, nanosec), now):
                return
            if index > self._index:
                self._index = index
            self._poses.popleft()
            self._unacked = now
