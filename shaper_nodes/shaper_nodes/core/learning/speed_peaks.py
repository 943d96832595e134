"""A move's joint torques and speeds at a higher time-scaling factor, predicted from those measured at lower ones.

The speed learner measures a move's peaks after the move; raising its factor blindly would let one cycle per move
pass a torque limit (a real UR would protective-stop there). So before a raise, each joint's peak at the new factor
is predicted from what the move measured at the factors it ran at, and the factor is not raised past one whose
prediction exceeds ``(1 - margin)`` of the joint's limit (:func:`allowed_factor`).

**The scaling.** Time scaling by ``s`` runs the same path ``s`` times faster: joint speeds x s; accelerations and the
velocity-product (Coriolis, centripetal) torques x s^2, viscous friction x s; gravity does not scale. A joint's peak
|torque| is modelled ``a + b s^2`` (``a``: the part that does not scale, gravity and Coulomb friction; ``b s^2``
the dynamic part; the viscous part, x s, lies between them and is over-estimated by s^2 above the measured factors),
its peak |speed| ``b s`` (power 1). The prediction at ``s`` (:func:`predict`) is the larger of

- the pure-scaling rule from the largest measured factor ``s_k`` at or below ``s`` (peak ``p_k``):
  ``p_k (s / s_k)^power``, all of the peak scaled: conservative above ``s_k`` for any ``a >= 0`` (it is all that one
  measured factor allows; between measured factors, e.g. after a bad cycle, the one below counts, not the top);
- with two or more measured factors, the least-squares fit ``a + b s^power`` over them, ``a >= 0`` (where the
  unconstrained fit gives ``a < 0`` the peaks grow faster than s^power, and ``a = 0`` with its own ``b`` is fitted):
  it exceeds the rule when the measured peaks grow faster than the model's bound.

A caveat, stated rather than hidden: a peak is the largest over the move of ``|g(t) + c(t) s^2|``, convex in s^2;
where gravity opposes the dynamic torque at the peak's instant, the peak grows faster than s^2 between measured
factors, and neither rule bounds it. The margin and the check of the measured peaks after every move (a breach: a bad
cycle, lowered at once) cover that case.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["POWERS", "UNITS", "PeakLimits", "allowed_factor", "fit", "predict"]

#: the power of the factor each measured quantity scales with
POWERS = {"effort": 2, "velocity": 1}
#: their units in the log lines
UNITS = {"effort": "N m", "velocity": "rad/s"}


@dataclass(frozen=True)
class PeakLimits:
    """The joints' limits a raise is predicted against.

    Attributes
    ----------
    names : tuple of str
        The move's joints.
    limits : mapping of str to (J,) array
        Per quantity (``effort``, N m; ``velocity``, rad/s), the joints' limits (inf: not predicted).
    margin : float
        The prediction must stay within ``(1 - margin)`` of each limit, 0 <= margin < 1.
    """

    names: tuple[str, ...]
    limits: Mapping[str, np.ndarray]
    margin: float = 0.05


def _rows(measured: Sequence[tuple[float, Sequence[float]]]) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray([m[0] for m in measured], dtype=float)
    p = np.abs(np.asarray([list(m[1]) for m in measured], dtype=float)).reshape(len(measured), -1)
    return s, p


def fit(factors: np.ndarray, peaks: np.ndarray, power: int) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``a + b s^power`` per joint with ``a >= 0`` (a factor measured once or more).

    Parameters
    ----------
    factors : (K,) array
        The factors measured at (K >= 1; a single distinct factor gives ``a = 0``, ``b = p / s^power``).
    peaks : (K, J) array
        The peaks measured there.
    power : int
        2 for torques, 1 for speeds.

    Returns
    -------
    a, b : (J,) arrays
    """
    u = np.asarray(factors, dtype=float) ** power
    p = np.asarray(peaks, dtype=float)
    if np.ptp(u) > 0:
        du = u - u.mean()
        b = (du @ (p - p.mean(axis=0))) / (du @ du)
        a = p.mean(axis=0) - b * u.mean()
    else:
        a, b = np.full(p.shape[1], -1.0), np.zeros(p.shape[1])
    through0 = (u @ p) / (u @ u)  # a = 0: the best line through the origin
    neg = a < 0
    return np.where(neg, 0.0, a), np.where(neg, through0, b)


