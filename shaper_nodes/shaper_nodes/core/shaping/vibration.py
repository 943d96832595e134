"""Percentage vibration of impulse sequences, and residual vibration of measured cycles.

The percentage vibration (seeds 000, 002, 004; Singer & Seering 1990) is the ratio of the
residual vibration amplitude after the last impulse to that of a single unit impulse:

    V(omega, zeta) = exp(-zeta omega t_n) sqrt(C^2 + S^2),
    C = sum_i A_i exp(zeta omega t_i) cos(omega sqrt(1 - zeta^2) t_i),
    S = sum_i A_i exp(zeta omega t_i) sin(omega sqrt(1 - zeta^2) t_i),

with t_n the last impulse time. omega in rad/s, zeta dimensionless, V a fraction (1 = 100 %).
The exponentials are combined as exp(zeta omega (t_i - t_n)) so that long sequences and
heavy damping do not overflow.

The insensitivity of a shaper (:func:`insensitivity_width`) is the width of the contiguous band
of frequencies around the design frequency where V stays at or below a level (5 % usually),
as a fraction of the design frequency, the damping ratio held at the design value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: an insensitivity band is searched from 0 up to this multiple of the design frequency
MAX_BAND_RATIO = 5.0


def percentage_vibration(
    amplitudes: np.ndarray, times: np.ndarray, omega: float | np.ndarray, zeta: float | np.ndarray
) -> np.ndarray:
    """V(omega, zeta) of the impulse sequence, as a fraction; broadcasts over omega and zeta.

    Parameters
    ----------
    amplitudes : array_like
        Impulse amplitudes (dimensionless).
    times : array_like
        Impulse times, s (any order; t_n is the largest).
    omega : float or array_like
        Natural frequency of the vibrating system, rad/s.
    zeta : float or array_like
        Damping ratio, in [0, 1).
    """
    amps = np.asarray(amplitudes, dtype=float)
    ts = np.asarray(times, dtype=float)
    om, ze = np.broadcast_arrays(np.asarray(omega, dtype=float), np.asarray(zeta, dtype=float))
    sigma = (ze * om)[..., None]
    wd = (om * np.sqrt(1.0 - ze**2))[..., None]
    decay = np.exp(sigma * (ts - ts.max()))
    c = np.sum(amps * decay * np.cos(wd * ts), axis=-1)
    s = np.sum(amps * decay * np.sin(wd * ts), axis=-1)
    v: np.ndarray = np.sqrt(c * c + s * s)
    return v


def sensitivity_curve(
    amplitudes: np.ndarray,
    times: np.ndarray,
    design_omega: float,
    zeta: float,
    ratio: tuple[float, float] = (0.0, 2.0),
    points: int = 401,
) -> tuple[np.ndarray, np.ndarray]:
    """V against the ratio of actual to design frequency, at damping ``zeta``.

    Returns
    -------
    ratios : numpy.ndarray
        omega / design_omega, from ``ratio[0]`` to ``ratio[1]``.
    v : numpy.ndarray
        Percentage vibration at each ratio (fraction).
    """
    ratios = np.linspace(ratio[0], ratio[1], points)
    return ratios, percentage_vibration(amplitudes, times, ratios * design_omega, zeta)


def insensitivity_width(
    amplitudes: np.ndarray, times: np.ndarray, design_omega: float, zeta: float, level: float = 0.05
) -> float:
    """Width of the contiguous band around ``design_omega`` where V <= ``level``, as a fraction.

    The band is the largest interval of frequencies containing ``design_omega`` on which
    V(omega, zeta) <= level (the damping ratio held at ``zeta``); its width is returned divided
    by ``design_omega`` (ZV at zeta = 0: 0.0637 for 5 %). V is evaluated on a grid fine enough
    for the sequence's duration (steps below 0.01 / t_n rad/s and 0.1 % of the design frequency)
    and the edges are refined by root finding (``scipy.optimize.brentq``). V equal to the level
    within a relative 1e-6 counts as inside, so designs that touch the level at their humps (EI
    shapers with V_tol = level) are measured across their humps. The search stops at 0 and at
    :data:`MAX_BAND_RATIO` times the design frequency (a heavily damped design can stay below the
    level at all higher frequencies).

    Parameters
    ----------
    amplitudes, times : array_like
        The impulse sequence (times in s).
    design_omega : float
        Design frequency, rad/s, > 0.
    zeta : float
        Damping ratio, in [0, 1).
    level : float
        Vibration level, fraction (0.05 = 5 %), in (0, 1].

    Returns
    -------
    float
        (omega_hi - omega_lo) / design_omega; 0 if V > level at the design frequency.
    """
    w0 = float(design_omega)
    if not (math.isfinite(w0) and w0 > 0.0):
        raise ValueError(f"design_omega must be finite and > 0 rad/s, got {design_omega!r}")
    if not (math.isfinite(zeta) and 0.0 <= zeta < 1.0):
        raise ValueError(f"zeta must be in [0, 1), got {zeta!r}")
    if not (math.isfinite(level) and 0.0 < level <= 1.0):
        raise ValueError(f"level must be in (0, 1], got {level!r}")
    amps = np.asarray(amplitudes, dtype=float)
    ts = np.asarray(times, dtype=float)
    limit = level * (1.0 + 1e-6)

    def excess(w: float | np.ndarray) -> np.ndarray:
        return percentage_vibration(amps, ts, w, zeta) - level

    if excess(w0) > limit - level:
        return 0.0
    span = float(ts.max() - ts.min()) if ts.size else 0.0
    step = min(1e-3 * w0, 0.01 / span) if span > 0.0 else 1e-3 * w0

    def edge(stop: float) -> float:
        from scipy.optimize import brentq  # on first use (a node's start need not pay for scipy.optimize)

        n = int(math.ceil(abs(stop - w0) / step)) + 1
        grid = np.linspace(w0, stop, n)
        above = np.flatnonzero(excess(grid) > limit - level)
        if above.size == 0:
            return stop
        i = int(above[0])
        if excess(grid[i - 1]) > 0.0:  # last point inside only within the tolerance
            return float(grid[i - 1])
        return float(brentq(excess, grid[i - 1], grid[i], xtol=1e-12 * w0))

    return (edge(MAX_BAND_RATIO * w0) - edge(0.0)) / w0


@dataclass(frozen=True)
class ResidualVibration:
    """Residual vibration of one cycle: window (s) and RMS/peak of |acceleration| (m/s^2)."""

    window_start: float
    window_end: float
    rms: float
    peak: float
    samples: int


def settle_time(times: np.ndarray, positions: np.ndarray, after: float, tolerance: float) -> float:
    """First time >= ``after`` from which every joint stays within ``tolerance`` of its last value.

    Parameters
    ----------
    times : (N,) array
        Sample times, s, increasing.
    positions : (N, J) array
        Commanded or measured joint positions (rad or m).
    after : float
        Earliest time to return (the unshaped motion's end), s.
    tolerance : float
        Band around the final value (rad or m).
    """
    t = np.asarray(times, dtype=float)
    p = np.asarray(positions, dtype=float).reshape(t.size, -1)
    if t.size == 0:
        return float(after)
    outside = np.any(np.abs(p - p[-1]) > tolerance, axis=1)
    idx = np.flatnonzero(outside)
    if idx.size == 0:
        return float(after)
    last_out = int(idx[-1])
    settle = t[min(last_out + 1, t.size - 1)]
    return float(max(settle, after))


def residual_vibration(
    times: np.ndarray, accel: np.ndarray, start: float, end: float, remove_mean: bool = False
) -> ResidualVibration:
    """RMS and peak of the acceleration magnitude in ``[start, end)``.

    Parameters
    ----------
    times : (N,) array
        Sample times, s.
    accel : (N,) or (N, 3) array
        Acceleration, m/s^2 (the magnitude is taken over the last axis).
    start, end : float
        Window, s.
    remove_mean : bool
        Subtract the window mean per axis first (for sensors with a DC offset or gravity).
    """
    t = np.asarray(times, dtype=float)
    a = np.asarray(accel, dtype=float)
    a = a.reshape(t.size, -1) if a.size else np.zeros((t.size, 1))
    sel = (t >= start) & (t < end)
    w = a[sel]
    if w.shape[0] == 0:
        return ResidualVibration(float(start), float(end), float("nan"), float("nan"), 0)
    if remove_mean:
        w = w - w.mean(axis=0)
    mag = np.linalg.norm(w, axis=1)
    return ResidualVibration(float(start), float(end), float(np.sqrt(np.mean(mag**2))), float(mag.max()),
                             int(w.shape[0]))


def settling_time(times: np.ndarray, accel: np.ndarray, start: float, end: float, band: float,
                  remove_mean: bool = False, hold: float = 0.1) -> float:
    """Time from ``start`` until the acceleration magnitude stays within ``band`` up to ``end``, s.

    Parameters
    ----------
    times : (N,) array
        Sample times, s.
    accel : (N,) or (N, 3) array
        Acceleration, m/s^2 (magnitude over the last axis).
    start, end : float
        Window, s (the residual window of a cycle).
    band : float
        Band half-width, m/s^2, > 0.
    remove_mean : bool
        Subtract the window mean per axis first.
    hold : float
        Fraction of the window the magnitude must stay within the band at its end to count as
        settled (an oscillation near a zero crossing at the window's end is not settled).

    Returns
    -------
    float
        0 if the magnitude is within the band from ``start`` on; the time after ``start`` of the
        first sample from which it stays within it; NaN if it does not stay within it for the
        last ``hold`` of the window, or the window holds no sample.
    """
    if not (math.isfinite(band) and band > 0.0):
        raise ValueError(f"band must be finite and > 0 m/s^2, got {band!r}")
    t = np.asarray(times, dtype=float)
    a = np.asarray(accel, dtype=float)
    a = a.reshape(t.size, -1) if a.size else np.zeros((t.size, 1))
    sel = (t >= start) & (t < end)
    w, tw = a[sel], t[sel]
    if tw.size == 0:
        return float("nan")
    if remove_mean:
        w = w - w.mean(axis=0)
    outside = np.flatnonzero(np.linalg.norm(w, axis=1) > band)
    if outside.size == 0:
        return 0.0
    last = int(outside[-1])
    if last == tw.size - 1 or float(tw[-1] - tw[last + 1]) < hold * float(end - start):
        return float("nan")
    return float(tw[last + 1] - start)
