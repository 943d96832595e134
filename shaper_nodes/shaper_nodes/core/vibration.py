"""Percentage vibration of impulse sequences, and residual vibration of measured cycles.

The percentage vibration (seeds 000, 002, 004; Singer & Seering 1990) is the ratio of the
residual vibration amplitude after the last impulse to that of a single unit impulse:

    V(omega, zeta) = exp(-zeta omega t_n) sqrt(C^2 + S^2),
    C = sum_i A_i exp(zeta omega t_i) cos(omega sqrt(1 - zeta^2) t_i),
    S = sum_i A_i exp(zeta omega t_i) sin(omega sqrt(1 - zeta^2) t_i),

with t_n the last impulse time. omega in rad/s, zeta dimensionless, V a fraction (1 = 100 %).
The exponentials are combined as exp(zeta omega (t_i - t_n)) so that long sequences and
heavy damping do not overflow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    return np.sqrt(c * c + s * s)


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
    a = np.asarray(accel, dtype=float).reshape(t.size, -1)
    sel = (t >= start) & (t < end)
    w = a[sel]
    if w.shape[0] == 0:
        return ResidualVibration(float(start), float(end), float("nan"), float("nan"), 0)
    if remove_mean:
        w = w - w.mean(axis=0)
    mag = np.linalg.norm(w, axis=1)
    return ResidualVibration(float(start), float(end), float(np.sqrt(np.mean(mag**2))), float(mag.max()), int(w.shape[0]))
