"""The identification methods: poles (s_m, w_m) of the damped sinusoids in a record.

Each method (:data:`ESTIMATORS`, keyed as :data:`~.modes.METHODS`) takes a :class:`~.record.Record`
and the most modes wanted, and returns the poles ``theta = [s_1, w_1, s_2, w_2, ...]`` (decay
rates 1/s, damped frequencies rad/s) with their covariance, or None for the Jacobian one
(:func:`covariance`):

fit
    Nonlinear least squares by variable projection (:class:`PoleModel`): the residual is
    minimised over the poles only, the linear coefficients (offset, drift, amplitudes) solved
    at every step; modes added one at a time from the residual spectrum's peaks and kept when
    they lower the residual by more than the BIC penalty.
spectral
    Peak, envelope decay and phase slope of the band-passed analytic signal, mode by mode.
matrix_pencil
    Poles as eigenvalues of the shifted singular-vector pencil of a Hankel matrix, pruned by
    the BIC penalty.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from scipy.linalg import eigh
from scipy.optimize import least_squares

from .record import MAX_NYQUIST_FRACTION, FloatArray, Record, spectral_peaks, spectrum

#: with ``band_hz``, this many modes outside the band may be fitted as nuisance modes
NUISANCE_MODES = 4


#: the least squares of a basis Phi: its column norms, the unit-normalised columns, and the eigenvectors and
#: pseudo-inverted eigenvalues of their Gram matrix (see :meth:`PoleModel.solve`)
_Gram = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
#: what :meth:`PoleModel.solve` computed on the way that the Jacobian uses again: the Gram decomposition, and
#: the basis' envelopes, cosines and sines (N, M) each
_Parts = tuple[_Gram, tuple[FloatArray, FloatArray, FloatArray]]


def _gram(phi: FloatArray) -> _Gram:
    """The Gram decomposition of the basis ``phi`` that :func:`_gram_solve` solves on."""
    norm = np.sqrt(np.sum(phi * phi, axis=0))
    norm[norm == 0.0] = 1.0
    a = phi / norm
    vals, vecs = np.linalg.eigh(a.T @ a)
    inv = np.where(vals > 1e-13 * vals[-1], 1.0 / np.where(vals > 0, vals, 1.0), 0.0)
    return norm, a, vecs, inv


def _gram_solve(gram: _Gram, rhs: FloatArray) -> FloatArray:
    """The least-squares coefficients of ``rhs`` on the basis whose :func:`_gram` this is."""
    norm, a, vecs, inv = gram
    coef: FloatArray = (vecs @ (inv[:, None] * (vecs.T @ (a.T @ rhs)))) / norm[:, None]
    return coef


class PoleModel:
    """Offset + drift + damped sinusoids, linear coefficients solved for given poles."""

    def __init__(self, rec: Record) -> None:
        self.t = rec.t
        self.y = rec.y
        self.k: int = rec.y.shape[1]
        self.base = np.column_stack([np.ones_like(rec.t), rec.t / rec.t[-1]])
        self._cache: tuple[bytes, tuple[FloatArray, FloatArray, FloatArray], _Parts] | None = None

    def basis(self, s: FloatArray, w: FloatArray) -> FloatArray:
        return self._basis(s, w)[0]

    def _basis(self, s: FloatArray, w: FloatArray) -> tuple[FloatArray, tuple[FloatArray, FloatArray, FloatArray]]:
        """:meth:`basis`, and its envelopes exp(-s t) and the cos(w t) and sin(w t), (N, M) each."""
        e = np.exp(-np.outer(self.t, s))
        ph = np.outer(self.t, w)
        c, sn = np.cos(ph), np.sin(ph)
        return np.hstack([self.base, e * c, e * sn]), (e, c, sn)

    def _solved(self, theta: FloatArray) -> tuple[tuple[FloatArray, FloatArray, FloatArray], _Parts]:
        """:meth:`solve`'s result and the basis' Gram decomposition, for the last poles asked (the
        least-squares solver asks for the residual, then the Jacobian, at the same poles)."""
        key = theta.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        phi, trig = self._basis(theta[0::2], theta[1::2])
        gram = _gram(phi)
        coef = _gram_solve(gram, self.y)
        resid = self.y - phi @ coef
        out = (phi, coef, resid)
        self._cache = (key, out, (gram, trig))
        return out, (gram, trig)

    def solve(self, theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Basis Phi (N, 2 + 2M), coefficients (2 + 2M, k) and residual (N, k) for the poles.

        Least squares through the Gram matrix of the unit-normalised columns (small, and well
        conditioned for distinct poles), pseudo-inverted by eigen-decomposition; tall QR or
        SVD would cost far more for these few columns.
        """
        return self._solved(theta)[0]

    def residual(self, theta: FloatArray) -> FloatArray:
        return self.solve(theta)[2].ravel()

    def rss(self, theta: FloatArray) -> float:
        r = self.solve(theta)[2]
        return float(np.sum(r * r))

    def jacobian(self, theta: FloatArray) -> FloatArray:
        """Kaufman's variable-projection Jacobian -P_perp dPhi/dtheta c, (N k, 2M)."""
        (phi, coef, _), (gram, (env, cos, sin)) = self._solved(theta)
        m = theta.size // 2
        t = self.t[:, None]
        ds = []
        for i in range(m):
            # the basis' own exp(-s_i t), cos(w_i t), sin(w_i t): the same numbers as computing them again
            e, c, sn = env[:, i : i + 1], cos[:, i : i + 1], sin[:, i : i + 1]
            a, b = coef[2 + i], coef[2 + m + i]
            ds.append(-t * e * (c * a + sn * b))  # d model / d s_i, (N, k)
            ds.append(t * e * (c * b - sn * a))  # d model / d w_i
        d = np.hstack(ds)
        proj = d - phi @ _gram_solve(gram, d)  # the decomposition of solve's, reused: the same numbers
        return -proj.reshape(self.t.size, 2 * m, self.k).transpose(0, 2, 1).reshape(-1, 2 * m)

    def rss_null(self) -> float:
        coef, *_ = np.linalg.lstsq(self.base, self.y, rcond=None)
        r = self.y - self.base @ coef
        return float(np.sum(r * r))

    def dof(self, m: int) -> int:
        return self.y.size - (2 * m + self.k * (2 + 2 * m))


