"""Identification of vibration modes from free residual vibration.

One record is the accelerometer (or any vibration signal) after a move, while the structure
rings freely. It is modelled, per axis j, as an offset, a linear drift and a sum of M damped
sinusoids sharing their poles across axes:

    y_j(t) = c_j + d_j t + sum_m exp(-s_m t) (a_mj cos(w_m t) + b_mj sin(w_m t)) + noise,

with decay rate ``s_m = zeta_m omega_m`` (1/s) and damped frequency ``w_m = omega_m sqrt(1 -
zeta_m^2)`` (rad/s), so ``omega_m = sqrt(s_m^2 + w_m^2)`` and ``zeta_m = s_m / omega_m``.

Methods (:data:`METHODS`)
-------------------------
fit (default)
    Nonlinear least squares of the model above by variable projection (Golub & Pereyra 1973):
    the residual is minimised over the poles (s_m, w_m) only, the linear coefficients being
    solved by linear least squares at every step; Kaufman's (1975) Jacobian. Modes are added
    one at a time (successive peak extraction on the residual spectrum, each start refined by
    a small grid over damping) and refitted jointly; a mode is kept if it lowers the residual
    sum of squares by more than the BIC penalty. Uncertainty: ``sigma^2 (J^T J)^-1``.
spectral
    Tapered, zero-padded FFT peak refined by parabolic interpolation of the log power; the
    analytic signal (FFT band-pass around the peak) gives the envelope and phase, whose
    weighted straight-line fits give the decay rate (log decrement) and the damped frequency.
    Uncertainty from the regression residuals, corrected for the correlation the band-pass
    introduces. Successive extraction for further modes.
matrix_pencil
    Hua & Sarkar (1990): SVD of a Hankel matrix (stacked over axes), truncated to the model
    order, poles as eigenvalues of the shifted singular-vector pencil. Uncertainty: the same
    Jacobian covariance as ``fit``, evaluated at the pencil estimate.

Preprocessing (all methods): validation, resampling onto a uniform grid when the time stamps
jitter a little, removal of the offset and linear drift, and block-averaging decimation of
long, heavily oversampled records (block means keep a sum of damped exponentials a sum of the
same exponentials, so the poles are unchanged).

The shaper recommended for the modes found is in :mod:`.recommend`. See docs/identification.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh
from scipy.optimize import least_squares
from scipy.signal import find_peaks

from shaper_nodes.core.checks import InputError, finite_array, strictly_increasing
from shaper_nodes.core.shaping import Mode

#: fewest samples in a record
MIN_SAMPLES = 32
#: fewest damped periods of the strongest mode a record must span
MIN_PERIODS = 3.0
#: largest relative deviation of a time step from the median step that is resampled
MAX_JITTER = 0.25
#: modes weaker than this fraction of the strongest (initial amplitude) are dropped
MIN_RELATIVE_AMPLITUDE = 0.05
#: identified damping ratios must lie in (0, MAX_IDENTIFIED_DAMPING)
MAX_IDENTIFIED_DAMPING = 0.9
#: modes are searched below this fraction of the Nyquist frequency
MAX_NYQUIST_FRACTION = 0.9
#: longest record (samples) before decimation is considered, and the length it aims for
DECIMATE_ABOVE = 1000
#: samples per period of 1.5 x the highest spectral peak kept after decimation
OVERSAMPLING = 10
#: with ``band_hz``, this many modes outside the band may be fitted as nuisance modes
NUISANCE_MODES = 4
#: relative frequency difference within which modes of different records are the same mode
MATCH_TOLERANCE = 0.1

#: identification methods, name -> description
METHODS: dict[str, str] = {
    "fit": "nonlinear least squares (variable projection) of damped sinusoids + offset + drift;"
    " Jacobian covariance",
    "spectral": "FFT peak with parabolic interpolation, Hilbert envelope log decrement and phase"
    " slope; regression-residual uncertainty",
    "matrix_pencil": "Hankel-SVD matrix pencil (Hua & Sarkar 1990); Jacobian covariance at the"
    " estimate",
}


class IdentificationError(ValueError):
    """Identification is impossible; the message names the problem."""


@dataclass(frozen=True)
class ModeFit:
    """An identified vibration mode with one-sigma uncertainties.

    Attributes
    ----------
    omega : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio, dimensionless.
    omega_std, zeta_std : float
        One-sigma uncertainties of omega (rad/s) and zeta.
    amplitude : float
        Initial amplitude of the decay (norm over axes), in signal units; ranks modes.
    method : str
        The method that produced it (a key of :data:`METHODS`).
    """

    omega: float
    zeta: float
    omega_std: float
    zeta_std: float
    amplitude: float
    method: str

    @property
    def mode(self) -> Mode:
        """The mode (omega, zeta) for shaper design."""
        return Mode(self.omega, self.zeta)

    @property
    def hz(self) -> float:
        """Natural frequency, Hz."""
        return self.omega / (2.0 * math.pi)


# --------------------------------------------------------------------------------------------
# Preprocessing


@dataclass(frozen=True)
class _Record:
    t: np.ndarray  # (N,) s, uniform, from 0 at the record start
    y: np.ndarray  # (N, k) detrended
    dt: float  # s
    band: tuple[float, float]  # Hz, natural frequencies reported
    limited: bool  # band_hz given: modes outside it may be fitted as nuisance modes

    @property
    def search(self) -> tuple[float, float]:
        """Hz, where peaks and poles are searched (the whole usable spectrum if limited)."""
        return (0.0, MAX_NYQUIST_FRACTION * 0.5 / self.dt) if self.limited else self.band

    def in_band(self, theta: np.ndarray) -> np.ndarray:
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


def _detrend(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    base = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(base, y, rcond=None)
    return y - base @ coef


def _spectrum(y: np.ndarray, dt: float, pad: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Power spectrum summed over axes, with the right half of a Hann window as taper.

    A free decay is strongest at the start of the record, so only the end is tapered.
    """
    n = y.shape[0]
    taper = np.cos(0.5 * np.pi * np.arange(n) / n) ** 2
    nfft = 1 << int(math.ceil(math.log2(pad * n)))
    spec = np.fft.rfft(taper[:, None] * y, n=nfft, axis=0)
    return np.fft.rfftfreq(nfft, dt), np.sum(np.abs(spec) ** 2, axis=1)


