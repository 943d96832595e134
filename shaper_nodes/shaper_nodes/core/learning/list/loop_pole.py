"""The position loop's damped pole in a noisy residual: pooled reference windows, the pole searched with the modes
that ring held fixed, its amplitude measured by least squares with the pole fixed.

Over a schedule with accelerometer noise the loop's transient (the servo part: a pole near 50 Hz damped 0.5-0.7,
a few ms long) is a few 0.001 m/s^2 in a 1 s RMS against the noise's 0.0173, so one reference window's identification
(:func:`.payback.components`) finds no component to put a factor on. Two things make it usable:

- the move's reference cycles are the same response each time (the arm starts each move at rest and the schedule is
  fixed), so their windows, aligned at the commanded end, are averaged (:func:`pooled`): the noise falls as
  1/sqrt(k);
- the transient is so heavily damped that what cancels it hardly depends on its pole (a zero-vibration pair on any
  pole of 45-60 Hz, damping 0.5-0.7, takes the arm's servo part to 2-9 %; docs/results/arm_learning_noise.md), while
  its *amplitude* with the pole held fixed is a linear least-squares estimate with a standard error
  (:func:`fixed_pole_fit`): a trial's amplitude at the same pole, measured in the trial's own window, says whether
  the factor removed it (:func:`lower_at_pole`), where the 1 s RMS cannot (the part is 0.0001-0.0002 m/s^2 of it,
  the noise's scatter per window 0.0002).

:func:`loop_pole` searches the pole on a grid (damping :data:`ZETA_RANGE`, frequency :data:`HZ_RANGE`) with the modes
that ring fixed, each candidate's amplitudes by least squares, and keeps the one with the least residual sum of
squares, reported only when its amplitude is :data:`SIGNIFICANCE` standard errors above zero; a trial is judged
lower at it at :data:`LOWER` combined standard errors.

ROS-free.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .params import ListError
from .payback import Component

__all__ = ["HZ_RANGE", "LOWER", "SIGNIFICANCE", "WINDOW", "ZETA_RANGE", "PoleFit", "Pool", "change_at_pole",
           "fixed_pole_fit", "loop_pole", "lower_at_pole", "pooled"]

#: the loop's pole is searched at these frequencies, Hz (from, to, step). The top: the loop's poles are 45-60 Hz
#: (damping 0.5-0.7; the reproduction finds 47-73 Hz), and a pair on a pole above 80 Hz is short (T2 under 7 ms): on
#: place->rotated the pair on 92 Hz took the servo part only to 22.5 % and moved the vibration part to 101.5 % over
#: DDS (issue 31, session 13); a best fit at the top itself is not a located pole (:func:`loop_pole`)
HZ_RANGE = (25.0, 80.0, 1.0)
#: ... and damping ratios (from, to, step): a servo pole (>= 0.12, residual_split.SERVO_ZETA) up to 0.7; above it a
#: zero-vibration pair has A1 over 0.95 and does nearly nothing, and on the noisy arm the search drifts there (a short
#: transient's frequency and damping trade against each other)
ZETA_RANGE = (0.15, 0.7, 0.025)
#: the window after the commanded end the pole is searched in, s (the transient is gone in 0.05 s)
WINDOW = 0.2
#: a pole is reported when its amplitude is this many standard errors above zero
SIGNIFICANCE = 3.0
#: a trial is judged lower at a pole when its response there is below the reference's by this many standard errors of
#: the change (:func:`change_at_pole`; one-sided, about 2 % of unchanged responses judged lower)
LOWER = 2.0


@dataclass(frozen=True)
class PoleFit:
    """Amplitudes (m/s^2, the norm over axes of each pole's response at the window's start) of fixed poles fitted by
    least squares, with their standard errors (m/s^2, from the fit's residual variance)."""

    amplitudes: tuple[float, ...]
    errors: tuple[float, ...]
    rss: float
    variance: float
    #: the last pole's response: its cosine and sine coefficients per axis ((2, k), m/s^2) and their covariance per
    #: axis ((2, 2), (m/s^2)^2: the residual variance times that block of (X^T X)^-1), for :func:`change_at_pole`
    response: tuple[np.ndarray, np.ndarray] | None = None


def _basis(t: np.ndarray, poles: Sequence[complex]) -> np.ndarray:
    cols = [np.ones_like(t), t]  # offset and drift per axis, as the identification's model
    for p in poles:
        e = np.exp(p.real * t)
        cols += [e * np.cos(p.imag * t), e * np.sin(p.imag * t)]
    return np.stack(cols, axis=1)


def _window(times: np.ndarray, signal: np.ndarray, start: float, window: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(times, dtype=float)
    y = np.asarray(signal, dtype=float).reshape(t.size, -1)
    sel = (t >= start) & (t <= start + window)
    return t[sel] - start, y[sel]


def fixed_pole_fit(times: np.ndarray, signal: np.ndarray, start: float, poles: Sequence[complex],
                   window: float = WINDOW) -> PoleFit:
    """Each fixed pole's amplitude at ``start`` by linear least squares on ``[start, start + window]`` (per axis: an
    offset, a drift and each pole's decaying cosine and sine), with its standard error.

    The amplitude is the norm over axes of the pole's cosine coefficients (its response's value at ``start``); its
    standard error that of one coefficient (the residual variance times the diagonal of (X^T X)^-1).

    Parameters
    ----------
    times : (N,) array
        Sample times, s.
    signal : (N,) or (N, k) array
        The accelerometer, m/s^2.
    start : float
        The window's start (the commanded end), s.
    poles : sequence of complex
        The poles, 1/s (:attr:`.payback.Component.pole`).
    window : float
        The window's length, s.
    """
    t, y = _window(times, signal, start, window)
    x = _basis(t, poles)
    if t.size <= x.shape[1]:
        raise ListError(f"{t.size} samples in the {window:g} s window cannot fit {len(poles)} poles")
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    rss = float(np.sum((y - x @ coef) ** 2))
    variance = rss / (y.size - coef.size)
    inv = np.linalg.pinv(x.T @ x)
    diag = np.diag(inv)
    amps = tuple(float(np.linalg.norm(coef[2 + 2 * i])) for i in range(len(poles)))
    errs = tuple(math.sqrt(variance * float(diag[2 + 2 * i])) for i in range(len(poles)))
    last = 2 * len(poles)
    response = (coef[last:last + 2].copy(), variance * inv[last:last + 2, last:last + 2]) if poles else None
    return PoleFit(amps, errs, rss, variance, response)


def loop_pole(times: np.ndarray, signal: np.ndarray, start: float, ringing: Sequence[Component],
              window: float = WINDOW) -> tuple[Component, float] | None:
    """The damped pole that, beside the modes that ring (``ringing``, held fixed), fits the window from ``start``
    best (grid :data:`HZ_RANGE` x :data:`ZETA_RANGE`, amplitudes by least squares), as a component with its
    amplitude at ``start``, and its standard error (m/s^2); None when the amplitude is not :data:`SIGNIFICANCE`
    standard errors above zero, or when the best fit is at the grid's top frequency (the fit would go on above it:
    not the loop's pole located; more windows pooled may locate it)."""
    fixed = [c.pole for c in ringing]
    best: tuple[float, Component, PoleFit] | None = None
    for hz in np.arange(HZ_RANGE[0], HZ_RANGE[1] + 1e-9, HZ_RANGE[2]):
        for zeta in np.arange(ZETA_RANGE[0], ZETA_RANGE[1] + 1e-9, ZETA_RANGE[2]):
            c = Component(2.0 * math.pi * float(hz), float(zeta), 0.0)
            fit = fixed_pole_fit(times, signal, start, [*fixed, c.pole], window)
            if best is None or fit.rss < best[0]:
                best = (fit.rss, c, fit)
    assert best is not None
    _, c, fit = best
    amp, err = fit.amplitudes[-1], fit.errors[-1]
    if amp < SIGNIFICANCE * err or c.hz >= HZ_RANGE[1] - 0.5 * HZ_RANGE[2]:
        return None
    return Component(c.omega, c.zeta, amp), err


def lower_at_pole(reference: tuple[float, float], trial: tuple[float, float], significance: float = LOWER) -> bool:
    """Whether a trial's measured amplitude at a pole is below the reference's by more than ``significance`` times
    their combined standard error (each an (amplitude, standard error) pair, m/s^2, :func:`fixed_pole_fit`)."""
    (a_ref, e_ref), (a_trial, e_trial) = reference, trial
    return a_trial + significance * math.hypot(e_ref, e_trial) < a_ref


def change_at_pole(reference: tuple[np.ndarray, np.ndarray], trial: tuple[np.ndarray, np.ndarray]) -> float:
    """How far a trial's response at a pole is below the reference's, in standard errors of the change (one-sided:
    > 0 lower); each response is :attr:`PoleFit.response` (the pole's cosine and sine coefficients per axis, their
    covariance per axis).

    The change ``r - t`` is projected on the reference's direction in the metric of the change's covariance
    ``S = S_r + S_t`` (the whitened projection: every coefficient the pole has, cosine and sine, on every axis, each
    weighted by what the noise leaves of it), ``(r' S^-1 (r - t) - b) / sqrt(r' S^-1 r)``, with ``b = k tr(S^-1 S_r)``
    the bias of projecting on a direction measured with the reference's own noise (k axes): unchanged responses
    give about N(0, 1). Against the amplitude's norm on the cosine coefficients (:func:`lower_at_pole`) it uses the
    sine coefficients too and takes no norm of a noisy trial (a trial near zero reads about 1.6 standard errors
    there): on the arm's servo transient under 0.01 m/s^2 of noise the same false-keep rate with far more power
    (docs/results/arm_demo.md, issue 31, session 13)."""
    (r, s_r), (t, s_t) = reference, trial
    r, t = np.asarray(r, dtype=float), np.asarray(t, dtype=float)
    inv = np.linalg.inv(np.asarray(s_r, dtype=float) + np.asarray(s_t, dtype=float))
    q = float(np.einsum("ia,ij,ja->", r, inv, r))
    if not q > 0.0:
        return 0.0
    cross = float(np.einsum("ia,ij,ja->", r, inv, t))
    bias = r.shape[1] * float(np.trace(inv @ np.asarray(s_r, dtype=float)))
    return float((q - cross - bias) / math.sqrt(q))


class Pool:
    """Windows of the same response pooled as they come (:func:`pooled`'s mean, kept as a running sum: its size does
    not grow with the count): the first window's times from its start, the sum of the windows' samples over the
    shortest count so far, and the count. Saved and restored (:meth:`to_dict`, :meth:`from_dict`) by the learner
    node between cycles."""

    def __init__(self, length: float = 1.0) -> None:
        self.length = float(length)
        self.times: np.ndarray | None = None
        self.total: np.ndarray | None = None
        self.count = 0

    def add(self, times: np.ndarray, signal: np.ndarray, start: float) -> None:
        """One window more: ``signal`` (m/s^2, (N,) or (N, k)) at ``times`` (s), from ``start`` for :attr:`length` s."""
        t, y = _window(times, signal, start, self.length)
        if self.total is None or self.times is None:
            self.times, self.total = t, y.copy()
        else:
            if y.shape[1] != self.total.shape[1]:
                raise ListError(f"a window of {y.shape[1]} axes cannot join a pool of {self.total.shape[1]}")
            n = min(self.times.size, t.size)
            self.times, self.total = self.times[:n], self.total[:n] + y[:n]
        self.count += 1

    def mean(self) -> tuple[np.ndarray, np.ndarray]:
        """(times from the start, s; the mean signal, m/s^2)."""
        if self.total is None or self.times is None or not self.count:
            raise ListError("no window to pool")
        return self.times, self.total / self.count

    def to_dict(self) -> dict[str, Any]:
        """The pool as plain data: ``count``, ``length``, ``times`` (s from the start) and ``sum`` (per sample, per
        axis, m/s^2); about 4 numbers per sample of a three-axis accelerometer."""
        return {"count": self.count, "length": self.length,
                "times": [] if self.times is None else self.times.tolist(),
                "sum": [] if self.total is None else self.total.tolist()}

    @classmethod
    def from_dict(cls, d: Any) -> Pool:
        """A pool saved by :meth:`to_dict`, checked (:class:`ListError` names the problem)."""
        if not isinstance(d, Mapping) or set(d) != {"count", "length", "times", "sum"}:
            got = sorted(d) if isinstance(d, Mapping) else d
            raise ListError(f"a pool has the entries count, length, sum and times, got {got!r:.200}")
        count, length = d["count"], d["length"]
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ListError(f"a pool's count must be an integer >= 0, got {count!r}")
        if isinstance(length, bool) or not isinstance(length, (int, float)) or not 0 < length < math.inf:
            raise ListError(f"a pool's length must be a finite number > 0 s, got {length!r}")
        pool = cls(float(length))
        if count == 0:
            return pool
        try:
            t = np.asarray(d["times"], dtype=float)
            y = np.asarray(d["sum"], dtype=float)
        except (TypeError, ValueError) as err:
            raise ListError(f"a pool's times and sum must be numbers: {err}") from None
        if t.ndim != 1 or y.ndim != 2 or y.shape[0] != t.size or t.size == 0 or not (
                np.all(np.isfinite(t)) and np.all(np.isfinite(y))) or np.any(np.diff(t) <= 0):
            raise ListError(f"a pool's times must be finite and increasing and its sum one finite row per time, got"
                            f" {t.shape} times and a sum of shape {y.shape}")
        pool.times, pool.total, pool.count = t, y, count
        return pool


def pooled(windows: Sequence[tuple[np.ndarray, np.ndarray, float]],
           length: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The mean of several cycles' windows of the same response, aligned at their starts: each (times, signal, start)
    cut to the samples in ``[start, start + length]``, the shortest count taken; returns (times from the start, the
    mean signal). With independent noise the mean's noise is 1/sqrt(k) of one window's (:class:`Pool`)."""
    pool = Pool(length)
    for t, y, s in windows:
        pool.add(t, y, s)
    return pool.mean()