def _fit_poles(model: PoleModel, theta0: FloatArray, rec: Record) -> FloatArray:
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


def _penalty(model: PoleModel) -> float:
    """BIC penalty of one more mode (2 poles + 2k coefficients), in units of sigma^2."""
    return (2 + 2 * model.k) * math.log(model.y.size)


def _sigma2(model: PoleModel, rss: float, m: int) -> float:
    floor = 1e-20 * float(np.mean(model.y**2))
    return max(rss / max(model.dof(m), 1), floor)


def _start_for(model: PoleModel, theta: FloatArray, f_peak: float, rec: Record) -> FloatArray:
    """Initial (s, w) of a new mode near a spectral peak, the other modes fixed: the best
    damping of a coarse grid at the peak frequency, then the best of a few frequencies around
    the peak at that damping (the peak of a heavily damped mode is broad and shifted)."""
    wmax = MAX_NYQUIST_FRACTION * math.pi / rec.dt
    w0 = min(2 * math.pi * f_peak, 0.99 * wmax)

    def cand(zeta: float, w: float) -> FloatArray:
        return np.append(theta, [zeta * w / math.sqrt(1 - zeta**2), w])

    zeta = min((0.003, 0.01, 0.03, 0.1, 0.3), key=lambda z: model.rss(cand(z, w0)))
    ws = [w0] + [w0 * f for f in (0.85, 0.93, 1.07, 1.15) if w0 * f < wmax]
    w = min(ws, key=lambda w: model.rss(cand(zeta, w)))
    return cand(zeta, w)


def _near(f: float, theta: FloatArray, df: float) -> bool:
    w = theta[1::2] / (2 * math.pi)
    return bool(np.any(np.abs(w - f) < df))


def _budget(rec: Record, theta: FloatArray, max_modes: int) -> bool:
    """True while more modes may be added: fewer than max_modes in the band and, with a band,
    at most NUISANCE_MODES more outside it."""
    m = theta.size // 2
    inside = int(rec.in_band(theta).sum()) if m else 0
    return inside < max_modes and m < max_modes + (NUISANCE_MODES if rec.limited else 0)


