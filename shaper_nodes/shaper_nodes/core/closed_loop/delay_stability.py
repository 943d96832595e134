"""The stability of the time-delay feedback loop of seed 001, free of ROS: the PPUSMD gains, the controller, the
characteristic quasi-polynomial and its imaginary-axis crossings, the stable interval of real plant frequencies
(eq. 27), the assumed frequencies to choose (eqs. 28-30), and the independent sampled-data check
(:func:`sampled_spectral_radius`). The equations, and the step response beside them: :mod:`.time_delay`, which
hands these names on."""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["AssumedRange", "Crossing", "StableInterval", "TimeDelayError", "assumed_frequency_range", "change_points",
           "characteristic", "controller_response", "g_ff", "growth_rate", "ppusmd_gains", "sampled_loop_matrix",
           "sampled_spectral_radius", "stable_interval", "upper_bound_curve"]


class TimeDelayError(ValueError):
    """Invalid time-delay design input; the message names the problem."""


def _check(omega_a: float, delay: float) -> None:
    if not (math.isfinite(omega_a) and omega_a > 0):
        raise TimeDelayError(f"assumed frequency w_A must be finite and > 0 rad/s, got {omega_a!r}")
    if not (math.isfinite(delay) and delay > 0):
        raise TimeDelayError(f"delay T must be finite and > 0 s, got {delay!r}")
    if 1.0 - math.cos(omega_a * delay) < 1e-9:
        raise TimeDelayError(f"w_A T = {omega_a * delay:.6g} is a multiple of 2 pi: the PPUSMD gains"
                             " (eqs. 9-11) are undefined there")


def ppusmd_gains(omega_a: float, delay: float) -> tuple[float, float, float]:
    """Gains (A0, A1, A2) of eqs. (9)-(11) for the assumed frequency w_A (rad/s) and delay T (s)."""
    _check(omega_a, delay)
    c = math.cos(omega_a * delay)
    a0 = 1.0 / (2.0 * (1.0 - c))
    return a0, -2.0 * c * a0, a0


def g_ff(s: npt.ArrayLike, omega_a: float, delay: float) -> np.ndarray:
    """G_FF(s) of eq. (8) at complex s (array), for w_A (rad/s) and T (s)."""
    a0, a1, a2 = ppusmd_gains(omega_a, delay)
    z = np.asarray(s, dtype=complex)
    g: np.ndarray = a0 + a1 * np.exp(-z * delay) + a2 * np.exp(-2.0 * z * delay)
    return g


def controller_response(s: npt.ArrayLike, omega_a: float, delay: float) -> np.ndarray:
    """G_C(s) = G_FF / (1 - G_FF G_PA) (eqs. 3, 12) at complex s."""
    z = np.asarray(s, dtype=complex)
    g = g_ff(z, omega_a, delay)
    gc: np.ndarray = g * (z**2 + omega_a**2) / ((z**2 + omega_a**2) - omega_a**2 * g)
    return gc


def characteristic(s: npt.ArrayLike, omega_a: float, delay: float, omega_r: float) -> np.ndarray:
    """The characteristic quasi-polynomial F(s) of eq. (18) at complex s."""
    z = np.asarray(s, dtype=complex)
    g = g_ff(z, omega_a, delay)
    f: np.ndarray = z**2 * (z**2 + omega_a**2 * (1.0 - g)) + omega_r**2 * (omega_a**2 + z**2 * (1.0 + g))
    return f


@dataclass(frozen=True)
class Crossing:
    """A point where a root crosses the imaginary axis: branch k (0: the w_R = w_A solution),
    crossing frequency phi (rad/s) and the real plant frequency w_R (rad/s) at which it happens."""

    k: int
    phi: float
    omega_r: float


