"""Learning to move faster: a per-move time-scaling factor raised while the move stays good.

A move's planned trajectory q(t) run ``s`` times faster is q(s t): velocities x s, accelerations
x s^2, duration / s, the same path. :class:`SpeedLearner` learns ``s`` for one move from its
cycles, as one of FANUC's learning-vibration-control patents describes the idea (raise the speed
over repetitions while the vibration stays within an allowed bound):

- after a good cycle (the settled residual within the tolerance and every joint limit held) the
  factor is raised by ``step``, up to ``ceiling`` (the largest factor the joint velocity and
  acceleration limits allow on the planned profile, :func:`limit_ceiling`);
- after a bad cycle (either violated) it is lowered at once to the largest factor that was good,
  and the failed factor is remembered: later raises go half way between the two (bisection), and
  the learner holds once they are closer than ``resolution``;
- the learner never goes below ``floor`` (1: never slower than planned; a move that fails at the
  floor holds there and says so).

It is deterministic and its state is a JSON-ready dictionary (:meth:`SpeedLearner.to_dict`,
:meth:`SpeedLearner.from_dict`, every entry checked).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SPEED_VERSION", "SpeedError", "SpeedLearner", "SpeedSettings", "limit_ceiling", "limits_held"]

#: version of :meth:`SpeedLearner.to_dict`'s dictionaries
SPEED_VERSION = 1


class SpeedError(ValueError):
    """Bad settings or state of the speed learner; the message names the problem."""


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SpeedError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise SpeedError(f"{name} must be finite and > 0, got {value!r}")
    return v


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


def limit_ceiling(velocities: np.ndarray, accelerations: np.ndarray, max_velocity: Sequence[float] | np.ndarray,
                  max_acceleration: Sequence[float] | np.ndarray) -> float:
    """The largest time-scaling factor that keeps a planned profile inside joint limits.

    Parameters
    ----------
    velocities, accelerations : (N, J) array
        The planned profile, rad/s and rad/s^2.
    max_velocity, max_acceleration : (J,) array_like
        Joint limits, rad/s and rad/s^2 (> 0; inf: no limit).

    Returns
    -------
    float
        min over joints of v_max / |v| and sqrt(a_max / |a|) (inf for a joint that does not move).
    """
    v = np.max(np.abs(np.asarray(velocities, dtype=float)), axis=0)
    a = np.max(np.abs(np.asarray(accelerations, dtype=float)), axis=0)
    vmax = np.asarray(max_velocity, dtype=float)
    amax = np.asarray(max_acceleration, dtype=float)
    if v.shape != vmax.shape or a.shape != amax.shape:
        raise SpeedError(f"limits for {vmax.size} and {amax.size} joints, profile has {v.size}")
    if not (np.all(vmax > 0) and np.all(amax > 0)):  # nan fails too
        raise SpeedError("joint velocity and acceleration limits must be > 0 (inf: no limit)")
    with np.errstate(divide="ignore"):
        s_v = np.where(v > 0, vmax / np.where(v > 0, v, 1.0), np.inf)
        s_a = np.where(a > 0, np.sqrt(amax / np.where(a > 0, a, 1.0)), np.inf)
    return float(min(np.min(s_v), np.min(s_a)))


def limits_held(peaks: np.ndarray, limits: Sequence[float] | np.ndarray) -> list[int]:
    """Indices of the joints whose peak magnitude exceeds its limit (empty: every limit held)."""
    p = np.abs(np.asarray(peaks, dtype=float)).reshape(-1)
    lim = np.asarray(limits, dtype=float).reshape(-1)
    if p.shape != lim.shape:
        raise SpeedError(f"{p.size} peaks against {lim.size} limits")
    return [int(i) for i in np.flatnonzero(~(p <= lim))]


class SpeedLearner:
    """One move's time-scaling factor, learned cycle by cycle (module docstring).

    Parameters
    ----------
    settings : SpeedSettings, optional
        Step, floor, ceiling and resolution.
    """

    def __init__(self, settings: SpeedSettings | None = None) -> None:
        self.settings = SpeedSettings() if settings is None else settings
        if not isinstance(self.settings, SpeedSettings):
            raise SpeedError(f"settings must be SpeedSettings, got {type(self.settings).__name__}")
        self.factor = self.settings.floor
        self.good: float | None = None  # largest factor a cycle was good at
        self.failed: float | None = None  # smallest factor a cycle was bad at
        self.history: list[dict[str, Any]] = []

    @property
    def holding(self) -> bool:
        """No raise is left: at the ceiling, or the good and failed factors within the resolution."""
        s = self.settings
        top = s.ceiling if self.failed is None else self.failed
        base = s.floor if self.good is None else self.good
        return top - base < s.resolution or (self.failed is not None and self.failed <= s.floor)

    def update(self, ok: bool, reason: str = "") -> float:
        """Take the verdict of a cycle run at :attr:`factor`; returns the factor for the next cycle.

        Parameters
        ----------
        ok : bool
            The settled residual was within the tolerance and every joint limit held.
        reason : str
            What was violated (kept in the history).
        """
        s, used = self.settings, self.factor
        if ok:
            self.good = used if self.good is None else max(self.good, used)
            if self.failed is None:
                nxt = min(used + s.step, s.ceiling)
            else:
                nxt = 0.5 * (self.good + self.failed) if self.failed - self.good >= s.resolution else self.good
        else:
            self.failed = used if self.failed is None else min(self.failed, used)
            if self.good is not None and self.good >= self.failed:
                self.good = None  # the good factor no longer holds (the plant changed)
            nxt = s.floor if self.good is None else self.good
        self.factor = float(min(max(nxt, s.floor), s.ceiling))
        self.history.append({"factor": used, "ok": bool(ok), "reason": str(reason), "next": self.factor})
        return self.factor

    def relearn(self) -> None:
        """Forget what was learned (the plant changed, e.g. its payload): start again from the floor."""
        self.factor, self.good, self.failed = self.settings.floor, None, None

    def to_dict(self) -> dict[str, Any]:
        """The state as a JSON-ready dictionary."""
        return {"version": SPEED_VERSION, "settings": self.settings.to_dict(), "factor": self.factor,
                "good": self.good, "failed": self.failed, "history": [dict(h) for h in self.history]}

    @classmethod
    def from_dict(cls, d: Any) -> SpeedLearner:
        """The learner saved by :meth:`to_dict`, every entry checked.

        Raises
        ------
        SpeedError
            A missing, unknown or invalid entry (named).
        """
        if not isinstance(d, Mapping):
            raise SpeedError(f"speed state must be a dictionary, got {type(d).__name__}")
        keys = {"version", "settings", "factor", "good", "failed", "history"}
        if set(d) != keys:
            raise SpeedError(f"speed state entries differ: missing {sorted(keys - set(d))},"
                             f" unknown {sorted(set(d) - keys)}")
        if d["version"] != SPEED_VERSION:
            raise SpeedError(f"speed state version {d['version']!r}, expected {SPEED_VERSION}")
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
        return out
