"""The core's copies of interface constants agree with the messages (the core cannot import them)."""

from __future__ import annotations

from shaper_msgs.msg import CycleEvent
from shaper_nodes.core import cycles


def test_cycle_event_codes_are_the_messages():
    assert (cycles.START, cycles.MOTION_END, cycles.END) == (CycleEvent.START, CycleEvent.MOTION_END,
                                                              CycleEvent.END)
