"""The record of free vibration, prepared for identification, and its spectrum.

A record (:class:`Record`) is what every method of :mod:`.estimators` works on: the samples
validated (finite, strictly increasing and near-uniform times, enough of them), resampled onto a
uniform grid when the time stamps jitter a little, with the offset and linear drift removed,
and long, heavily oversampled records decimated by block averaging (block means keep a sum of
damped exponentials a sum of the same exponentials, so the poles are unchanged). Also here: the
tapered power spectrum and its peaks, from which modes are started, and
:class:`IdentificationError`, the package's error, which these checks raise first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks

from shaper_nodes.core.checks import InputError, finite_array, strictly_increasing

#: arrays of samples, times, frequencies and poles (float64 in practice)
FloatArray = npt.NDArray[np.floating[Any]]

#: fewest samples in a record
MIN_SAMPLES = 32
#: largest relative deviation of a time step from the median step that is resampled
MAX_JITTER = 0.25
#: modes are searched below this fraction of the Nyquist frequency
MAX_NYQUIST_FRACTION = 0.9
#: longest record (samples) before decimation is considered, and the length it aims for
DECIMATE_ABOVE = 1000
#: samples per period of 1.5 x the highest spectral peak kept after decimation
OVERSAMPLING = 10


class IdentificationError(ValueError):
    """Identification is impossible; the message names the problem."""


@dataclass(frozen=True)
class Record:
    t: FloatArray  # (N,) s, uniform, from 0 at the record start
    y: FloatArray  # (N, k) detrended
    dt: float  # s
    band: tuple[float, float]  # Hz, natural frequencies reported
    limited: bool  # band_hz given: modes outside it may be fitted as nuisance modes

    @property
    def search(self) -> tuple[float, float]:
        """Hz, where peaks and poles are searched (the whole usable spectrum if limited)."""
        return (0.0, MAX_NYQUIST_FRACTION * 0.5 / self.dt) if self.limited else self.band

    def in_band(self, theta: FloatArray) -> npt.NDArray[np.bool_]:
        f = np.hypot(theta[0::2], theta[1::2]) / (2 * math.pi)
        return (f >= self.band[0]) & (f <= self.band[1])


def _as_band(band_hz: tuple[float, float] | None, nyquist: float) -> tuple[float, float]:
    if band_hz is None:
        return 0.0, nyquist
    try:
        lo, hi = (float(x) for x in band_hz)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"band_hz must be (low, high) in Hz, got {band_hz!r}") from exc
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise IdentificationError(f"band_hz must be (low, high) with 0 <= low < high, got {band_hz!r}")
    if lo >= nyquist:
        raise IdentificationError(f"band_hz {band_hz!r} lies above the Nyquist frequency {nyquist:.6g} Hz")
    return lo, min(hi, nyquist)


def _detrend(t: FloatArray, y: FloatArray) -> FloatArray:
    base = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(base, y, rcond=None)
    detrended: FloatArray = y - base @ coef
    return detrended


def spectrum(y: FloatArray, dt: float, pad: int = 4) -> tuple[FloatArray, FloatArray]:
    """Power spectrum summed over axes, with the right half of a Hann window as taper.

    A free decay is strongest at the start of the record, so only the end is tapered.
    """
    n = y.shape[0]
    taper = np.cos(0.5 * np.pi * np.arange(n) / n) ** 2
    nfft = 1 << int(math.ceil(math.log2(pad * n)))
    spec = np.fft.rfft(taper[:, None] * y, n=nfft, axis=0)
    return np.fft.rfftfreq(nfft, dt), np.sum(np.abs(spec) ** 2, axis=1)


def spectral_peaks(freqs: FloatArray, power: FloatArray, band: tuple[float, float], fmin: float,
           count: int = 8) -> list[float]:
    """The ``count`` largest local maxima of the power in the band (Hz), parabolic-refined."""
    idx, _ = find_peaks(power)
    lo = max(band[0], fmin)
    idx = idx[(freqs[idx] >= lo) & (freqs[idx] <= band[1])]
    idx = idx[np.argsort(power[idx])[::-1][:count]]
    df = freqs[1] - freqs[0]
    out = []
    for i in idx:
        lp = np.log(power[i - 1 : i + 2] + 1e-300)
        den = lp[0] - 2.0 * lp[1] + lp[2]
        delta = 0.5 * (lp[0] - lp[2]) / den if den < 0.0 else 0.0
        out.append(float(freqs[i] + np.clip(delta, -0.5, 0.5) * df))
    return out


def _decimation(y: FloatArray, dt: float) -> int:
    """Block length q bringing a long record down to about DECIMATE_ABOVE samples, keeping
    OVERSAMPLING samples per period of 1.5 times the highest significant spectral peak (a
    local maximum 10 times above its surroundings and above 10 times the median power), so
    that no mode aliases."""
    n = y.shape[0]
    if n <= DECIMATE_ABOVE:
        return 1
    freqs, power = spectrum(y, dt, pad=1)
    smooth = np.convolve(power, np.ones(5) / 5.0, mode="same")
    threshold = max(1e-6 * smooth.max(), 10.0 * float(np.median(smooth)))
    idx, _ = find_peaks(np.log(smooth + 1e-300), prominence=math.log(10.0))
    idx = idx[smooth[idx] > threshold]
    if idx.size == 0:
        return 1
    f_keep = 1.5 * max(float(freqs[idx].max()), freqs[1])
    q: int = min(int(1.0 / (dt * OVERSAMPLING * f_keep)), -(-n // DECIMATE_ABOVE))
    return max(q, 1)


def prepare(times: Sequence[float] | FloatArray, signal: Sequence[float] | FloatArray,
            band_hz: tuple[float, float] | None) -> Record:
    """The record of ``times`` and ``signal`` (see :func:`~.modes.identify`) checked, resampled
    onto a uniform grid if needed, detrended and decimated; ``band_hz`` limits the modes reported."""
    try:
        t = strictly_increasing("times", finite_array("times", times))
        y = finite_array("signal", signal)
    except InputError as exc:
        raise IdentificationError(str(exc)) from exc
    if t.ndim != 1:
        raise IdentificationError(f"times must be one-dimensional, got shape {t.shape}")
    if y.ndim == 1:
        y = y[:, None]
    if y.ndim != 2:
        raise IdentificationError(f"signal must be (N,) or (N, k), got shape {y.shape}")
    if y.shape[0] != t.size:
        raise IdentificationError(f"times and signal lengths differ: {t.size} times, {y.shape[0]} samples")
    if t.size < MIN_SAMPLES:
        raise IdentificationError(f"too few samples: {t.size}, need at least {MIN_SAMPLES}")
    steps = np.diff(t)
    dt = float(np.median(steps))
    jitter = float(np.max(np.abs(steps / dt - 1.0)))
    if jitter > MAX_JITTER:
        raise IdentificationError(
            f"sample times are not near-uniform: steps from {steps.min():.4g} s to {steps.max():.4g} s"
            f" (median {dt:.4g} s, {100 * jitter:.0f} % off, more than {100 * MAX_JITTER:.0f} %);"
            " split the record at the gap or resample it"
        )
    t = t - t[0]
    if jitter > 1e-9:
        grid = np.arange(int(math.floor(t[-1] / dt + 1e-9)) + 1) * dt
        y = np.column_stack([np.interp(grid, t, col) for col in y.T])
        t = grid
    scale = float(np.max(np.abs(y)))
    y = _detrend(t, y)
    if float(np.max(np.abs(y))) <= 1e-12 * max(scale, 1e-300):
        raise IdentificationError("no mode found: the signal is constant after removing offset and drift")
    band = _as_band(band_hz, 0.5 / dt)
    band = (band[0], min(band[1], MAX_NYQUIST_FRACTION * 0.5 / dt))
    q = _decimation(y, dt)
    if q > 1:
        n = (t.size // q) * q
        y = y[:n].reshape(-1, q, y.shape[1]).mean(axis=1)
        t = t[:n].reshape(-1, q).mean(axis=1)
        dt *= q
        band = (band[0], min(band[1], MAX_NYQUIST_FRACTION * 0.5 / dt))
    return Record(t, y, dt, band, band_hz is not None)

