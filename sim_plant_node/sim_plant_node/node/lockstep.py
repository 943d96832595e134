"""The sim plant node's side of the lockstep exchange with the shaper: its asks on the wire, the answers.

The rules (numbering, labels, layouts, late answers) are :mod:`shaper_nodes.core.lockstep`'s; this is their
ROS glue: :class:`Exchange` publishes the asks as std_msgs/Float64MultiArray, keeps the steps asked and not
yet answered, tells a late answer (counted and warned about), and when ``lockstep_timeout`` went by.
:class:`Readers` subscribes the acknowledgements of the readers a run declares (``lockstep.readers``) and tells
whether the plant may step (:class:`shaper_nodes.core.lockstep.ReaderGate`).
"""

from __future__ import annotations

import functools
import math
import struct
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from shaper_nodes.core.lockstep import Asks, ReaderGate
from shaper_nodes.ros.lockstep_reader import ACK_QOS, OutOfWaitSet, ack_topic, take_all

__all__ = ["ACK_LOOK", "Exchange", "Readers"]


#: wall s between two looks at the readers' acknowledgements while the plant steps unheld (:class:`Readers`)
ACK_LOOK = 0.01


class Readers:
    """The readers a lockstep run waits for (``lockstep.readers``), from their acknowledgements.

    The acknowledgements are out of the executor's wait set while the plant steps (each would wake it, a
    hundred us or more of its CPU, hundreds of times a second with the demo's readers): the plant takes them
    from their queues itself before a step they might hold, and every :data:`ACK_LOOK` s of wall time (a
    reader's first acknowledgement holds the plant from about the simulated time it arrives). Held, the plant
    waits on them as on any subscription, and resumes on the one that releases it.

    Parameters
    ----------
    node : rclpy Node
        The sim plant node.
    readers : sequence of str
        The readers' node names.
    lead, timeout : float
        ``lockstep.lead`` (simulated s) and ``lockstep.reader_timeout`` (wall s).
    now : callable
        The plant's simulated time, s.
    on_ack : callable, optional
        Called after each acknowledgement taken while the plant is held (a plant held by a reader resumes on it,
        not on a poll).
    """

    def __init__(self, node: Any, readers: Any, lead: float, timeout: float, now: Callable[[], float],
                 on_ack: Callable[[], None] | None = None) -> None:
        names = ["/" + str(r).strip("/") for r in readers]
        self.gate = ReaderGate(names, lead, timeout)
        self._log = node.get_logger()
        self._now = now
        self._on_ack_hook = on_ack
        self._group = OutOfWaitSet()  # waited on only while the plant is held
        self._subs = {r: node.create_subscription(Clock, ack_topic(r), lambda raw, r=r: self._on_ack(r, raw), ACK_QOS,
                                                  raw=True, callback_group=self._group) for r in names}
        self._looked = -math.inf  # wall time of the last look at the queues
        #: acknowledgements taken (from the queues, or waking the plant while held)
        self.taken = 0

    def _apply(self, reader: str, raw: bytes) -> None:
        sec, nanosec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)  # rosgraph_msgs/Clock
        self.taken += 1
        line = self.gate.ack(reader, -1.0 if sec < 0 else sec + nanosec * 1e-9, self._now())
        if line:
            self._log.info(line)

    def _on_ack(self, reader: str, raw: bytes) -> None:
        self._apply(reader, raw)
        self.take()
        if self._on_ack_hook is not None:
            self._on_ack_hook()

    def take(self) -> None:
        """Take every acknowledgement queued, in order per reader."""
        self._looked = time.monotonic()
        for reader, sub in self._subs.items():
            take_all(sub, Clock, functools.partial(self._taken, reader), 1000)

    def _taken(self, reader: str, got: tuple[bytes, Any]) -> None:
        self._apply(reader, got[0])

    @property
    def waited(self) -> bool:
        """Whether the executor waits on the acknowledgements (the plant is held)."""
        return self._group.waited

    def may_step(self, t: float) -> bool:
        """Whether the plant may step to simulated time ``t`` s now (a reader that went away is dropped, and one
        that holds the plant past ``lockstep.reader_timeout``, each with one line). Held, the acknowledgements
        wake the executor until a step is allowed again."""
        if not self._subs:
            return True
        if self.gate.holding(t) or time.monotonic() - self._looked > ACK_LOOK:
            self.take()
        if not self.gate.holding(t):
            self.gate.may_step(t, 0.0)  # (not waiting any more)
            self._group.waited = False
            return True
        for reader, sub in self._subs.items():  # (only while held: a graph query)
            if sub.get_publisher_count() == 0:
                line = self.gate.leave(reader)
                if line:
                    self._log.warning(line)
        ok, line = self.gate.may_step(t, time.monotonic())
        if line:
            self._log.error(line)
        self._group.waited = not ok
        return ok


