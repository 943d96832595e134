"""Cycle events (shaper_msgs/CycleEvent) with a START a listener missed stood in for, written once.

The rule is the core's (:class:`~shaper_nodes.core.cycles.MissedStarts`); here it is applied to messages:
:class:`EventStream` turns each event received into the messages to handle, a START made from a later event's
``start_stamp`` (every field but the kind and the stamp copied from it) when the listener missed it, and a
publisher fills the field with :func:`set_start_stamp`. A message without the field (decoded from an older
definition) or with it empty carries no start stamp.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from shaper_nodes.core.cycles import START, MissedStarts, start_stamp
from shaper_nodes.core.stamps import stamp_to_sec


def set_start_stamp(msg: Any, start_s: float) -> None:
    """Fill ``msg``'s ``start_stamp`` with the cycle's START stamp ``start_s`` (s)."""
    from shaper_nodes.ros.conversions import sec_to_time

    msg.start_stamp = [sec_to_time(start_s)]


@dataclass(frozen=True)
class Handled:
    """One event to handle: the message (a stood-in START is a copy), its stamp (s), and whether it is a START
    stood in for."""

    msg: Any
    stamp: float
    stood_in: bool = False


class EventStream:
    """A listener's cycle events, each START it missed stood in for (when the later event carries its stamp)."""

    def __init__(self) -> None:
        self.rule = MissedStarts()

    def handle(self, msg: Any) -> list[Handled]:
        """The messages to handle for ``msg``, in order."""
        out = []
        for ev in self.rule.events(msg.event, msg.cycle, stamp_to_sec(msg.header.stamp), start_stamp(msg)):
            if not ev.stood_in:
                out.append(Handled(msg, ev.t))
                continue
            start = type(msg)(header=type(msg.header)(frame_id=msg.header.frame_id, stamp=msg.start_stamp[0]),
                              event=START, cycle=msg.cycle, task=msg.task, joint_names=list(msg.joint_names),
                              start_positions=list(msg.start_positions), goal_positions=list(msg.goal_positions),
                              start_stamp=list(msg.start_stamp))
            out.append(Handled(start, ev.t, True))
        return out