def change_points(omega_a: float, delay: float, k_max: int = 50) -> list[Crossing]:
    """The possible changes of stability of eq. (15) for k = 1..k_max (those with w_R^2 > 0),
    plus the solution w_R = w_A of eq. (17) as k = 0; sorted by w_R."""
    _check(omega_a, delay)
    c = math.cos(omega_a * delay)
    out = [Crossing(0, omega_a, omega_a)]
    ratio = omega_a * delay / math.pi
    for k in range(1, int(k_max) + 1):
        if abs(k - ratio) < 1e-9:
            continue  # numerator and denominator vanish: the w_R = w_A solution (see the paper)
        p2 = (k * math.pi / delay) ** 2
        sign = (-1.0) ** k
        num = p2 * (c - 1.0) + omega_a**2 * c * (sign - 1.0)
        den = p2 * (c + sign * c - 2.0) + omega_a**2 * (1.0 - c)
        if den == 0.0:
            continue
        w2 = p2 * num / den
        if w2 > 0.0:
            out.append(Crossing(k, k * math.pi / delay, math.sqrt(w2)))
    return sorted(out, key=lambda x: x.omega_r)


@dataclass(frozen=True)
class StableInterval:
    """The interval of real plant frequencies w_R (rad/s) with a stable loop, eq. (27); ``upper_k``
    is the branch k of eq. (15) that bounds it."""

    omega_a: float
    delay: float
    lower: float
    upper: float
    upper_k: int


def stable_interval(omega_a: float, delay: float) -> StableInterval:
    """w_A <= w_R <= min(w_R(k) > w_A) (eq. 27) for the assumed frequency w_A and delay T.

    For large k, w_R(k) tends to k pi / (T sqrt 2) (even k) and k pi |sin(w_A T / 2)| / T (odd k), so
    the search over k stops once half the smaller of these exceeds the best bound found.
    """
    _check(omega_a, delay)
    best: Crossing | None = None
    slope = 0.5 * min(1.0 / math.sqrt(2.0), abs(math.sin(0.5 * omega_a * delay))) * math.pi / delay
    k_max = 8
    while True:
        cands = [x for x in change_points(omega_a, delay, k_max) if x.k > 0 and x.omega_r > omega_a * (1 + 1e-12)]
        if cands:
            best = min(cands, key=lambda x: x.omega_r)
        if best is not None and k_max * slope > best.omega_r and k_max * math.pi / delay > 4 * omega_a:
            break
        if k_max > 200000:
            raise TimeDelayError(f"no upper stability bound found up to k = {k_max} (w_A T = {omega_a * delay:.6g}"
                                 " is too close to a multiple of 2 pi)")
        k_max *= 2
    return StableInterval(omega_a, delay, omega_a, best.omega_r, best.k)


@dataclass(frozen=True)
class AssumedRange:
    """Range of w_A (rad/s) for a real plant w_R and delay T (eqs. 28-30), with the branch k."""

    k: int
    low: float
    high: float


def assumed_frequency_range(omega_r: float, delay: float) -> list[AssumedRange]:
    """Eqs. (28)-(30): for each integer k with w_R T / pi <= k <= w_R T / pi + 1, w_A may be
    chosen in [(k - 1) pi / T, k pi / T] and w_A <= w_R."""
    if not (math.isfinite(omega_r) and omega_r > 0):
        raise TimeDelayError(f"real frequency w_R must be finite and > 0 rad/s, got {omega_r!r}")
    if not (math.isfinite(delay) and delay > 0):
        raise TimeDelayError(f"delay T must be finite and > 0 s, got {delay!r}")
    x = omega_r * delay / math.pi
    out = []
    for k in range(max(1, math.ceil(x - 1e-12)), math.floor(x + 1 + 1e-12) + 1):
        low, high = (k - 1) * math.pi / delay, min(k * math.pi / delay, omega_r)
        if high > low:
            out.append(AssumedRange(k, low, high))
    return out


def upper_bound_curve(omega_a: np.ndarray, delay: float) -> np.ndarray:
    """Upper stability bound of w_R (eq. 27) for each w_A (rad/s) at a fixed T (seed 001 Fig. 6);
    NaN where the gains are undefined."""
    out = np.full(np.shape(omega_a), np.nan)
    for i, wa in enumerate(np.ravel(omega_a)):
        with contextlib.suppress(TimeDelayError):
            out.flat[i] = stable_interval(float(wa), delay).upper
    return out


# ------------------------------------------------------------------------------------------------
# independent check: the sampled-data loop


def _zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n = a.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n] = a, b
    from scipy.linalg import expm  # on first use: 0.2-0.5 s of CPU at a start (the sim plant imports this module)

    e = expm(m * dt)
    return e[:n, :n], e[:n, n]


