"""A move's stacked LIST factors: the two-impulse factors kept (each because it paid), and the one on trial.

Where two modes ring in a move, one two-impulse factor cancels one of them. The reproduction's per-move rule
(``reproductions.arm_learning``, ``scheduled_list_factor``) stacks factors: after a factor is kept, the move's
next cycle is a new reference with the kept factor in place, and the next factor is chosen on what still rings,
up to a number of factors. :class:`FactorStack` is that state for one move; :func:`stack_shaper` the one impulse
sequence the move's goals run with (the factors convolved: 2**n impulses for n factors, their T2s summed).

ROS-free: the learner node (``nodes/learner_payback.py``) keeps one per move in its state file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from shaper_nodes.core.shaping import Shaper
from shaper_nodes.core.shaping.families import convolve

from .params import ListError, ListParams

__all__ = ["MAX_FACTORS", "FactorStack", "Wanted", "factors_of", "stack_duration", "stack_shaper", "wanted"]

#: most factors stacked on one move (2**4 = 16 impulses: the scheduler's limit on a move's correction)
MAX_FACTORS = 4


def _pair(value: Any, what: str) -> ListParams:
    if not (isinstance(value, Sequence) and len(value) == 2):
        raise ListError(f"{what} must be [a1, t2], got {value!r}")
    try:
        return ListParams(float(value[0]), float(value[1])).check()
    except (TypeError, ValueError) as err:
        raise ListError(f"{what}: {err}") from None


@dataclass
class FactorStack:
    """One move's factors: ``kept`` (each paid, in the order kept), ``trial`` (the factor its next cycle tries,
    None if none) and ``done`` (no more factor is looked for: the last trial did not pay, none was predicted to,
    or ``max_factors`` were kept)."""

    kept: list[ListParams] = field(default_factory=list)
    trial: ListParams | None = None
    done: bool = False
    #: with no schedule: the accelerometer's settled band of the move, m/s^2 (set at its first reference)
    band: float | None = None

    def factors(self) -> tuple[ListParams, ...]:
        """What the move's goals run with: the kept factors, then the trial (empty: the schedule alone)."""
        return (*self.kept, self.trial) if self.trial is not None else tuple(self.kept)

    def phase(self, held: bool, max_factors: int) -> str:
        """``held`` (the schedule alone: nothing paid), ``trial``, ``kept`` (no more factor looked for: the move
        runs with its kept factors) or ``reference`` (its next cycle, with the kept factors, is measured as the
        base the next factor is chosen from and judged against)."""
        if held:
            return "held"
        if self.trial is not None:
            return "trial"
        if self.kept and (self.done or len(self.kept) >= max_factors):
            return "kept"
        return "reference"

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kept": [[p.a1, p.t2] for p in self.kept],
                             "trial": None if self.trial is None else [self.trial.a1, self.trial.t2],
                             "done": self.done}
        if self.band is not None:
            d["band"] = self.band
        return d

    @classmethod
    def from_dict(cls, d: Any) -> FactorStack:
        """A stack saved by :meth:`to_dict`, checked (:class:`ListError` names the problem)."""
        if not isinstance(d, Mapping) or set(d) - {"band"} != {"kept", "trial", "done"}:
            raise ListError(f"a factor stack has the entries done, kept and trial (and may have band), got {d!r}")
        band = d.get("band")
        if band is not None and (isinstance(band, bool) or not isinstance(band, (int, float))
                                 or not math.isfinite(band) or band <= 0):
            raise ListError(f"band must be a finite number > 0 m/s^2, got {band!r}")
        if not isinstance(d["kept"], list) or len(d["kept"]) > MAX_FACTORS:
            raise ListError(f"kept must be a list of at most {MAX_FACTORS} factors, got {d['kept']!r}")
        if not isinstance(d["done"], bool):
            raise ListError(f"done must be true or false, got {d['done']!r}")
        kept = [_pair(v, "a kept factor") for v in d["kept"]]
        trial = None if d["trial"] is None else _pair(d["trial"], "the trial")
        return cls(kept, trial, d["done"], None if band is None else float(band))


def stack_duration(factors: Sequence[ListParams]) -> float:
    """The convolved factors' duration, s (their T2s summed)."""
    return float(sum(p.t2 for p in factors))


def stack_shaper(factors: Sequence[ListParams], structure: str = "zv2") -> Shaper | None:
    """The factors convolved into one impulse sequence (None for none; one factor: its own shaper, unchanged)."""
    if not factors:
        return None
    if len(factors) == 1:
        return factors[0].shaper(structure)
    first = factors[0].shaper(structure)
    amps, times = first.amplitudes, first.times
    for p in factors[1:]:
        sh = p.shaper(structure)
        amps, times = convolve((amps, times), (sh.amplitudes, sh.times))
    return Shaper(amps, times, "custom")


#: what a move's goals run with, comparable: None (the schedule alone), one factor, or the stacked factors
Wanted = ListParams | tuple[ListParams, ...] | None


def factors_of(params: Wanted) -> tuple[ListParams, ...]:
    """The factors of a :data:`Wanted` (empty: the schedule alone)."""
    return () if params is None else params if isinstance(params, tuple) else (params,)


def wanted(factors: Sequence[ListParams]) -> Wanted:
    """What a move's goals run with, comparable: None (the schedule alone), the one factor, or the factors."""
    if not factors:
        return None
    return factors[0] if len(factors) == 1 else tuple(factors)