def _next_peak(model: PoleModel, rec: Record, theta: FloatArray, fmin: float
               ) -> tuple[FloatArray, FloatArray, FloatArray, float | None]:
    """The residual of the modes so far, its spectrum, and its strongest new peak (Hz) or None."""
    resid = model.solve(theta)[2] if theta.size else rec.y
    freqs, power = spectrum(resid, rec.dt)
    peaks = [f for f in spectral_peaks(freqs, power, rec.search, fmin) if not _near(f, theta, 0.5 * fmin)]
    return resid, freqs, power, (peaks[0] if peaks else None)


def _method_fit(rec: Record, max_modes: int) -> tuple[FloatArray, FloatArray | None]:
    model = PoleModel(rec)
    theta: FloatArray = np.zeros(0)
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


def _method_matrix_pencil(rec: Record, max_modes: int) -> tuple[FloatArray, FloatArray | None]:
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
    model = PoleModel(rec)
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


def _prune(model: PoleModel, theta: FloatArray) -> FloatArray:
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


def _analytic_band(y: FloatArray, dt: float, f0: float, half_width: float) -> npt.NDArray[np.complex128]:
    """Analytic signal of each axis band-passed to f0 +- half_width (Hz), raised-cosine edges."""
    n = y.shape[0]
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.fft(y, n=nfft, axis=0)
    f = np.fft.fftfreq(nfft, dt)
    x = np.clip((np.abs(f - f0) - half_width) / half_width + 1.0, 0.0, 1.0)
    gain = np.where(f > 0, 2.0 * np.cos(0.5 * np.pi * x) ** 2, 0.0)
    return np.fft.ifft(spec * gain[:, None], axis=0)[:n]


def _weighted_line(t: FloatArray, v: FloatArray, wts: FloatArray, corr: float) -> tuple[float, float]:
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


def _spectral_mode(rec: Record, y: FloatArray, f_peak: float, freqs: FloatArray, power: FloatArray
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


def _method_spectral(rec: Record, max_modes: int) -> tuple[FloatArray, FloatArray | None]:
    model = PoleModel(rec)
    theta: FloatArray = np.zeros(0)
    cov_blocks: list[FloatArray] = []
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


ESTIMATORS: dict[str, Callable[[Record, int], tuple[FloatArray, FloatArray | None]]] = {
    "fit": _method_fit,
    "spectral": _method_spectral,
    "matrix_pencil": _method_matrix_pencil,
}


def covariance(model: PoleModel, theta: FloatArray) -> FloatArray:
    """sigma^2 (J^T J)^-1 of the poles (the linear coefficients profiled out)."""
    jac = model.jacobian(theta)
    m = theta.size // 2
    s2 = _sigma2(model, model.rss(theta), m)
    return s2 * np.linalg.pinv(jac.T @ jac)



def hac_covariance(model: PoleModel, theta: FloatArray) -> FloatArray:
    """Covariance of the poles robust to a residual that is not white (Newey & West 1987).

    The sandwich (J^T J)^-1 S (J^T J)^-1 with S = sum over lags |l| <= L of the Bartlett weight
    (1 - |l| / (L + 1)) times sum_t g_t g_{t-l}^T, g_t the score of sample t (summed over axes).
    For white residuals it is sigma^2 (J^T J)^-1 (:func:`covariance`); a residual that holds
    unmodelled content (a mode left out, the sensor's own dynamics) is correlated over many
    samples, and the sandwich widens the uncertainty by as much. The bandwidth L is where the
    residual's autocorrelation (over axes) first falls below 1/e, times 4, at most N/4.
    """
    m = theta.size // 2
    jac = model.jacobian(theta).reshape(model.t.size, model.k, 2 * m)
    resid = model.solve(theta)[2]
    n = model.t.size
    r = resid - resid.mean(axis=0)
    acf = np.array([np.sum(r[lag:] * r[:n - lag]) for lag in range(min(n // 4, 200) + 1)])
    below = np.nonzero(acf < acf[0] / math.e)[0]
    lags = int(min(n // 4, 4 * (below[0] if below.size else n // 16)))
    g = np.einsum("tkp,tk->tp", jac, resid)
    s = g.T @ g
    for lag in range(1, lags + 1):
        c = g[lag:].T @ g[:-lag]
        s += (1.0 - lag / (lags + 1.0)) * (c + c.T)
    bread = np.linalg.pinv(jac.reshape(-1, 2 * m).T @ jac.reshape(-1, 2 * m))
    cov: FloatArray = bread @ s @ bread
    return cov