def _below(s: np.ndarray, factor: float) -> int:
    """The index of the largest measured factor at or below ``factor`` (the smallest if none is)."""
    return max(int(np.searchsorted(s, factor, side="right")) - 1, 0)


def predict(measured: Sequence[tuple[float, Sequence[float]]], factor: float, power: int) -> np.ndarray:
    """Each joint's peak predicted at ``factor`` (module docstring): the larger of the pure-scaling rule from the
    largest measured factor at or below it and, with two or more factors, the fit ``a + b s^power`` (``a >= 0``).

    Parameters
    ----------
    measured : sequence of (factor, (J,) peaks)
        What the move measured (at least one; in increasing factor, each factor once: :meth:`.SpeedLearner.record`).
    factor : float
        The factor to predict at.
    power : int
        2 for torques, 1 for speeds.
    """
    s, p = _rows(measured)
    k = _below(s, factor)
    out: np.ndarray = p[k] * (factor / s[k]) ** power
    if s.size > 1:
        a, b = fit(s, p, power)
        out = np.maximum(out, a + b * factor ** power)
    return out


def _cap(s: np.ndarray, p: np.ndarray, power: int, level: np.ndarray, start: float) -> np.ndarray:
    """Per joint, the largest factor from ``start`` up to which the prediction stays within ``level`` (``start``
    itself when it is above already; inf: nothing bounds it)."""
    cap = np.full(p.shape[1], np.inf)
    k0 = _below(s, start)
    a, b = fit(s, p, power) if s.size > 1 else (np.zeros(p.shape[1]), np.zeros(p.shape[1]))
    for j in np.flatnonzero(np.isfinite(level)):
        for k in range(k0, s.size):  # the rule from s[k] holds from s[k] to the next measured factor
            lo, hi = (start if k == k0 else s[k]), (s[k + 1] if k + 1 < s.size else np.inf)
            if p[k, j] > 0:
                cross = s[k] * (level[j] / p[k, j]) ** (1.0 / power)
                if cross < hi:
                    cap[j] = max(cross, lo)
                    break
        if b[j] > 0:  # the fit, increasing: where it reaches the level
            cap[j] = min(cap[j], max(max(level[j] - a[j], 0.0) / b[j], 0.0) ** (1.0 / power))
        elif a[j] > level[j]:
            cap[j] = min(cap[j], start)
        cap[j] = max(cap[j], start)
    return cap


def allowed_factor(measured: Mapping[str, Sequence[tuple[float, Sequence[float]]]], limits: PeakLimits,
                   start: float, target: float) -> tuple[float, str]:
    """The largest factor from ``start`` up to ``target`` whose predicted peaks stay within ``(1 - margin)`` of every
    limit.

    Parameters
    ----------
    measured : mapping of str to sequence of (factor, (J,) peaks)
        Per quantity (``effort``, ``velocity``), what the move measured, in increasing factor (a quantity absent or
        empty: not predicted).
    limits : PeakLimits
        The joints, their limits and the margin.
    start : float
        The factor the raise starts from (the one just run).
    target : float
        The factor the learner would raise to.

    Returns
    -------
    factor : float
        ``target`` when every prediction up to it is within, else the largest factor below it that is (``start``
        when none above it is).
    why : str
        Empty when ``target`` is allowed; else the joint and quantity that bound it, in one line
        ("joint X: predicted |effort| ... N m at x1.800 above ... N m (95 % of its limit ... N m)").
    """
    best, why = float(target), ""
    keep = 1.0 - float(limits.margin)
    for quantity, power in POWERS.items():
        rows = measured.get(quantity) or []
        lim = limits.limits.get(quantity)
        if not rows or lim is None:
            continue
        s, p = _rows(rows)
        level = keep * np.asarray(lim, dtype=float).reshape(-1)
        if level.size != p.shape[1] or p.shape[1] != len(limits.names):
            continue  # (another joint set: not this move's)
        cap = _cap(s, p, power, level, float(start))
        j = int(np.argmin(cap))
        if cap[j] < best:
            at = predict(rows, target, power)
            best = float(cap[j])
            why = (f"joint {limits.names[j]}: predicted |{quantity}| {at[j]:.4g} {UNITS[quantity]} at x{target:.3f}"
                   f" above {level[j]:.4g} {UNITS[quantity]} ({100 * keep:.0f} % of its limit {lim[j]:.4g}"
                   f" {UNITS[quantity]})")
    return (best if math.isfinite(best) else float(target)), why
