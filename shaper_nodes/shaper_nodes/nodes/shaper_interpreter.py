"""The shaper node's process: the interpreter tuned so that the streamed inputs' thread is never held for long
by whole-trajectory work on another thread (nodes/shaper.py, its module docstring's "Threads").

:func:`tune_interpreter` shortens the thread switch interval and keeps full garbage collections away while a long
trajectory's messages are alive; :func:`background_pause` is the pause whole-trajectory work takes every 100
points it builds.
"""

from __future__ import annotations

import gc
import sys
import time

__all__ = ["BACKGROUND_PAUSE", "GC_THRESHOLDS", "SWITCH_INTERVAL", "background_pause", "tune_interpreter"]

#: s, the interpreter's thread switch interval in this node (Python's default is 5 ms, ten command
#: periods at 2 kHz): a thread shaping a long trajectory gives the streaming thread the interpreter
#: within this time
SWITCH_INTERVAL = 2e-4
#: s, how long the side thread sleeps after each 100 points of a whole trajectory's message it builds
#: (about 1 ms of work): whole trajectories are background work, the stream comes first
BACKGROUND_PAUSE = 1e-3
#: the collector's thresholds in this node (Python's default is (700, 10, 10)); see tune_interpreter
GC_THRESHOLDS = (700, 10, 1000)


def background_pause() -> None:
    """Whole-trajectory work yields the interpreter to the stream for a while (see BACKGROUND_PAUSE)."""
    time.sleep(BACKGROUND_PAUSE)


def tune_interpreter() -> None:
    """Thread switches within :data:`SWITCH_INTERVAL`; no full garbage collection while a long
    trajectory's messages are alive (each would scan them all, holding the interpreter for tens of ms):
    the objects made at start-up are frozen out of the collector and the oldest generation is
    collected only after :data:`GC_THRESHOLDS` [2] collections of the middle one. Messages hold no
    reference cycles, so they are freed by reference counting as before."""
    sys.setswitchinterval(SWITCH_INTERVAL)
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLDS)