def sampled_loop_matrix(omega_a: float, delay_samples: int, dt: float, omega_r: float,
                        damping_ratio: float = 0.0) -> np.ndarray:
    """Transition matrix of the sampled-data loop (reference 0): the real plant w_R (optional damping
    ratio, base-driven m-c-k with unit mass) and the internal model w_A, both discretised exactly under
    a zero-order hold of u; v_k = -y_k + yhat_k, u_k = A0 v_k + A1 v_{k-N} + A2 v_{k-2N}, N = delay_samples.

    This is what :class:`sim_plant_node.models.loops.DelayLoopPlant` computes; it uses none of eqs. (13)-(27).
    """
    n = int(delay_samples)
    if n < 1:
        raise TimeDelayError(f"delay must be at least one sample, got {delay_samples!r}")
    a0, a1, a2 = ppusmd_gains(omega_a, n * dt)
    c = 2.0 * damping_ratio * omega_r
    # plant: x = [y, y'] with base u constant over the sample: y'' = w^2 (u - y) - c y' (the c u' impulse
    # at a jump of u moves y' by c du: added below)
    ap, bp = _zoh(np.array([[0.0, 1.0], [-omega_r**2, -c]]), np.array([0.0, omega_r**2]), dt)
    am, bm = _zoh(np.array([[0.0, 1.0], [-omega_a**2, 0.0]]), np.array([0.0, omega_a**2]), dt)
    # state: plant (2), model (2), u_{k-1} (1), v_{k-1} .. v_{k-2N} (2N)
    size = 5 + 2 * n
    # u_k as a row over the state at step k: v_k = -y + yhat; delayed v from the line
    u_row = np.zeros(size)
    u_row[0], u_row[2] = -a0, a0
    u_row[5 + n - 1] += a1   # v_{k-N}
    u_row[5 + 2 * n - 1] += a2  # v_{k-2N}
    v_row = np.zeros(size)
    v_row[0], v_row[2] = -1.0, 1.0
    m = np.zeros((size, size))
    # plant with the damper impulse at the jump u_k - u_{k-1}
    jump = np.zeros((2, size))
    jump[1] = c * (u_row - np.eye(size)[4])
    p_state = np.zeros((2, size))
    p_state[0, 0], p_state[1, 1] = 1.0, 1.0
    m[0:2] = ap @ (p_state + jump) + np.outer(bp, u_row)
    m[2:4, 2:4] = am
    m[2:4] += np.outer(bm, u_row)
    m[4] = u_row
    m[5] = v_row
    for i in range(1, 2 * n):
        m[5 + i, 5 + i - 1] = 1.0
    return m


def sampled_spectral_radius(omega_a: float, delay: float, omega_r: float, samples_per_delay: int = 60,
                            damping_ratio: float = 0.0) -> float:
    """Spectral radius of the sampled-data loop with T split into ``samples_per_delay`` samples
    (< 1: stable, > 1: unstable), leaving out the internal model's own undamped poles
    e^{+-j w_A dt}: the filter's zeros at +-j w_A make them unobservable at u and y (they are the
    hidden modes of eq. 12's cancellation, see docs/design/closed_loop.md). Independent of the analysis of
    eqs. (13)-(27)."""
    n = int(samples_per_delay)
    dt = delay / n
    eig = np.linalg.eigvals(sampled_loop_matrix(omega_a, n, dt, omega_r, damping_ratio))
    hidden = np.exp(1j * omega_a * dt)
    for z in (hidden, hidden.conjugate()):
        i = int(np.argmin(np.abs(eig - z)))
        if abs(eig[i] - z) < 1e-6:
            eig = np.delete(eig, i)
    return float(np.max(np.abs(eig)))


def growth_rate(omega_a: float, delay: float, omega_r: float, samples_per_delay: int = 60) -> float:
    """Largest real part of the sampled loop's poles mapped back to s, 1/s (log of the spectral radius
    over the sample period, hidden model poles left out): > 0 grows, < 0 decays."""
    dt = delay / int(samples_per_delay)
    return math.log(sampled_spectral_radius(omega_a, delay, omega_r, samples_per_delay)) / dt
