"""Learning to move faster: a per-move time-scaling factor raised while the move stays good.

A move's planned trajectory q(t) run ``s`` times faster is q(s t): velocities x s, accelerations
x s^2, duration / s, the same path. :class:`SpeedLearner` learns ``s`` for one move from its
cycles, as one of FANUC's learning-vibration-control patents describes the idea (raise the speed
over repetitions while the vibration stays within an allowed bound):

- after a good cycle (the settled residual within the tolerance and every joint limit held) the
  factor is raised by ``step``, up to ``ceiling`` (the largest factor the joint velocity and
  acceleration limits allow on the planned profile, :func:`limit_ceiling`), and, given the peaks the cycle measured
  (joint torques, speeds) and their limits, no further than the factor whose predicted peaks stay within the limits
  less a margin (:mod:`.speed_peaks`); a raise that would be smaller than ``resolution`` is not made: the factor
  holds, and the learner says which joint's prediction held it;
- after a bad cycle (either violated) it is lowered at once to the largest factor that was good,
  and the failed factor is remembered: later raises go half way between the two (bisection), and
  the learner holds once they are closer than ``resolution``;
- the learner never goes below ``floor`` (1: never slower than planned; a move that fails at the
  floor holds there and says so).

It is deterministic and its state is a JSON-ready dictionary (:meth:`SpeedLearner.to_dict`,
:meth:`SpeedLearner.from_dict`, every entry checked).

What a node needs around it, measurable on a robot (the learner node's ``speed_moves`` mode), lives in
:mod:`.speed_limits` and is handed on here: :func:`time_scale`, :func:`limit_breach`, :func:`effort_check`,
:func:`peak_check`, :func:`acceleration_tolerance`, :func:`limit_ceiling` (and :class:`SpeedError`, the one error
of both).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .speed_limits import (
    SpeedError,
    _positive,
    acceleration_tolerance,
    effort_check,
    limit_breach,
    limit_ceiling,
    limits_held,
    motion_end_index,
    peak_check,
    time_scale,
)
from .speed_peaks import POWERS, PeakLimits, allowed_factor

__all__ = ["SPEED_VERSION", "SpeedError", "SpeedLearner", "SpeedSettings", "acceleration_tolerance", "effort_check",
           "limit_breach", "limit_ceiling", "limits_held", "motion_end_index", "peak_check", "time_scale"]

#: version of :meth:`SpeedLearner.to_dict`'s dictionaries (1: without the measured peaks; still read)
SPEED_VERSION = 2
_KEYS_V1 = {"version", "settings", "factor", "good", "failed", "history"}
_KEYS = _KEYS_V1 | {"peaks", "cap"}


@dataclass(frozen=True)
class SpeedSettings:
    """Settings of :class:`SpeedLearner` (dimensionless factors).

    Attributes
    ----------
    step : float
        Raise of the factor after a good cycle while no factor has failed.
    floor : float
        Smallest factor (1: the planned speed).
    ceiling : float
        Largest factor (from the joint limits, :func:`limit_ceiling`).
    resolution : float
        The learner holds once the good and the failed factor are closer than this.
    """

    step: float = 0.1
    floor: float = 1.0
    ceiling: float = 2.0
    resolution: float = 0.02

    def __post_init__(self) -> None:
        for name in ("step", "floor", "ceiling", "resolution"):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        if self.ceiling < self.floor:
            raise SpeedError(f"ceiling {self.ceiling:g} is below floor {self.floor:g}")

    def to_dict(self) -> dict[str, float]:
        return {"step": self.step, "floor": self.floor, "ceiling": self.ceiling, "resolution": self.resolution}




class SpeedLearner:
    """One move's time-scaling factor, learned cycle by cycle (module docstring).

    Parameters
    ----------
    settings : SpeedSettings, optional
        Step, floor, ceiling and resolution.

    Attributes
    ----------
    peaks : dict of str to list of (float, list of float)
        Per quantity (``effort``, ``velocity``), the largest |value| per joint measured at each factor since the
        last :meth:`relearn` (the largest over the cycles at a factor).
    cap : float or None
        The factor the predicted peaks allowed at the last update (None: not predicted).
    held : str
        Why the last update's raise was held or cut short by the prediction ('' if it was not).
    """

    def __init__(self, settings: SpeedSettings | None = None) -> None:
        self.settings = SpeedSettings() if settings is None else settings
        if not isinstance(self.settings, SpeedSettings):
            raise SpeedError(f"settings must be SpeedSettings, got {type(self.settings).__name__}")
        self.factor = self.settings.floor
        self.good: float | None = None  # largest factor a cycle was good at
        self.failed: float | None = None  # smallest factor a cycle was bad at
        self.history: list[dict[str, Any]] = []
        self.peaks: dict[str, list[tuple[float, list[float]]]] = {}
        self.cap: float | None = None
        self.held = ""

    @property
    def holding(self) -> bool:
        """No raise is left: at the ceiling, the good and failed factors within the resolution, or the predicted
        peaks allow no raise of at least the resolution."""
        s = self.settings
        top = s.ceiling if self.failed is None else self.failed
        if self.cap is not None:
            top = min(top, self.cap)
        base = s.floor if self.good is None else self.good
        return top - base < s.resolution or (self.failed is not None and self.failed <= s.floor)

    def record(self, factor: float, peaks: Mapping[str, np.ndarray | Sequence[float] | None]) -> None:
        """Keep the peaks measured at ``factor`` (per quantity, one per joint; None or a non-finite value: not
        kept), the largest per joint where the factor was measured before."""
        for quantity, values in peaks.items():
            if values is None or quantity not in POWERS:
                continue
            row = np.abs(np.asarray(values, dtype=float)).reshape(-1)
            if not np.all(np.isfinite(row)):
                continue
            rows = self.peaks.setdefault(quantity, [])
            if rows and len(rows[0][1]) != row.size:
                raise SpeedError(f"{row.size} {quantity} peaks for a move measured on {len(rows[0][1])} joints")
            for k, (f, old) in enumerate(rows):
                if f == factor:
                    rows[k] = (f, np.maximum(old, row).tolist())
                    break
            else:
                rows.append((float(factor), row.tolist()))
                rows.sort()

    def update(self, ok: bool, reason: str = "", peaks: Mapping[str, np.ndarray | Sequence[float] | None] | None = None,
               limits: PeakLimits | None = None) -> float:
        """Take the verdict of a cycle run at :attr:`factor`; returns the factor for the next cycle.

        Parameters
        ----------
        ok : bool
            The settled residual was within the tolerance and every joint limit held.
        reason : str
            What was violated (kept in the history).
        peaks : mapping of str to (J,) array_like, optional
            The peaks the cycle measured, per quantity (``effort``: |torque| N m, ``velocity``: |speed| rad/s), kept
            (:meth:`record`).
        limits : PeakLimits, optional
            The joints' limits: a raise goes no further than the factor whose predicted peaks stay within them less
            the margin (:func:`~.speed_peaks.allowed_factor`), and is not made if it would be smaller than the
            resolution (the factor holds; :attr:`held` says why).
        """
        s, used = self.settings, self.factor
        if peaks:
            self.record(used, peaks)
        self.held = ""
        if ok:
            self.good = used if self.good is None else max(self.good, used)
            if self.failed is None:
                nxt = min(used + s.step, s.ceiling)
            else:
                nxt = 0.5 * (self.good + self.failed) if self.failed - self.good >= s.resolution else self.good
            if limits is not None and self.peaks:
                self.cap, why = allowed_factor(self.peaks, limits, used, max(nxt, used))
                if nxt > used and self.cap < nxt:
                    raised = self.cap - used >= s.resolution
                    nxt = self.cap if raised else used
                    self.held = f"{why}: {'raised only to' if raised else 'held at'} x{nxt:.3f}"
        else:
            self.failed = used if self.failed is None else min(self.failed, used)
            if self.good is not None and self.good >= self.failed:
                self.good = None  # the good factor no longer holds (the plant changed)
            nxt = s.floor if self.good is None else self.good
        self.factor = float(min(max(nxt, s.floor), s.ceiling))
        self.history.append({"factor": used, "ok": bool(ok), "reason": str(reason), "next": self.factor,
                             "held": self.held})
        return self.factor

    def relearn(self) -> None:
        """Forget what was learned (the plant changed, e.g. its payload): start again from the floor, the peaks
        measured forgotten too."""
        self.factor, self.good, self.failed = self.settings.floor, None, None
        self.peaks, self.cap, self.held = {}, None, ""

    def to_dict(self) -> dict[str, Any]:
        """The state as a JSON-ready dictionary."""
        return {"version": SPEED_VERSION, "settings": self.settings.to_dict(), "factor": self.factor,
                "good": self.good, "failed": self.failed, "history": [dict(h) for h in self.history],
                "peaks": {q: [[f, list(p)] for f, p in rows] for q, rows in self.peaks.items()}, "cap": self.cap}

    @classmethod
    def from_dict(cls, d: Any) -> SpeedLearner:
        """The learner saved by :meth:`to_dict`, every entry checked (a version 1 state, without the peaks, is read
        with none measured).

        Raises
        ------
        SpeedError
            A missing, unknown or invalid entry (named).
        """
        if not isinstance(d, Mapping):
            raise SpeedError(f"speed state must be a dictionary, got {type(d).__name__}")
        if d.get("version") not in (1, SPEED_VERSION):
            raise SpeedError(f"speed state version {d.get('version')!r}, expected {SPEED_VERSION}")
        keys = _KEYS_V1 if d["version"] == 1 else _KEYS
        if set(d) != keys:
            raise SpeedError(f"speed state entries differ: missing {sorted(keys - set(d))},"
                             f" unknown {sorted(set(d) - keys)}")
        st = d["settings"]
        if not isinstance(st, Mapping) or set(st) != {"step", "floor", "ceiling", "resolution"}:
            raise SpeedError(f"speed settings must have step, floor, ceiling, resolution, got {st!r}")
        out = cls(SpeedSettings(**{k: st[k] for k in st}))
        out.factor = _positive("factor", d["factor"])
        if not out.settings.floor <= out.factor <= out.settings.ceiling:
            raise SpeedError(f"factor {out.factor:g} outside [{out.settings.floor:g}, {out.settings.ceiling:g}]")
        out.good = None if d["good"] is None else _positive("good", d["good"])
        out.failed = None if d["failed"] is None else _positive("failed", d["failed"])
        if not isinstance(d["history"], list) or not all(isinstance(h, Mapping) for h in d["history"]):
            raise SpeedError("speed history must be a list of dictionaries")
        out.history = [dict(h) for h in d["history"]]
        out.cap = None if d.get("cap") is None else _positive("cap", d["cap"])
        peaks = d.get("peaks", {})
        if not isinstance(peaks, Mapping) or set(peaks) - set(POWERS):
            raise SpeedError(f"speed peaks must be a dictionary of {sorted(POWERS)}, got {peaks!r}")
        for quantity, rows in peaks.items():
            for row in rows if isinstance(rows, list) else [rows]:
                try:
                    p = np.asarray(row[1], dtype=float)
                    ok = len(row) == 2 and p.ndim == 1 and bool(np.all(np.isfinite(p)))
                except (TypeError, ValueError, IndexError, KeyError):
                    ok = False
                if not ok:
                    raise SpeedError(f"speed {quantity} peaks must be [factor, [finite peak per joint]] pairs,"
                                     f" got {row!r}")
                out.record(_positive(f"{quantity} peaks' factor", row[0]), {quantity: p})
        return out