def _peaks(freqs: np.ndarray, power: np.ndarray, band: tuple[float, float], fmin: float,
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


def _decimation(y: np.ndarray, dt: float) -> int:
    """Block length q bringing a long record down to about DECIMATE_ABOVE samples, keeping
    OVERSAMPLING samples per period of 1.5 times the highest significant spectral peak (a
    local maximum 10 times above its surroundings and above 10 times the median power), so
    that no mode aliases."""
    n = y.shape[0]
    if n <= DECIMATE_ABOVE:
        return 1
    freqs, power = _spectrum(y, dt, pad=1)
    smooth = np.convolve(power, np.ones(5) / 5.0, mode="same")
    threshold = max(1e-6 * smooth.max(), 10.0 * float(np.median(smooth)))
    idx, _ = find_peaks(np.log(smooth + 1e-300), prominence=math.log(10.0))
    idx = idx[smooth[idx] > threshold]
    if idx.size == 0:
        return 1
    f_keep = 1.5 * max(float(freqs[idx].max()), freqs[1])
    q = min(int(1.0 / (dt * OVERSAMPLING * f_keep)), -(-n // DECIMATE_ABOVE))
    return max(q, 1)


def _prepare(times, signal, band_hz) -> _Record:
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
    return _Record(t, y, dt, band, band_hz is not None)


# --------------------------------------------------------------------------------------------
# The linear-in-coefficients model and its variable-projection residual


class _Model:
    """Offset + drift + damped sinusoids, linear coefficients solved for given poles."""

    def __init__(self, rec: _Record) -> None:
        self.t = rec.t
        self.y = rec.y
        self.k = rec.y.shape[1]
        self.base = np.column_stack([np.ones_like(rec.t), rec.t / rec.t[-1]])
        self._cache: tuple[bytes, tuple] | None = None

    def basis(self, s: np.ndarray, w: np.ndarray) -> np.ndarray:
        e = np.exp(-np.outer(self.t, s))
        ph = np.outer(self.t, w)
        return np.hstack([self.base, e * np.cos(ph), e * np.sin(ph)])

    def solve(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Basis Phi (N, 2 + 2M), coefficients (2 + 2M, k) and residual (N, k) for the poles.

        Least squares through the Gram matrix of the unit-normalised columns (small, and well
        conditioned for distinct poles), pseudo-inverted by eigen-decomposition; tall QR or
        SVD would cost far more for these few columns.
        """
        key = theta.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        phi = self.basis(theta[0::2], theta[1::2])
        coef = self._lstsq(phi, self.y)
        resid = self.y - phi @ coef
        out = (phi, coef, resid)
        self._cache = (key, out)
        return out

    @staticmethod
    def _lstsq(phi: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        norm = np.sqrt(np.sum(phi * phi, axis=0))
        norm[norm == 0.0] = 1.0
        a = phi / norm
        vals, vecs = np.linalg.eigh(a.T @ a)
        inv = np.where(vals > 1e-13 * vals[-1], 1.0 / np.where(vals > 0, vals, 1.0), 0.0)
        return (vecs @ (inv[:, None] * (vecs.T @ (a.T @ rhs)))) / norm[:, None]

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return self.solve(theta)[2].ravel()

    def rss(self, theta: np.ndarray) -> float:
        r = self.solve(theta)[2]
        return float(np.sum(r * r))

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """Kaufman's variable-projection Jacobian -P_perp dPhi/dtheta c, (N k, 2M)."""
        phi, coef, _ = self.solve(theta)
        s, w = theta[0::2], theta[1::2]
        m = s.size
        t = self.t[:, None]
        ds = []
        for i in range(m):
            e = np.exp(-s[i] * t)
            c, sn = np.cos(w[i] * t), np.sin(w[i] * t)
            a, b = coef[2 + i], coef[2 + m + i]
            ds.append(-t * e * (c * a + sn * b))  # d model / d s_i, (N, k)
            ds.append(t * e * (c * b - sn * a))  # d model / d w_i
        d = np.hstack(ds)
        proj = d - phi @ self._lstsq(phi, d)
        return -proj.reshape(self.t.size, 2 * m, self.k).transpose(0, 2, 1).reshape(-1, 2 * m)

    def rss_null(self) -> float:
        coef, *_ = np.linalg.lstsq(self.base, self.y, rcond=None)
        r = self.y - self.base @ coef
        return float(np.sum(r * r))

    def dof(self, m: int) -> int:
        return self.y.size - (2 * m + self.k * (2 + 2 * m))


def _fit_poles(model: _Model, theta0: np.ndarray, rec: _Record) -> np.ndarray:
    m = theta0.size // 2
    wmax = MAX_NYQUIST_FRACTION * math.pi / rec.dt
    lb = np.tile([0.0, 2 * math.pi * rec.search[0]], m)
    ub = np.tile([np.inf, min(2 * math.pi * rec.search[1] * 1.05, wmax)], m)
    x0 = np.clip(theta0, lb + 1e-9 * np.maximum(ub[1], 1.0), ub * (1 - 1e-9))
    sol = least_squares(
        model.residual, x0, jac=model.jacobian, bounds=(lb, ub), x_scale="jac",
        method="trf", xtol=1e-10, ftol=1e-12, gtol=1e-12, max_nfev=100 * (m + 1),
    )
    return np.asarray(sol.x, dtype=float)


def _penalty(model: _Model) -> float:
    """BIC penalty of one more mode (2 poles + 2k coefficients), in units of sigma^2."""
    return (2 + 2 * model.k) * math.log(model.y.size)


def _sigma2(model: _Model, rss: float, m: int) -> float:
    floor = 1e-20 * float(np.mean(model.y**2))
    return max(rss / max(model.dof(m), 1), floor)


def _start_for(model: _Model, theta: np.ndarray, f_peak: float, rec: _Record) -> np.ndarray:
    """Initial (s, w) of a new mode near a spectral peak, the other modes fixed: the best
    damping of a coarse grid at the peak frequency, then the best of a few frequencies around
    the peak at that damping (the peak of a heavily damped mode is broad and shifted)."""
    wmax = MAX_NYQUIST_FRACTION * math.pi / rec.dt
    w0 = min(2 * math.pi * f_peak, 0.99 * wmax)

    def cand(zeta: float, w: float) -> np.ndarray:
        return np.append(theta, [zeta * w / math.sqrt(1 - zeta**2), w])

    zeta = min((0.003, 0.01, 0.03, 0.1, 0.3), key=lambda z: model.rss(cand(z, w0)))
    ws = [w0] + [w0 * f for f in (0.85, 0.93, 1.07, 1.15) if w0 * f < wmax]
    w = min(ws, key=lambda w: model.rss(cand(zeta, w)))
    return cand(zeta, w)


def _near(f: float, theta: np.ndarray, df: float) -> bool:
    w = theta[1::2] / (2 * math.pi)
    return bool(np.any(np.abs(w - f) < df))


def _budget(rec: _Record, theta: np.ndarray, max_modes: int) -> bool:
    """True while more modes may be added: fewer than max_modes in the band and, with a band,
    at most NUISANCE_MODES more outside it."""
    m = theta.size // 2
    inside = int(rec.in_band(theta).sum()) if m else 0
    return inside < max_modes and m < max_modes + (NUISANCE_MODES if rec.limited else 0)


def _next_peak(model: _Model, rec: _Record, theta: np.ndarray, fmin: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float | None]:
    """The residual of the modes so far, its spectrum, and its strongest new peak (Hz) or None."""
    resid = model.solve(theta)[2] if theta.size else rec.y
    freqs, power = _spectrum(resid, rec.dt)
    peaks = [f for f in _peaks(freqs, power, rec.search, fmin) if not _near(f, theta, 0.5 * fmin)]
    return resid, freqs, power, (peaks[0] if peaks else None)


def _method_fit(rec: _Record, max_modes: int) -> tuple[np.ndarray, np.ndarray | None]:
    model = _Model(rec)
    theta = np.zeros(0)
    rss = model.rss_null()
    fmin = 1.0 / rec.t[-1]
    while _budget(rec, theta, max_modes):
        peak = _next_peak(model, rec, theta, fmin)[3]
        if peak is None:
            break
        cand = _fit_poles(model, _start_for(model, theta, peak, rec), rec)
        rss_new = model.rss(cand)
        m = cand.size // 2
        if rss - rss_new <= _penalty(model) * _sigma2(model, rss_new, m):
            break
        theta, rss = cand, rss_new
    return theta, None


def _method_matrix_pencil(rec: _Record, max_modes: int) -> tuple[np.ndarray, np.ndarray | None]:
    y = rec.y
    n = y.shape[0]
    lpen = int(min(max(n // 3, 4), 150))
    total = max_modes + (NUISANCE_MODES if rec.limited else 0)
    order = min(2 * total + 6, lpen - 1)
    idx = np.arange(n - lpen)[:, None] + np.arange(lpen + 1)[None, :]
    hank = np.vstack([y[idx, j] for j in range(y.shape[1])])
    # dominant right singular vectors of the Hankel matrix = top eigenvectors of its Gram matrix
    _, vecs = eigh(hank.T @ hank, subset_by_index=(lpen + 1 - order, lpen), driver="evr")
    v = vecs[:, ::-1]
    z = np.linalg.eigvals(np.linalg.pinv(v[:-1]) @ v[1:])
    z = z[np.abs(z) > 1e-12]
    lam = np.log(z.astype(complex)) / rec.dt
    s, w = -lam.real, lam.imag
    f = w / (2 * math.pi)
    keep = (f >= max(rec.search[0], 1.0 / rec.t[-1])) & (f <= rec.search[1]) & (s > -0.5 * w)
    if not keep.any():
        return np.zeros(0), None
    theta = np.column_stack([s[keep], w[keep]]).ravel()
    model = _Model(rec)
    theta = _prune(model, theta)
    m = theta.size // 2
    if m > max_modes:
        # the strongest max_modes in the band, and up to NUISANCE_MODES outside it
        coef = model.solve(theta)[1]
        amp = np.sqrt(np.sum(coef[2 : 2 + m] ** 2 + coef[2 + m :] ** 2, axis=1))
        inside = rec.in_band(theta)
        order_idx = np.argsort(amp)[::-1]
        top = np.concatenate([order_idx[inside[order_idx]][:max_modes],
                              order_idx[~inside[order_idx]][: total - max_modes]])
        top = np.sort(top)
        theta = np.column_stack([theta[0::2][top], theta[1::2][top]]).ravel()
    return theta, None


def _prune(model: _Model, theta: np.ndarray) -> np.ndarray:
    """Drop modes whose removal raises the RSS by less than the BIC penalty (weakest first)."""
    while theta.size:
        m = theta.size // 2
        rss = model.rss(theta)
        s2 = _sigma2(model, rss, m)
        gains = []
        for i in range(m):
            rest = np.delete(theta, [2 * i, 2 * i + 1])
            gains.append((model.rss(rest) if rest.size else model.rss_null()) - rss)
        i = int(np.argmin(gains))
        if gains[i] > _penalty(model) * s2:
            break
        theta = np.delete(theta, [2 * i, 2 * i + 1])
    return theta


def _analytic_band(y: np.ndarray, dt: float, f0: float, half_width: float) -> np.ndarray:
    """Analytic signal of each axis band-passed to f0 +- half_width (Hz), raised-cosine edges."""
    n = y.shape[0]
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.fft(y, n=nfft, axis=0)
    f = np.fft.fftfreq(nfft, dt)
    x = np.clip((np.abs(f - f0) - half_width) / half_width + 1.0, 0.0, 1.0)
    gain = np.where(f > 0, 2.0 * np.cos(0.5 * np.pi * x) ** 2, 0.0)
    return np.fft.ifft(spec * gain[:, None], axis=0)[:n]


def _weighted_line(t: np.ndarray, v: np.ndarray, wts: np.ndarray, corr: float) -> tuple[float, float]:
    """Weighted least-squares slope of v(t) and its standard error, inflated by sqrt(corr)."""
    wsum = wts.sum()
    tm = np.sum(wts * t) / wsum
    vm = np.sum(wts * v) / wsum
    stt = np.sum(wts * (t - tm) ** 2)
    slope = float(np.sum(wts * (t - tm) * (v - vm)) / stt)
    res = v - vm - slope * (t - tm)
    neff = max(wsum**2 / np.sum(wts**2) / corr, 3.0)
    s2 = np.sum(wts * res**2) / wsum * neff / (neff - 2.0)
    return slope, float(math.sqrt(s2 / (stt / wsum) / neff))


def _spectral_mode(rec: _Record, y: np.ndarray, f_peak: float, freqs: np.ndarray, power: np.ndarray
                   ) -> tuple[float, float, float, float] | None:
    """(s, w, s_std, w_std) of the mode at f_peak from the envelope and phase of y."""
    dt, t = rec.dt, rec.t
    n = t.size
    big = power.max()
    i0 = int(np.argmin(np.abs(freqs - f_peak)))
    half = power[i0] / 2.0
    lo = i0
    while lo > 0 and power[lo] > half:
        lo -= 1
    hi = i0
    while hi < power.size - 1 and power[hi] > half:
        hi += 1
    hpbw = max(freqs[hi] - freqs[lo], 1.0 / t[-1])  # Hz, full width
    half_width = min(max(3.0 * hpbw, 3.0 / t[-1]), 0.9 * f_peak)
    z = _analytic_band(y, dt, f_peak, half_width)
    # principal complex direction over axes = mode shape
    _, _, vh = np.linalg.svd(z, full_matrices=False)
    p = z @ vh[0].conj()
    env = np.abs(p)
    phase = np.unwrap(np.angle(p))
    # white-noise level from the median of the spectrum -> noise of the band-passed signal
    taper2 = np.sum(np.cos(0.5 * np.pi * np.arange(n) / n) ** 4)
    sigma2 = float(np.median(power)) / math.log(2.0) / taper2 / y.shape[1]
    floor = math.sqrt(sigma2 * 4.0 * half_width * dt) if big > 0 else 0.0
    edge = int(math.ceil(0.5 / (half_width * dt)))
    sel = np.zeros(n, dtype=bool)
    sel[edge : n - edge] = True
    sel &= env > 3.0 * floor
    if sel.sum() < 8:
        sel = np.zeros(n, dtype=bool)
        sel[edge : max(edge + 8, n - edge)] = True
        sel &= env > 0
        if sel.sum() < 4:
            return None
    corr = max(1.0 / (2.0 * half_width * dt), 1.0)  # samples per independent noise sample
    wts = env[sel] ** 2
    slope_env, se_env = _weighted_line(t[sel], np.log(env[sel]), wts, corr)
    w, se_w = _weighted_line(t[sel], phase[sel], wts, corr)
    s = -slope_env
    if not (w > 0):
        return None
    return s, abs(w), se_env, se_w


def _method_spectral(rec: _Record, max_modes: int) -> tuple[np.ndarray, np.ndarray | None]:
    model = _Model(rec)
    theta = np.zeros(0)
    cov_blocks: list[np.ndarray] = []
    fmin = 1.0 / rec.t[-1]
    rss = model.rss_null()
    while _budget(rec, theta, max_modes):
        resid, freqs, power, peak = _next_peak(model, rec, theta, fmin)
        if peak is None:
            break
        est = _spectral_mode(rec, resid, peak, freqs, power)
        if est is None:
            break
        s, w, ss, sw = est
        cand = np.append(theta, [max(s, 0.0), w])
        rss_new = model.rss(cand)
        if rss - rss_new <= _penalty(model) * _sigma2(model, rss_new, cand.size // 2):
            break
        theta, rss = cand, rss_new
        cov_blocks.append(np.diag([ss**2, sw**2]))
    if not theta.size:
        return theta, None
    cov = np.zeros((theta.size, theta.size))
    for i, blk in enumerate(cov_blocks):
        cov[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = blk
    return theta, cov


_IMPLEMENTATIONS: dict[str, Callable[[_Record, int], tuple[np.ndarray, np.ndarray | None]]] = {
    "fit": _method_fit,
    "spectral": _method_spectral,
    "matrix_pencil": _method_matrix_pencil,
}


def _covariance(model: _Model, theta: np.ndarray) -> np.ndarray:
    """sigma^2 (J^T J)^-1 of the poles (the linear coefficients profiled out)."""
    jac = model.jacobian(theta)
    m = theta.size // 2
    s2 = _sigma2(model, model.rss(theta), m)
    return s2 * np.linalg.pinv(jac.T @ jac)


def _to_modes(rec: _Record, theta: np.ndarray, cov: np.ndarray | None, method: str) -> list[ModeFit]:
    model = _Model(rec)
    if cov is None:
        cov = _covariance(model, theta)
    coef = model.solve(theta)[1]
    m = theta.size // 2
    out = []
    for i in range(m):
        s, w = float(theta[2 * i]), float(theta[2 * i + 1])
        omega = math.hypot(s, w)
        zeta = s / omega
        g = np.array([[s / omega, w / omega], [w * w / omega**3, -s * w / omega**3]])
        c = g @ cov[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] @ g.T
        amp = float(np.sqrt(np.sum(coef[2 + i] ** 2 + coef[2 + m + i] ** 2)))
        out.append(ModeFit(omega, zeta, float(math.sqrt(max(c[0, 0], 0.0))),
                           float(math.sqrt(max(c[1, 1], 0.0))), amp, method))
    return out


def _check_method(method: str, max_modes: int) -> str:
    name = str(method).strip().lower()
    if name not in METHODS:
        raise IdentificationError(f"unknown identification method {method!r}; known: {sorted(METHODS)}")
    if isinstance(max_modes, bool) or int(max_modes) != max_modes or not 1 <= int(max_modes) <= 8:
        raise IdentificationError(f"max_modes must be an integer in [1, 8], got {max_modes!r}")
    return name


def identify(
    times: Sequence[float] | np.ndarray,
    signal: Sequence[float] | np.ndarray,
    *,
    method: str = "fit",
    max_modes: int = 2,
    band_hz: tuple[float, float] | None = None,
) -> list[ModeFit]:
    """Identify the vibration modes of one record of free residual vibration.

    Parameters
    ----------
    times : (N,) array_like
        Sample times, s, strictly increasing and near-uniform (steps within
        :data:`MAX_JITTER` of the median; resampled linearly onto a uniform grid).
    signal : (N,) or (N, k) array_like
        The vibration (e.g. acceleration in m/s^2, k axes). Axes share the modes' poles and
        are fitted jointly; offset and linear drift per axis are part of the model.
    method : str
        One of :data:`METHODS`; ``"fit"`` (default) is the most accurate.
    max_modes : int
        Most modes to identify (1 to 8).
    band_hz : (float, float), optional
        Only look for natural frequencies in this band, Hz.

    Returns
    -------
    list of ModeFit
        Strongest (largest initial amplitude) first. Modes with damping outside (0,
        :data:`MAX_IDENTIFIED_DAMPING`), fewer than :data:`MIN_PERIODS` damped periods in the
        record, or weaker than :data:`MIN_RELATIVE_AMPLITUDE` of the strongest are dropped.

    Raises
    ------
    IdentificationError
        Bad input (non-finite, mismatched lengths, non-increasing or irregular times, too few
        samples), a record shorter than MIN_PERIODS periods of its strongest mode, or no mode
        significantly above the noise.
    """
    name = _check_method(method, max_modes)
    rec = _prepare(times, signal, band_hz)
    theta, cov = _IMPLEMENTATIONS[name](rec, int(max_modes))
    if theta.size == 0:
        raise IdentificationError(
            "no mode found: no damped oscillation significantly above the noise"
            + (f" in {rec.band[0]:.4g}-{rec.band[1]:.4g} Hz" if band_hz is not None else "")
        )
    modes = [mf for mf, inside in zip(_to_modes(rec, theta, cov, name), rec.in_band(theta)) if inside]
    if not modes:
        raise IdentificationError(
            f"no mode found in {rec.band[0]:.4g}-{rec.band[1]:.4g} Hz: the oscillations found lie outside"
        )
    modes.sort(key=lambda mf: -mf.amplitude)
    duration = float(rec.t[-1] + rec.dt)
    strongest = modes[0]
    periods = duration * strongest.omega * math.sqrt(max(1.0 - strongest.zeta**2, 0.0)) / (2 * math.pi)
    if periods < MIN_PERIODS and 0.0 < strongest.zeta < MAX_IDENTIFIED_DAMPING:
        raise IdentificationError(
            f"record too short: {duration:.4g} s holds {periods:.2f} periods of the strongest mode"
            f" ({strongest.hz:.4g} Hz), need at least {MIN_PERIODS:g}"
        )
    kept = []
    for mf in modes:
        wd = mf.omega * math.sqrt(max(1.0 - mf.zeta**2, 0.0))
        if not 0.0 < mf.zeta < MAX_IDENTIFIED_DAMPING:
            continue
        if duration * wd / (2 * math.pi) < MIN_PERIODS:
            continue
        kept.append(mf)
    if not kept:
        raise IdentificationError(
            "no mode found: the oscillations found have damping outside"
            f" (0, {MAX_IDENTIFIED_DAMPING}) (growing, undamped or overdamped)"
        )
    top = kept[0].amplitude
    return [mf for mf in kept if mf.amplitude >= MIN_RELATIVE_AMPLITUDE * top]


def identify_records(
    records: Sequence[tuple[Sequence[float] | np.ndarray, Sequence[float] | np.ndarray]],
    *,
    method: str = "fit",
    max_modes: int = 2,
    band_hz: tuple[float, float] | None = None,
) -> list[ModeFit]:
    """Identify modes in several records (e.g. one per move) and combine them.

    Each record is identified with :func:`identify`. Modes are matched across records by
    natural frequency (within :data:`MATCH_TOLERANCE`, strongest first, at most one per
    record); a mode is kept if found in at least half of the records. The combined omega and
    zeta are the means; each uncertainty is the larger of the RMS per-record one-sigma and the
    standard deviation between records, i.e. the spread of a single record's mode, which the
    shaper must tolerate (not the standard error of the mean).

    Raises
    ------
    IdentificationError
        No records, or a record that cannot be identified (the message names its index).
    """
    records = list(records)
    if not records:
        raise IdentificationError("no records to identify")
    name = _check_method(method, max_modes)
    per_record: list[list[ModeFit]] = []
    for i, rec in enumerate(records):
        try:
            times, signal = rec
        except (TypeError, ValueError) as exc:
            raise IdentificationError(f"record {i}: expected a (times, signal) pair") from exc
        try:
            per_record.append(identify(times, signal, method=name, max_modes=max_modes, band_hz=band_hz))
        except IdentificationError as exc:
            raise IdentificationError(f"record {i}: {exc}") from exc
    return combine_modes(per_record, method=name, max_modes=max_modes)


def combine_modes(per_record: Sequence[Sequence[ModeFit]], *, method: str = "fit", max_modes: int = 2
                  ) -> list[ModeFit]:
    """Combine the modes identified in several records, as :func:`identify_records` does.

    ``per_record`` holds each record's modes (from :func:`identify`); matching, the at-least-half
    rule and the uncertainties are those described in :func:`identify_records`.
    """
    clusters: list[list[tuple[int, ModeFit]]] = []
    entries = sorted(((i, mf) for i, mfs in enumerate(per_record) for mf in mfs), key=lambda e: -e[1].amplitude)
    for i, mf in entries:
        best, best_d = None, MATCH_TOLERANCE
        for cl in clusters:
            if any(j == i for j, _ in cl):
                continue
            ref = float(np.mean([m.omega for _, m in cl]))
            d = abs(mf.omega - ref) / ref
            if d < best_d:
                best, best_d = cl, d
        if best is None:
            clusters.append([(i, mf)])
        else:
            best.append((i, mf))
    need = math.ceil(len(per_record) / 2)
    out = []
    for cl in clusters:
        if len(cl) < need:
            continue
        om = np.array([m.omega for _, m in cl])
        ze = np.array([m.zeta for _, m in cl])
        om_std = math.sqrt(float(np.mean([m.omega_std**2 for _, m in cl])))
        ze_std = math.sqrt(float(np.mean([m.zeta_std**2 for _, m in cl])))
        if len(cl) > 1:
            om_std = max(om_std, float(np.std(om, ddof=1)))
            ze_std = max(ze_std, float(np.std(ze, ddof=1)))
        out.append(ModeFit(float(om.mean()), float(ze.mean()), om_std, ze_std,
                           float(np.mean([m.amplitude for _, m in cl])), method))
    out.sort(key=lambda mf: -mf.amplitude)
    return out[: int(max_modes)]
