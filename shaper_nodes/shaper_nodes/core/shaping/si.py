"""Specified-insensitivity shapers (:func:`si`): the shortest sequence with V <= V_tol over a band.

Singer & Seering 1992 (cited in seeds 002 and 004): the shortest positive sequence keeping the
percentage vibration V <= V_tol over the band ``omega (1 -+ I/2)`` of every mode, found by linear
programming on a time grid and refined by SQP. Several modes are designed jointly over the
union of their bands. Units: omega in rad/s, times in s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from .types import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_VIBRATION_TOLERANCE,
    FloatArray,
    Impulses,
    Mode,
    ShaperError,
    _check_insensitivity,
    _check_tolerance,
)
from .vibration import percentage_vibration

#: directions of the polygon that stands for |R| <= V_tol in the linear programme
_SI_DIRECTIONS = 8
#: the SQP refinement keeps V below V_tol (1 - margin), so V <= V_tol holds between samples too;
#: a round that ends above V_tol (SQP stopped early) is followed by one with a larger margin
_SI_MARGINS = (1e-4, 1e-3, 3e-3, 1e-2, 3e-2)
#: time-grid points per period of the highest band frequency in the linear programme
_SI_POINTS_PER_PERIOD = 24
#: most time-grid points in one linear programme
_SI_MAX_POINTS = 1500
#: longest SI design searched, in periods of the lowest design frequency
_SI_MAX_PERIODS = 40.0
#: widest spread of the design modes (highest / lowest frequency) SI designs jointly: the grid follows
#: the highest, the duration the lowest, so the work grows with the square of the spread
MAX_SI_SPREAD = 16.0
#: most entries of one linear programme's constraint matrix (about 16 MB): beyond, refused
_SI_MAX_ENTRIES = 2_000_000
#: weight of sum(A^2) added to t_n in the SQP objective: breaks ties between equally short sequences
_SI_TIE_BREAK = 1e-6

Band = tuple[float, float, float]  # (omega_lo, omega_hi, zeta), omega = 1 for the lowest mode


def _vsq(x: FloatArray, k: int, w: FloatArray, zeta: float) -> tuple[FloatArray, FloatArray]:
    """|R|^2 at frequencies ``w`` and its gradient in x = (A_1..A_k, t_2..t_k); t_1 = 0.

    The decay reference is the latest time (t_n of the V formula), whichever impulse it is.
    """
    amps = x[:k]
    t = np.concatenate([[0.0], x[k:]])
    last = int(np.argmax(t))
    wd = w * math.sqrt(1.0 - zeta * zeta)
    e = np.exp(zeta * w[:, None] * (t - t[last]) + 1j * wd[:, None] * t)
    r = e @ amps
    r2 = (r * np.conj(r)).real
    rc = np.conj(r)[:, None]
    d_amp = 2.0 * (rc * e).real
    d_t = 2.0 * (rc * e * amps * (zeta * w[:, None] + 1j * wd[:, None])).real
    d_t[:, last] -= 2.0 * zeta * w * r2  # the latest time also moves the decay reference
    return r2, np.hstack([d_amp, d_t[:, 1:]])


def _si_worst(amps: FloatArray, times: FloatArray, bands: Sequence[Band]) -> tuple[float, list[tuple[float, float]]]:
    """Largest V over the bands (local maxima refined) and where V has its local maxima."""
    from scipy.optimize import minimize_scalar  # on first use (a node's start need not pay for scipy.optimize)

    worst, peaks = 0.0, []
    span = max(float(times[-1]), 1e-9)
    for lo, hi, z in bands:
        n = int(min(20000, max(200, math.ceil((hi - lo) * span / 0.05))))
        w = np.linspace(lo, hi, n)
        v = percentage_vibration(amps, times, w, z)
        idx = [0, n - 1, *(np.flatnonzero((v[1:-1] >= v[:-2]) & (v[1:-1] >= v[2:])) + 1)]
        for i in idx:
            wi, vi = float(w[i]), float(v[i])
            if 0 < i < n - 1:
                res = minimize_scalar(lambda x, z=z: -float(percentage_vibration(amps, times, x, z)),
                                      bounds=(w[i - 1], w[i + 1]), method="bounded", options={"xatol": 1e-12 * hi})
                if -res.fun > vi:
                    wi, vi = float(res.x), float(-res.fun)
            peaks.append((wi, z, vi))
            worst = max(worst, vi)
    return worst, [(w, z) for w, z, vi in peaks]


def _si_clean(amps: FloatArray, times: FloatArray, merge: float) -> Impulses:
    """Drop impulses below 1e-7, merge those closer than ``merge`` (at their centroid), t_1 = 0."""
    keep_a: list[float] = []
    keep_t: list[float] = []
    for a, t in zip(np.clip(amps, 0.0, None), times, strict=True):
        if a <= 1e-7:
            continue
        if keep_t and t - keep_t[-1] <= merge:
            s = keep_a[-1] + a
            keep_t[-1] = (keep_a[-1] * keep_t[-1] + a * t) / s
            keep_a[-1] = s
        else:
            keep_a.append(float(a))
            keep_t.append(float(t))
    a_out, t_out = np.array(keep_a), np.array(keep_t)
    return a_out / a_out.sum(), t_out - t_out[0]


def _si_lp(duration: float, bands: Sequence[Band], v: float, dt: float) -> Impulses | None:
    """Amplitudes >= 0 on a time grid over [0, duration] with V <= V_tol at sampled frequencies.

    |R| <= V_tol is replaced by the inscribed regular polygon: Re(R e^{-j theta_p}) <=
    V_tol cos(pi/P) for P directions theta_p (sufficient for |R| <= V_tol). The objective
    maximises the last amplitude, so the sequence really lasts ``duration``.
    """
    nt = int(min(_SI_MAX_POINTS, max(24, math.ceil(duration / dt)))) + 1
    t = np.linspace(0.0, duration, nt)
    dirs = np.exp(-2j * math.pi * np.arange(_SI_DIRECTIONS) / _SI_DIRECTIONS)
    samples = [max(8, int(math.ceil((hi - lo) * duration / 0.25)) + 2) for lo, hi, _ in bands]
    if sum(samples) * _SI_DIRECTIONS * nt > _SI_MAX_ENTRIES:  # bounded work: refused before the matrix is made
        raise ShaperError(f"the SI design would need a linear programme of {sum(samples) * _SI_DIRECTIONS * nt:.3g}"
                          f" entries (limit {_SI_MAX_ENTRIES:.3g}): loosen vibration_tolerance or insensitivity,"
                          " or design the modes one by one")
    rows = []
    for (lo, hi, z), m in zip(bands, samples, strict=True):
        w = np.linspace(lo, hi, m)[:, None]
        e = np.exp(z * w * (t - duration) + 1j * w * math.sqrt(1.0 - z * z) * t)
        rows.append((dirs[:, None, None] * e[None]).real.reshape(-1, nt))
    a_ub = np.vstack(rows)
    cost = np.zeros(nt)
    cost[-1] = -1.0
    bound = v * math.cos(math.pi / _SI_DIRECTIONS) * (1.0 - 1e-6)  # vertices strictly inside
    from scipy.optimize import linprog  # on first use

    res = linprog(cost, A_ub=a_ub, b_ub=np.full(a_ub.shape[0], bound),
                  A_eq=np.ones((1, nt)), b_eq=[1.0], bounds=(0.0, None), method="highs")
    if res.status != 0:
        return None
    return res.x, t


def _si_sqp(amps: FloatArray, times: FloatArray, samples: Sequence[tuple[float, float]],
            target: float) -> FloatArray:
    """One SQP round (SLSQP, analytic gradients) from the sequence given: minimise t_n subject to
    V^2 <= target^2 at the sampled (omega, zeta), positive amplitudes summing to 1 and
    non-decreasing times. Returns x = (A_1..A_k, t_2..t_k)."""
    k = amps.size
    w_all = np.array([s[0] for s in samples])
    z_all = np.array([s[1] for s in samples])
    groups = [(float(z), w_all[z_all == z]) for z in np.unique(z_all)]
    order = np.zeros((k - 1, 2 * k - 1))
    for i in range(k - 1):
        order[i, k + i] = 1.0
        if i:
            order[i, k + i - 1] = -1.0

    def cons(x: FloatArray) -> FloatArray:
        return np.concatenate([target * target - _vsq(x, k, w, z)[0] for z, w in groups])

    def cons_jac(x: FloatArray) -> FloatArray:
        return -np.vstack([_vsq(x, k, w, z)[1] for z, w in groups])

    def obj(x: FloatArray) -> float:
        return float(x[-1] + _SI_TIE_BREAK * np.sum(x[:k] ** 2))

    def obj_jac(x: FloatArray) -> FloatArray:
        return np.concatenate([2.0 * _SI_TIE_BREAK * x[:k], np.zeros(k - 2), [1.0]])

    from scipy.optimize import minimize  # on first use

    res = minimize(
        obj, np.concatenate([amps, times[1:]]), jac=obj_jac, method="SLSQP",
        bounds=[(0.0, 1.0)] * k + [(0.0, None)] * (k - 1),
        constraints=[
            {"type": "ineq", "fun": cons, "jac": cons_jac},
            {"type": "ineq", "fun": lambda x: order @ x, "jac": lambda x: order},
            {"type": "eq", "fun": lambda x: np.sum(x[:k]) - 1.0,
             "jac": lambda x: np.concatenate([np.ones(k), np.zeros(k - 1)])},
        ],
        options={"maxiter": 100, "ftol": 1e-12},
    )
    return np.asarray(res.x, dtype=float)


def _si_polish(amps: FloatArray, times: FloatArray, bands: Sequence[Band], v: float) -> Impulses | None:
    """Shorten the sequence by SQP on amplitudes and times: min t_n, V^2 <= (V_tol (1-margin))^2.

    The constraint is imposed at sampled frequencies plus the local maxima of V, which are
    added round by round (an exchange method) until V <= V_tol on the whole band.
    """
    samples: list[tuple[float, float]] = []
    for lo, hi, z in bands:
        n = max(6, int(math.ceil((hi - lo) * times[-1])))
        samples += [(float(w), z) for w in np.linspace(lo, hi, n)]
    samples += _si_worst(amps, times, bands)[1]
    for margin in _SI_MARGINS:
        k = amps.size
        if k < 2:
            return None
        x = _si_sqp(amps, times, samples, v * (1.0 - margin))
        if not np.all(np.isfinite(x)):
            return None
        t_new = np.concatenate([[0.0], x[k:]])
        if np.any(np.diff(t_new) < -1e-12):
            return None
        amps, times = _si_clean(x[:k], np.maximum.accumulate(t_new), 1e-7 * max(t_new[-1], 1e-9))
        worst, peaks = _si_worst(amps, times, bands)
        if worst <= v:
            return amps, times
        samples += peaks
    return None


@lru_cache(maxsize=256)
def _si_normalised(modes: tuple[tuple[float, float], ...], v: float,
                   insensitivity: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """SI for modes ((omega, zeta), ...) with the lowest omega = 1; (amplitudes, times)."""
    bands = [(w * (1.0 - insensitivity / 2.0), w * (1.0 + insensitivity / 2.0), z) for w, z in modes]
    top = max(hi for _, hi, _ in bands)
    dt = 2.0 * math.pi / top / _SI_POINTS_PER_PERIOD
    longest = _SI_MAX_PERIODS * 2.0 * math.pi
    # bracket the shortest feasible duration, then bisect to 1 %
    lo, hi = 0.0, math.pi / 2.0
    best = _si_lp(hi, bands, v, dt)
    while best is None:
        lo, hi = hi, hi * 1.5
        if hi > longest:
            raise ShaperError(
                f"no SI shaper up to {_SI_MAX_PERIODS:g} periods keeps V <= {v:g} over the band"
                f" (insensitivity {insensitivity:g}); loosen vibration_tolerance or insensitivity")
        best = _si_lp(hi, bands, v, dt)
    while hi - lo > 0.02 * hi:
        mid = 0.5 * (lo + hi)
        found = _si_lp(mid, bands, v, dt)
        if found is None:
            lo = mid
        else:
            hi, best = mid, found
    grid_amps, grid_t = best
    step = float(grid_t[1] - grid_t[0])
    start = _si_clean(grid_amps, grid_t, 1.5 * step)  # neighbouring grid impulses -> one impulse
    polished = _si_polish(*start, bands, v)
    if polished is None:  # fall back to the grid solution itself if it holds on the whole band
        raw = _si_clean(grid_amps, grid_t, 0.0)
        if _si_worst(*raw, bands)[0] > v:
            raise ShaperError(f"SI optimisation failed for V_tol={v:g}, insensitivity={insensitivity:g}")
        polished = raw
    amps, times = polished
    return tuple(amps.tolist()), tuple(times.tolist())


def si(
    modes: Sequence[Mode],
    vibration_tolerance: float = DEFAULT_VIBRATION_TOLERANCE,
    insensitivity: float = DEFAULT_INSENSITIVITY,
) -> Impulses:
    """Specified-insensitivity shaper: the shortest sequence with V <= V_tol over each mode's band.

    Problem (Singer & Seering 1992, "frequency sampling"; seeds 002 and 004 cite it): find
    positive amplitudes summing to 1 and times, with the last time as small as possible, such
    that V(omega, zeta_m) <= V_tol for every omega in ``[omega_m (1 - I/2), omega_m (1 + I/2)]``
    and every mode m (each band at its own damping ratio). Several modes are one joint problem
    over the union of the bands, usually shorter than the convolution of single-mode designs.

    Method (all in units where the lowest mode has omega = 1, cached):

    1. For a fixed duration D, a linear programme in the amplitudes on a time grid of 24
       points per period of the highest band frequency: |R| <= V_tol at frequencies sampled
       0.1 / D apart is replaced by the 8 linear inequalities of an inscribed octagon.
    2. Bracketing and bisection on D (to 1 %) give the shortest feasible grid design.
    3. Neighbouring grid impulses are merged, and SQP (SLSQP, analytic gradients) shortens the
       sequence with the exact V: minimise t_n subject to V^2 <= (V_tol (1 - 1e-4))^2 at sampled
       frequencies plus V's local maxima, exchanged round by round (with a larger margin if a
       round stops above V_tol) until V <= V_tol holds on the whole band (checked on a dense
       grid with the maxima refined). Impulses below 1e-7 are dropped. If SQP fails, the grid
       solution itself is used when it meets the specification.

    The result is exact for the damping ratios given. Typical time: 20-200 ms for one mode,
    0.1-0.4 s for two; a wide spread of modes (1:12) takes a few seconds (the grid follows the
    highest frequency, the duration the lowest).

    Raises
    ------
    ShaperError
        Invalid parameters, modes more than :data:`MAX_SI_SPREAD` times apart, a linear programme
        too large (bounded work), or no sequence of at most 40 periods meets the specification.
    """
    v = _check_tolerance(vibration_tolerance)
    ins = _check_insensitivity(insensitivity)
    modes = tuple(modes)
    if not modes:
        raise ShaperError("shaper family 'si' needs at least one mode")
    w_ref = min(m.omega for m in modes)
    spread = max(m.omega for m in modes) / w_ref
    if not spread <= MAX_SI_SPREAD:  # before any work (an overflowing ratio is inf: refused too)
        raise ShaperError(f"si designs modes at most {MAX_SI_SPREAD:g} times apart jointly; these are {spread:.3g}"
                          " times apart: design them one by one (another family convolves per mode)")
    key = tuple(sorted({(m.omega / w_ref, m.zeta) for m in modes}))
    amps, times = _si_normalised(key, v, ins)
    return np.array(amps), np.array(times) / w_ref

