"""When the scheduler sends a new shaper: the rate limit, free of ROS.

A scheduled shaper is sent only when a mode moved enough since the last one sent (the relative
change of :func:`~.scheduler.relative_change` at least ``relative_change``), and not sooner than
``min_interval`` after it, nor sooner than the shaper node retires shapers bumplessly: a switch
keeps the old filter alive for the active shaper's duration, and the node keeps at most
``max_stages - 1`` earlier shapers alive (:data:`~shaper_nodes.core.shaping.MAX_STAGES`), so a new
shaper every ``duration / (max_stages - 1)`` s is the fastest the node takes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from shaper_nodes.core.checks import in_range
from shaper_nodes.core.shaping.fir import MAX_STAGES
from shaper_nodes.core.shaping.types import Mode

from .fuzzy import FuzzyError
from .scheduler import relative_change


@dataclass(frozen=True)
class RateLimit:
    """The scheduler's rate limit (see the module docstring).

    Attributes
    ----------
    relative_change : float
        Least relative change of a mode that sends a new shaper, fraction (0: every change).
    min_interval : float
        Least time between two shapers sent, s.
    max_stages : int
        Shapers the shaper node keeps alive at once.
    """

    relative_change: float = 0.01
    min_interval: float = 0.1
    max_stages: int = MAX_STAGES

    def __post_init__(self) -> None:
        in_range("relative_change", self.relative_change, 0.0, error=FuzzyError)
        in_range("min_interval", self.min_interval, 0.0, unit="s", error=FuzzyError)
        if self.max_stages < 2:
            raise FuzzyError(f"max_stages must be at least 2, got {self.max_stages}")

    def min_gap(self, active_duration: float) -> float:
        """Least time between two shapers sent while a shaper of ``active_duration`` s is active, s."""
        return max(self.min_interval, active_duration / (self.max_stages - 1))

    def moved(self, last: Sequence[Mode] | None, modes: Sequence[Mode]) -> bool:
        """Whether ``modes`` moved enough from the last modes sent (always, if none was sent)."""
        return last is None or relative_change(last, modes) >= self.relative_change

    def due(self, last: Sequence[Mode] | None, modes: Sequence[Mode], since_sent: float,
            active_duration: float) -> bool:
        """Whether to send the shaper for ``modes`` now, ``since_sent`` s after the last one was sent."""
        return self.moved(last, modes) and since_sent >= self.min_gap(active_duration)
