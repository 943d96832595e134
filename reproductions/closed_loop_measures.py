"""What the closed-loop reproductions measure on a run's loop signals (:class:`Traces`), free of ROS: seed 001's
growth and settling, seed 002's residual, its oscillatory and non-oscillatory parts (the matrix pencil,
:func:`modal_split`), the shaper's own floor on the nominal plant and the effects of disturbances and noise.
:mod:`reproductions.closed_loop_cases` runs the nodes and writes the page from these."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DWELL_002 = 1.0  # s: seed 002's dwell after the step (the windows below end there)
EVENT_TIME = 0.5  # disturbance / noise step after the reference step, s


@dataclass
class Traces:
    """Loop signals of one run, per joint, from the step (t = 0 at the cycle's START)."""

    t: np.ndarray
    output: np.ndarray  # (samples, joints)
    measured: np.ndarray
    control: np.ndarray
    reference: np.ndarray


def growth(tr: Traces, j: int, final: float = 1.0) -> float:
    """Peak |y - final| over the last 5 s over that in 5-10 s (< 1 decays, > 1 grows)."""
    e = np.abs(tr.output[:, j] - final)
    early = e[(tr.t >= 5.0) & (tr.t < 10.0)].max()
    late = e[tr.t >= tr.t[-1] - 5.0].max()
    return float(late / max(early, 1e-300))


def settle_time(tr: Traces, j: int, tol: float = 1e-6, final: float = 1.0) -> float:
    """First time after which |y - final| stays within tol, s (inf if never)."""
    bad = np.nonzero(np.abs(tr.output[:, j] - final) > tol)[0]
    if bad.size == 0:
        return 0.0
    return float(tr.t[bad[-1] + 1]) if bad[-1] + 1 < tr.t.size else math.inf


def shaper_duration(family: str) -> float:
    from shaper_nodes.core.closed_loop import nominal
    from shaper_nodes.core.shaping import Mode, design

    p = nominal()
    return float(design(family, [Mode(p.omega_n, p.zeta)]).duration)


def residual(tr: Traces, family: str, until: float = DWELL_002) -> tuple[np.ndarray, np.ndarray]:
    """Per joint RMS and peak of x2 - 1 (m) from the end of the shaped step (the shaper's duration) to ``until``."""
    w = (tr.t >= shaper_duration(family) - 1e-9) & (tr.t <= until)
    e = tr.output[w] - 1.0
    return np.sqrt(np.mean(e**2, axis=0)), np.max(np.abs(e), axis=0)


#: relative singular-value threshold of the matrix pencil (the records are noise-free to ~1e-15)
PENCIL_RTOL = 1e-9
#: absolute one (m per Hankel entry): x2 is near 1 m, so its records carry rounding of some 1e-16 m per
#: sample, and poles fitted below this are rounding (they made the split of a near-zero record blow up)
PENCIL_ATOL = 1e-13


def modal_split(y: np.ndarray, dt: float, rtol: float = PENCIL_RTOL,
                atol: float = PENCIL_ATOL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a free response into its oscillatory and non-oscillatory parts by its poles.

    After the shaped step the reference is constant, so x2 - 1 of any of the linear schemes (open
    loop, or a loop discretised at the loop rate and recorded every command period) is exactly a sum
    of sampled exponentials sum_i a_i z_i^k. The matrix pencil (Hua and Sarkar 1990: Hankel SVD
    truncated where the singular values fall below ``rtol`` times the largest or below the records'
    rounding ``atol`` (per entry), poles as the
    eigenvalues of the shifted right singular vectors, amplitudes by least squares) recovers the
    z_i and a_i; a pole that completes at least one damped cycle within the record (|arg z_i| >=
    2 pi / samples) is oscillatory (vibration), the others (real poles: the loop's settling) are
    not. Returns (oscillatory part, non-oscillatory part, poles in 1/s).
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n < 12 or not np.all(np.isfinite(y)):
        raise ValueError(f"modal_split needs at least 12 finite samples, got {n}")
    if not np.any(y):
        return np.zeros(n), np.zeros(n), np.zeros(0, complex)
    width = n // 3
    hankel = np.lib.stride_tricks.sliding_window_view(y, width + 1)
    _, sv, vh = np.linalg.svd(hankel, full_matrices=False)
    order = max(1, int(np.sum(sv > max(rtol * sv[0], atol * math.sqrt(hankel.size)))))
    v = vh[:order].T
    z = np.linalg.eigvals(np.linalg.pinv(v[:-1]) @ v[1:]).astype(complex)
    basis = np.vander(z, n, increasing=True).T
    amp, *_ = np.linalg.lstsq(basis, y.astype(complex), rcond=None)
    osc = np.abs(np.angle(z)) >= 2.0 * np.pi / n
    return ((basis[:, osc] @ amp[osc]).real, (basis[:, ~osc] @ amp[~osc]).real,
            np.log(z) / dt)


def dominant_oscillation(y: np.ndarray, dt: float) -> tuple[float, float]:
    """Natural frequency (rad/s) and damping ratio of the oscillatory pole pair of :func:`modal_split`
    that contributes most (RMS) to ``y``; (nan, nan) if there is none."""
    y = np.asarray(y, dtype=float)
    _, _, poles = modal_split(y, dt)
    best, best_rms = (math.nan, math.nan), 0.0
    n = y.size
    basis = np.exp(np.outer(np.arange(n) * dt, poles))
    amp, *_ = np.linalg.lstsq(basis, y.astype(complex), rcond=None)
    for i, p in enumerate(poles):
        if p.imag * dt < 2.0 * np.pi / n:  # one of each pair (positive frequency), oscillatory only
            continue
        rms = float(np.sqrt(np.mean((2.0 * (basis[:, i] * amp[i]).real) ** 2)))
        if rms > best_rms:
            best, best_rms = (float(abs(p)), float(-p.real / abs(p))), rms
    return best


def settled_window(tr: Traces, until: float = DWELL_002) -> np.ndarray:
    """Sample indices from the first at which the reference holds its final value, to ``until``."""
    r = tr.reference[:, 0]
    moving = np.nonzero(np.abs(r - r[-1]) > 1e-12 * max(1.0, abs(r[-1])))[0]
    first = int(moving[-1]) + 1 if moving.size else 0
    return np.arange(first, tr.t.size)[tr.t[first:] <= until + 1e-9]


def vibration(tr: Traces, until: float = DWELL_002) -> tuple[np.ndarray, np.ndarray]:
    """Per joint RMS (m) of the oscillatory and of the non-oscillatory part of x2 - 1 after the shaped
    step (:func:`settled_window`, :func:`modal_split`): residual vibration and the loop's settling."""
    w = settled_window(tr, until)
    dt = float(np.median(np.diff(tr.t)))
    osc, slow = [], []
    for j in range(tr.output.shape[1]):
        o, s, _ = modal_split(tr.output[w, j] - tr.reference[-1, j], dt)
        osc.append(np.sqrt(np.mean(o**2)))
        slow.append(np.sqrt(np.mean(s**2)))
    return np.array(osc), np.array(slow)


def shaper_floor(tr: Traces, until: float = DWELL_002) -> float:
    """RMS (m) of x2 - 1 that the nominal plant P0 itself keeps after the reference the shaper node sent
    in this run (the shaper's impulses as the shaper node discretised them), over the window of
    :func:`vibration`: exact step responses of P0 summed, independent of the sim plant. With the
    continuous shaper, or the ``exact`` discretisation, it is zero to rounding; with ``split`` it is the
    floor of every scheme on a plant equal to P0."""
    import control
    from scipy.linalg import expm

    from shaper_nodes.core.closed_loop import nominal, plant_tf

    sys_ = control.ss(plant_tf(nominal()))
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys_.A, sys_.B, sys_.C, sys_.D))
    r = tr.reference[:, 0]
    jumps = np.nonzero(np.diff(np.concatenate([[0.0], r])))[0]
    w = settled_window(tr, until)
    dt = float(np.median(np.diff(tr.t)))
    step = expm(a * dt)
    ainv_b = np.linalg.solve(a, b[:, 0])
    y = np.zeros(w.size)
    for k in jumps:  # the command held from the sample before its stamp (as the plant integrates it)
        size = r[k] - (r[k - 1] if k else 0.0)
        x = expm(a * (tr.t[w[0]] - tr.t[k] + dt)) @ ainv_b
        for i in range(w.size):
            y[i] += size * (float(c[0] @ (x - ainv_b)) + d[0, 0])
            x = step @ x
    return float(np.sqrt(np.mean((y - r[-1]) ** 2)))


def noise_effect(noisy: Traces, clean: Traces) -> np.ndarray:
    """Per joint RMS of the true output's deviation caused by white noise (noisy run minus the same run
    without noise) over the last half of the dwell, m."""
    w = noisy.t >= EVENT_TIME
    diff = [noisy.output[w, j] - np.interp(noisy.t[w], clean.t, clean.output[:, j])
            for j in range(noisy.output.shape[1])]
    return np.sqrt(np.mean(np.square(diff), axis=1))


def event_effect(tr: Traces, signal: str = "output") -> np.ndarray:
    """Per joint RMS of (signal - 1) over the 0.5 s after the disturbance / noise step."""
    w = (tr.t >= EVENT_TIME) & (tr.t <= EVENT_TIME + 0.5)
    return np.sqrt(np.mean((getattr(tr, signal)[w] - 1.0) ** 2, axis=0))
