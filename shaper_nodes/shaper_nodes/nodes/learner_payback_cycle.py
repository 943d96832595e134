"""What the learner node's payback mode (:mod:`.learner_payback`) keeps of a cycle and reads from a move's entry:
the cycle's checked samples (:class:`CycleCapture`), its M (:func:`residual_m`), a move's phase and factor as saved
before stacks were (:func:`phase`, :func:`factor_of`, :func:`legacy_stack`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from shaper_nodes.core.learning.list import ListLearner, ListParams
from shaper_nodes.core.learning.list.stack import FactorStack
from shaper_nodes.core.learning.list.trials import ListUpdate
from shaper_nodes.core.learning.moves import MoveEntry
from shaper_nodes.core.shaping import Shaper
from shaper_nodes.core.shaping.vibration import residual_vibration

__all__ = ["RESIDUAL_WINDOW", "Captured", "CycleCapture", "factor_of", "legacy_stack", "phase", "residual_m",
           "unshaped"]

#: length of the window M is measured over, from the shaped command's end, s (the demo's residual window)
RESIDUAL_WINDOW = 1.0

@dataclass
class Captured:
    """One cycle's samples as :class:`~shaper_nodes.core.learning.list.ListSession` hands them over."""

    times: np.ndarray
    accel: np.ndarray
    motion_end: float
    end: float
    used: ListParams | None


class CycleCapture(ListLearner):
    """A learner for :class:`~shaper_nodes.core.learning.list.ListSession` that learns nothing: it keeps the cycle's
    checked samples (:attr:`captured`) for the payback rule, so the session's bookkeeping (the cycle's samples,
    saturation, stale sensor, the shaper it ran with) is the one the iterative LIST uses."""

    def __init__(self) -> None:
        super().__init__()
        self.captured: Captured | None = None

    def update(self, times: Any, accel: Any, motion_end: float, end: float, used: ListParams | None,
               direction: float = 1.0) -> ListUpdate:
        a = np.asarray(accel, dtype=float)
        t = np.asarray(times, dtype=float)
        self.captured = Captured(t, a.reshape(t.size, -1), float(motion_end), float(end), used)
        return ListUpdate(0, math.nan, math.nan, used, used, "none", "reference" if used is None else "hold",
                          "captured for the payback rule")


def factor_of(entry: MoveEntry) -> ListParams | None:
    """The two-impulse factor a move's entry holds (on trial or kept), None if none."""
    if entry.correction is None:
        return None
    a, t = entry.correction
    return ListParams(float(a[0]), float(t[-1])) if len(a) == 2 else None


def phase(entry: MoveEntry, held: bool) -> str:
    """The move's phase: ``held`` (the schedule alone: nothing paid), ``reference`` (its next cycle is the
    schedule alone, measured as the base), ``trial`` (the chosen factor, to be judged) or ``kept`` (it paid)."""
    if held:
        return "held"
    if entry.base is None or factor_of(entry) is None:
        return "reference"
    return "kept" if entry.best is not None and entry.best != entry.base else "trial"


def legacy_stack(entry: MoveEntry, held: bool) -> FactorStack:
    """The factors of a move saved before stacks were (one factor per move: :func:`phase` of its entry)."""
    ph, f = phase(entry, held), factor_of(entry)
    if ph == "trial":
        return FactorStack([], f)
    return FactorStack([f], None, True) if ph == "kept" and f is not None else FactorStack()


def residual_m(cap: Captured, shaper_end: float) -> tuple[float, float]:
    """The cycle's M (m/s^2: RMS of the accelerometer's deviation from its mean over :data:`RESIDUAL_WINDOW` s from
    the shaped command's end, MOTION_END + ``shaper_end`` s, cut at END) and that end (s from START)."""
    start = cap.motion_end + shaper_end
    res = residual_vibration(cap.times, cap.accel, start, min(start + RESIDUAL_WINDOW, cap.end), remove_mean=True)
    return float(res.rms), start


def unshaped(base: Shaper | None) -> bool:
    """Whether a move has no schedule at its goal (none, or the scheduler's family ``none``: one impulse)."""
    return base is None or len(base) == 1
