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

What a node needs around it, measurable on a robot (the learner node's ``speed_moves`` mode):

- :func:`time_scale`: a planned trajectory's points run ``s`` times faster (times / s up to the motion's
  last point, velocities x s, accelerations x s^2; the hold after the motion keeps its length);
- :func:`limit_breach`: the first point of a profile past a joint velocity or acceleration limit, named;
- :func:`effort_check`: the efforts measured during a move (a robot's /joint_states effort: joint torques, N m)
  against the joints' torque limits: the largest ratio, and the first joint past its limit, named (the plan's
  velocities and accelerations are checked before the move; the torque it took is known only after, and is
  predicted for the next factor before a raise, :mod:`.speed_peaks`); :func:`peak_check` the same for any measured
  peak (the joint speeds: a robot may overshoot its plan);
- :func:`acceleration_tolerance`: the accelerometer level that corresponds to a displacement tolerance at
  the flange, ``x (2 pi f)^2`` at the mode ``f`` (a sinusoid of amplitude x at f has the acceleration
  amplitude x (2 pi f)^2; at the move's lowest mode the same acceleration means the largest displacement,
  so the conversion is conservative for the higher modes and for the position loop's faster transient).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .speed_peaks import POWERS, PeakLimits, allowed_factor

__all__ = ["SPEED_VERSION", "SpeedError", "SpeedLearner", "SpeedSettings", "acceleration_tolerance", "effort_check",
           "limit_breach", "limit_ceiling", "limits_held", "motion_end_index", "peak_check", "time_scale"]

#: version of :meth:`SpeedLearner.to_dict`'s dictionaries (1: without the measured peaks; still read)
SPEED_VERSION = 2
_KEYS_V1 = {"version", "settings", "factor", "good", "failed", "history"}
_KEYS = _KEYS_V1 | {"peaks", "cap"}


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


def motion_end_index(positions: np.ndarray, tolerance: float = 1e-9) -> int:
    """Index of a trajectory's last point whose positions differ from the point before it (0 if none does):
    the points after it hold the final pose.

    Parameters
    ----------
    positions : (N, J) array
        The points' joint positions, rad.
    tolerance : float
        Largest change (rad) that still counts as holding.
    """
    q = np.asarray(positions, dtype=float)
    if q.shape[0] < 2:
        return 0
    moving = np.flatnonzero(np.any(np.abs(np.diff(q, axis=0)) > tolerance, axis=1))
    return int(moving[-1] + 1) if moving.size else 0


def time_scale(times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None,
               accelerations: np.ndarray | None, factor: float
               ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A planned trajectory's points run ``factor`` times faster on the same path.

    The motion (up to :func:`motion_end_index`) is q(s t): its points' times / s, velocities x s,
    accelerations x s^2. The points after it hold the final pose; they keep their spacing (a dwell at the
    goal stays as long as planned), shifted to the scaled motion's end.

    Parameters
    ----------
    times : (N,) array
        The points' times from the start, s (increasing).
    positions : (N, J) array
        Joint positions, rad (unchanged: the same path).
    velocities, accelerations : (N, J) array or None
        rad/s and rad/s^2 (None: not given; stays None).
    factor : float
        s > 0 (1: as planned).

    Returns
    -------
    times, velocities, accelerations
        The scaled points' times (s), velocities and accelerations.
    """
    s = _positive("factor", factor)
    t = np.asarray(times, dtype=float)
    m = motion_end_index(positions)
    out = t / s
    out[m + 1:] = t[m] / s + (t[m + 1:] - t[m])
    v = None if velocities is None else np.asarray(velocities, dtype=float) * s
    a = None if accelerations is None else np.asarray(accelerations, dtype=float) * s * s
    return out, v, a


def limit_breach(times: np.ndarray, velocities: np.ndarray, accelerations: np.ndarray,
                 max_velocity: Sequence[float] | np.ndarray, max_acceleration: Sequence[float] | np.ndarray,
                 names: Sequence[str]) -> str | None:
    """The first joint limit a profile breaks, in one line (None: every point within every limit).

    Parameters
    ----------
    times : (N,) array
        The points' times, s.
    velocities, accelerations : (N, J) array
        rad/s and rad/s^2.
    max_velocity, max_acceleration : (J,) array_like
        The joints' limits, rad/s and rad/s^2.
    names : sequence of str
        The joints' names.
    """
    for what, unit, values, limits in (("velocity", "rad/s", velocities, max_velocity),
                                       ("acceleration", "rad/s^2", accelerations, max_acceleration)):
        x = np.abs(np.asarray(values, dtype=float))
        lim = np.asarray(limits, dtype=float)
        over = x > lim[None, :]
        if np.any(over):
            i, j = (int(k) for k in np.argwhere(over)[0])
            return (f"joint {names[j]}: {what} {x[i, j]:.4g} {unit} above its limit {lim[j]:.4g} {unit} at the point"
                    f" of t = {float(times[i]):.3f} s")
    return None


def peak_check(peaks: np.ndarray | Sequence[float], limits: Sequence[float] | np.ndarray, names: Sequence[str],
               quantity: str = "effort", unit: str = "N m") -> tuple[float, int, str | None]:
    """The peaks measured during a move (joint efforts, N m; joint speeds, rad/s) against the joints' limits.

    Parameters
    ----------
    peaks : (J,) array_like
        The largest |value| each joint measured during the move.
    limits : (J,) array_like
        The joints' limits, in the same unit (> 0; inf: no limit).
    names : sequence of str
        The joints' names.
    quantity, unit : str
        What the peaks are (``effort``, ``velocity``) and their unit, for the line.

    Returns
    -------
    ratio : float
        The largest |value| / limit over the joints (0 for a joint without a limit; nan if a limit is nan).
    joint : int
        The index of the joint of that ratio (-1: no joint).
    breach : str or None
        The joint furthest past its limit, in one line (None: every joint within its limit; a nan value or limit
        counts as exceeded).
    """
    p = np.abs(np.asarray(peaks, dtype=float)).reshape(-1)
    lim = np.asarray(limits, dtype=float).reshape(-1)
    if p.shape != lim.shape or len(names) != p.size:
        plural = {"effort": "efforts", "velocity": "velocities"}.get(quantity, quantity)
        raise SpeedError(f"{p.size} {plural} against {lim.size} limits and {len(names)} names")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.where(np.isinf(lim), 0.0, p / lim)
    joint = int(np.argmax(np.nan_to_num(ratios, nan=np.inf))) if ratios.size else -1
    ratio = float(ratios[joint]) if ratios.size else 0.0
    over = limits_held(p, lim)
    if not over:
        return ratio, joint, None
    j = joint if joint in over else over[0]  # the joint furthest past its limit
    return ratio, joint, (f"joint {names[j]}: measured |{quantity}| {p[j]:.4g} {unit} above its limit"
                          f" {lim[j]:.4g} {unit}")


def effort_check(peaks: np.ndarray | Sequence[float], limits: Sequence[float] | np.ndarray,
                 names: Sequence[str]) -> tuple[float, int, str | None]:
    """:func:`peak_check` of the efforts measured during a move (a robot's /joint_states effort: joint torques, N m,
    or N for a prismatic joint) against the joints' effort limits."""
    return peak_check(peaks, limits, names, "effort", "N m")


def acceleration_tolerance(displacement: float, frequency_hz: float) -> float:
    """The accelerometer level, m/s^2, that a displacement tolerance at the flange corresponds to at a mode.

    Parameters
    ----------
    displacement : float
        Tolerance of the settled flange, m (0.05 mm: 5e-5).
    frequency_hz : float
        The mode's frequency, Hz (the move's lowest: the conversion is then conservative, module docstring).

    Returns
    -------
    float
        ``displacement * (2 pi frequency_hz)^2``.
    """
    x, f = _positive("displacement", displacement), _positive("frequency_hz", frequency_hz)
    return x * (2.0 * math.pi * f) ** 2


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