class Exchange:
    """The asks of a lockstep plant and their answers.

    Parameters
    ----------
    publisher : rclpy publisher
        Where the asks (raw setpoints, ``topics.command_out``) go.
    joints : int
        Values per setpoint.
    block : int
        Steps asked per exchange at most (``lockstep.block``).
    logger : rclpy logger
        Warns of late answers and timeouts.
    """

    def __init__(self, publisher: Any, joints: int, block: int, logger: Any) -> None:
        self._pub = publisher
        self.joints = joints
        self.block = block
        self._log = logger
        self.asks = Asks(joints, block > 1)  # numbers the asks, tells the late answers
        #: the steps asked of the shaper and not yet answered: (cycle events, preroll ends) each
        self.asked: list[tuple[list, bool]] = []
        #: wall time (monotonic, s) the pending ask went out; None: none pending
        self.waiting_since: float | None = None
        self.timeouts = 0
        self.late_answers = 0  # answers to an earlier ask, ignored

    def ask(self, steps: list[tuple[list, bool]], raws: list[np.ndarray]) -> None:
        """Publish the raw setpoints ``raws`` of the next ``steps`` as one ask and wait for its answer."""
        self.asked.extend(steps)
        msg = Float64MultiArray(data=(raws[-1] if self.block == 1 else np.concatenate(raws)).tolist())
        msg.layout.dim = [MultiArrayDimension(label=d.label, size=d.size, stride=d.stride)
                          for d in self.asks.next(len(raws))]
        self._pub.publish(msg)
        self.waiting_since = time.monotonic()

    def late(self, msg: Float64MultiArray) -> bool:
        """Whether ``msg`` answers an earlier ask (then it is counted, with a warning, and to be ignored)."""
        label = msg.layout.dim[0].label if msg.layout.dim else None
        if not self.asks.late(label):
            return False
        self.late_answers += 1
        self._log.warning(f"ignored a late answer to '{label}' (it came after lockstep_timeout; pending:"
                          f" '{self.asks.pending}')", throttle_duration_sec=5.0)
        return True

    def rows(self) -> int:
        """The setpoints an answer carries: the steps asked (1 when none is pending)."""
        return len(self.asked) if self.waiting_since is not None else 1

    def take(self) -> list[tuple[list, bool]]:
        """The steps asked, now answered (or given up): none is pending any more."""
        asked, self.asked = self.asked, []
        self.waiting_since = None
        return asked

    def unmatched(self, answers: Any) -> str:
        """What the loop through the shaper still lacks on DDS ('' if nothing), the shaped setpoints coming in on
        the subscription ``answers``: a step waits for the shaped answer to its raw setpoint, so a run started
        before the raw setpoints reach a subscription, or before a publisher's shaped setpoints reach the plant,
        loses its first setpoint and stalls for ``lockstep_timeout``. (Matched, not only discovered: a driver
        that sees the shaper in the graph may see it before the plant matches it.)"""
        missing = []
        if self._pub.get_subscription_count() == 0:
            missing.append(f"the raw setpoints on {self._pub.topic_name} have no matched subscription")
        if answers.get_publisher_count() == 0:
            missing.append(f"the shaped setpoints on {answers.topic_name} have no matched publisher")
        return "; ".join(missing)

    def overdue(self, timeout: Callable[[], float]) -> bool:
        """Whether the pending ask waited ``timeout()`` s of wall time (``lockstep_timeout``; then it is
        counted, with a warning)."""
        if self.waiting_since is None or time.monotonic() - self.waiting_since < timeout():
            return False
        self.timeouts += 1
        self._log.warning("no shaped setpoint within lockstep_timeout; holding the last setpoint",
                          throttle_duration_sec=5.0)
        return True
