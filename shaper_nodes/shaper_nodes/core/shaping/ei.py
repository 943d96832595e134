"""Extra-insensitive shapers with one, two or three humps (:func:`ei`, :func:`hump_ei`).

EI (Singhose, Seering & Singer 1990) and the multi-hump EI shapers (Singhose, Derezinski &
Singer, extra-insensitive shapers for flexible spacecraft): 3, 4 or 5 impulses whose percentage
vibration V equals the tolerance ``V_tol`` at each hump, with zero slope there, and is zero
between and around the humps. The undamped closed forms are the starting point; the
constraints are solved numerically for the damping given, continued from zeta = 0 (cached), so
every design is exact for the mode's damping ratio. Units: omega in rad/s, times in s.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .types import DEFAULT_VIBRATION_TOLERANCE, FloatArray, Impulses, Mode, ShaperError, _check_tolerance
from .vibration import percentage_vibration

#: the damped multi-hump EI constraints are continued from zeta = 0 in steps of this size
_HUMP_ZETA_STEP = 0.02


def _undamped_hump_ei(humps: int, v: float) -> tuple[FloatArray, list[float], list[float]]:
    """Undamped EI with 1, 2 or 3 humps: amplitudes, hump and zero frequencies / design frequency.

    Impulses half a period T apart, symmetric amplitudes; V is then a polynomial in a cosine,
    whose extrema and roots give the closed forms (see :func:`hump_ei`).
    """
    if humps == 1:
        # V = |A1 (1 + e^{2 j phi}) + A2 e^{j phi}| = |2 A1 cos phi + A2|, phi = omega T / 2
        theta = math.acos(-(1.0 - v) / (1.0 + v))
        amps = np.array([(1.0 + v) / 4.0, (1.0 - v) / 2.0, (1.0 + v) / 4.0])
        return amps, [1.0], [theta / math.pi, 2.0 - theta / math.pi]
    if humps == 2:
        # V = |h(c)|, h = 8 A1 c^3 + (1 - 8 A1) c, c = cos(omega T / 4); humps where h' = 0 with
        # |h| = V give 4 a^3 = 27 V^2 (a + 1), a = 8 A1 - 1 (one positive root).
        roots = np.roots([4.0, 0.0, -27.0 * v * v, -27.0 * v * v])
        a = max(r.real for r in roots if abs(r.imag) < 1e-9 and r.real > 0.0)
        a1 = (a + 1.0) / 8.0
        amps = np.array([a1, 0.5 - a1, 0.5 - a1, a1])
        ch, cz = math.sqrt(a / (24.0 * a1)), math.sqrt(a / (8.0 * a1))
        hump = [math.acos(ch) * 2.0 / math.pi, math.acos(-ch) * 2.0 / math.pi]
        zero = [math.acos(cz) * 2.0 / math.pi, 1.0, math.acos(-cz) * 2.0 / math.pi]
        return amps, hump, zero
    # humps == 3: V = |g(c)|, g = 4 A1 c^2 + 2 A2 c + A3 - 2 A1, c = cos(omega T / 2);
    # g(-1) = V (design hump), min g = -V (side humps), g(1) = 1 give the closed form.
    a2 = (1.0 - v) / 4.0
    a1 = (1.0 + 3.0 * v + 2.0 * math.sqrt(2.0 * v * (1.0 + v))) / 16.0
    a3 = 1.0 - 2.0 * a1 - 2.0 * a2
    amps = np.array([a1, a2, a3, a2, a1])
    cs = -a2 / (4.0 * a1)
    zc = np.sort(np.roots([4.0 * a1, 2.0 * a2, a3 - 2.0 * a1]).real)
    hump = [math.acos(cs) / math.pi, 1.0, 2.0 - math.acos(cs) / math.pi]
    zero = sorted([math.acos(c) / math.pi for c in zc] + [2.0 - math.acos(c) / math.pi for c in zc])
    return amps, hump, zero


def _hump_unpack(x: FloatArray, humps: int, zeta: float) -> tuple[FloatArray, FloatArray, list[float], list[float]]:
    """Unknowns -> (amplitudes, times for omega = 1, hump frequencies, zero frequencies).

    x = (A_1..A_{n-1}, t_2..t_n in damped periods, free hump frequencies, free zero frequencies);
    the design frequency 1 is a hump (odd ``humps``) or a zero (even).
    """
    n = humps + 2
    free_h = humps - 1 if humps % 2 else humps
    amps = np.append(x[: n - 1], 1.0 - np.sum(x[: n - 1]))
    times = np.concatenate([[0.0], x[n - 1 : 2 * n - 2]]) * 2.0 * math.pi / math.sqrt(1.0 - zeta * zeta)
    hump = list(x[2 * n - 2 : 2 * n - 2 + free_h])
    zero = list(x[2 * n - 2 + free_h :])
    (hump if humps % 2 else zero).append(1.0)
    return amps, times, sorted(hump), sorted(zero)


def _hump_equations(x: FloatArray, humps: int, v: float, zeta: float) -> FloatArray:
    """V - V_tol and d|R|^2/domega / (2 V_tol) at the humps; Re R and Im R at the zeros."""
    amps, times, hump, zero = _hump_unpack(x, humps, zeta)
    w = np.array(hump + zero)[:, None]
    sd = math.sqrt(1.0 - zeta * zeta)
    tau = times - times[-1]
    e = amps * np.exp(zeta * w * tau + 1j * w * sd * times)
    r = e.sum(axis=1)
    nh = len(hump)
    dr = (e[:nh] * w[:nh] * (zeta * tau + 1j * sd * times)).sum(axis=1)
    rh, rz = r[:nh], r[nh:]
    return np.concatenate([np.abs(rh) - v, (np.conj(rh) * dr).real / v, rz.real, rz.imag])


def _hump_rows(x: FloatArray, humps: int) -> tuple[list[int | None], list[int | None]]:
    """Which unknown each hump and each zero frequency is (index into ``x``; None: the design frequency 1), in
    the sorted order of :func:`_hump_unpack` (its rows of :func:`_hump_equations`)."""
    n = humps + 2
    free_h = humps - 1 if humps % 2 else humps
    hump: list[tuple[float, int | None]] = [(float(x[k]), k) for k in range(2 * n - 2, 2 * n - 2 + free_h)]
    zero: list[tuple[float, int | None]] = [(float(x[k]), k) for k in range(2 * n - 2 + free_h, x.size)]
    (hump if humps % 2 else zero).append((1.0, None))
    return ([k for _, k in sorted(hump, key=lambda p: p[0])], [k for _, k in sorted(zero, key=lambda p: p[0])])


def _hump_jacobian(x: FloatArray, humps: int, v: float, zeta: float) -> FloatArray:
    """The Jacobian of :func:`_hump_equations` with respect to ``x``, in closed form.

    With e_i = A_i exp(w g_i), g_i = zeta tau_i + j sd t_i (sd = sqrt(1 - zeta^2)), R = sum e_i and
    D = sum e_i w g_i: dR/dA_k = E_k - E_n and dD/dA_k = w (E_k g_k - E_n g_n) (E_i = exp(w g_i), the
    last amplitude is 1 - the others); for the time s_m of impulse m in damped periods (t = 2 pi / sd s,
    tau = t - t_n) dR/ds_m = w c sum_i e_i h_im and dD/ds_m = w c sum_i e_i h_im (w g_i + 1), with
    c = 2 pi / sd and h_im = zeta (delta_im - delta_in) + j sd delta_im; for a free frequency w of a row
    dR/dw = sum e_i g_i and dD/dw = sum e_i g_i (w g_i + 1). Then d|R| = Re(conj(R) dR) / |R|,
    d Re(conj(R) D) = Re(conj(dR) D + conj(R) dD). (The least-squares solve took most of its time in
    finite differences of the equations, one evaluation per unknown for each Jacobian.)
    """
    n = humps + 2
    amps, times, hump, zero = _hump_unpack(x, humps, zeta)
    rows_h, rows_z = _hump_rows(x, humps)
    w = np.array(hump + zero)[:, None]
    sd = math.sqrt(1.0 - zeta * zeta)
    c = 2.0 * math.pi / sd
    tau = times - times[-1]
    g = zeta * tau + 1j * sd * times                      # (n,)
    big_e = np.exp(w * g)                                 # (q, n)
    e = amps * big_e
    r = e.sum(axis=1)
    d = (e * w * g).sum(axis=1)
    q = w.shape[0]
    dr = np.zeros((q, x.size), dtype=complex)
    dd = np.zeros((q, x.size), dtype=complex)
    # amplitudes A_1..A_{n-1}
    dr[:, : n - 1] = big_e[:, : n - 1] - big_e[:, n - 1 : n]
    dd[:, : n - 1] = w * (big_e[:, : n - 1] * g[: n - 1] - big_e[:, n - 1 : n] * g[n - 1])
    # times s_2..s_n (impulse m = 1..n-1 from 0)
    h = np.zeros((n, n - 1), dtype=complex)
    h[np.arange(1, n), np.arange(n - 1)] = zeta + 1j * sd
    h[:, n - 2] -= zeta
    dr[:, n - 1 : 2 * n - 2] = w * c * (e @ h)
    dd[:, n - 1 : 2 * n - 2] = w * c * ((e * (w * g + 1.0)) @ h)
    # free frequencies: each in its own row
    for row, k in enumerate(rows_h + rows_z):
        if k is not None:
            dr[row, k] = (e[row] * g).sum()
            dd[row, k] = (e[row] * g * (w[row, 0] * g + 1.0)).sum()
    nh = len(hump)
    rh, dh = r[:nh, None], d[:nh, None]
    return np.concatenate([(np.conj(rh) * dr[:nh]).real / np.abs(rh),
                           (np.conj(dr[:nh]) * dh + np.conj(rh) * dd[:nh]).real / v,
                           dr[nh:].real, dr[nh:].imag])


def _hump_valid(x: FloatArray, residual: float, humps: int, v: float, zeta: float) -> bool:
    """Residual < 1e-9, positive amplitudes, increasing times, zeros and humps alternating,
    and V <= V_tol between the outer zeros."""
    amps, times, hump, zero = _hump_unpack(x, humps, zeta)
    freqs = sorted(hump + zero)
    alternating = len(set(freqs)) == len(freqs) and all((f in zero) == (i % 2 == 0) for i, f in enumerate(freqs))
    if not (residual < 1e-9 and np.all(amps > 0.0) and np.all(np.diff(times) > 0.0) and freqs[0] > 0.0
            and alternating):
        return False
    grid = np.linspace(zero[0], zero[-1], 2001)
    return float(np.max(percentage_vibration(amps, times, grid, zeta))) <= v * (1.0 + 1e-6)


def _hump_solve(humps: int, v: float, zeta: float, x0: FloatArray) -> FloatArray | None:
    """Solve the multi-hump EI constraints at ``zeta`` (omega = 1) from ``x0``; None if no valid
    solution is found.

    With damping the zero above the upper hump moves up quickly with zeta (V decays towards
    the last amplitude at high frequency), so when the solve from ``x0`` fails it is retried
    with that zero moved further out.
    """
    from scipy.optimize import least_squares  # on first use: scipy.optimize is 0.3 s of CPU at a node's start

    n = humps + 2
    nx = x0.size
    lower = np.concatenate([np.full(n - 1, -1.0), np.zeros(n - 1), np.full(nx - 2 * n + 2, 1e-3)])
    upper = np.concatenate([np.full(n - 1, 2.0), np.full(n - 1, 10.0), np.full(nx - 2 * n + 2, 60.0)])
    top = int(np.argmax(x0[2 * n - 2 :])) + 2 * n - 2  # the highest free frequency: the upper zero
    for factor in (1.0, 1.5, 3.0):
        start = x0.copy()
        start[top] = min(start[top] * factor, 50.0)
        start = np.clip(start, lower + 1e-12, upper - 1e-12)
        with np.errstate(over="ignore", invalid="ignore"):
            sol = least_squares(_hump_equations, start, jac=_hump_jacobian, bounds=(lower, upper),
                                args=(humps, v, zeta), xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=40 * nx)
        if np.all(np.isfinite(sol.fun)) and _hump_valid(sol.x, float(np.max(np.abs(sol.fun))), humps, v, zeta):
            return np.asarray(sol.x)
    return None


def _hump_failure(humps: int, v: float, zeta: float) -> ShaperError:
    return ShaperError(
        f"no {humps}-hump EI shaper for zeta={zeta:.4g}, vibration_tolerance={v:.4g}: its defining"
        " constraints have no valid solution there (the outer zeros run off at high damping; try"
        " a smaller damping ratio or tolerance)")


def _hump_continue(humps: int, v: float, x: FloatArray, z_from: float, z_to: float) -> FloatArray | None:
    """Continue a solution from damping ``z_from`` to ``z_to``, in four steps if one fails."""
    found = _hump_solve(humps, v, z_to, x)
    if found is None:
        found = x
        for z in np.linspace(z_from, z_to, 5)[1:]:
            found = _hump_solve(humps, v, float(z), found)
            if found is None:
                return None
    return found


@lru_cache(maxsize=1024)
def _hump_grid(humps: int, v: float, k: int) -> tuple[float, ...] | None:
    """Solution at zeta = k * step, continued from the one at (k - 1) * step; None if none."""
    if k == 0:
        amps, hump, zero = _undamped_hump_ei(humps, v)
        n = humps + 2
        x0 = np.concatenate([amps[:-1], 0.5 * np.arange(1, n), [h for h in hump if h != 1.0],
                             [z for z in zero if z != 1.0]])
        found = _hump_solve(humps, v, 0.0, x0)
    else:
        prev = _hump_grid(humps, v, k - 1)
        if prev is None:
            return None
        found = _hump_continue(humps, v, np.array(prev), (k - 1) * _HUMP_ZETA_STEP, k * _HUMP_ZETA_STEP)
    return None if found is None else tuple(found)


@lru_cache(maxsize=1024)
def _hump_at(humps: int, v: float, zeta: float) -> tuple[float, ...] | None:
    """Solution at any damping: from the grid point below, continued; None if none."""
    k = int(math.floor(zeta / _HUMP_ZETA_STEP + 1e-12))
    grid = _hump_grid(humps, v, k)
    if grid is None or abs(zeta - k * _HUMP_ZETA_STEP) <= 1e-12:
        return grid
    found = _hump_continue(humps, v, np.array(grid), k * _HUMP_ZETA_STEP, zeta)
    return None if found is None else tuple(found)


def hump_ei(mode: Mode, humps: int, vibration_tolerance: float = DEFAULT_VIBRATION_TOLERANCE) -> Impulses:
    """Extra-insensitive shaper with 1, 2 or 3 humps (3, 4 or 5 impulses) for the mode given.

    Constraints, for the damping ratio of ``mode`` at every frequency: sum A = 1; at each hump
    V = V_tol and dV/domega = 0; V = 0 (real and imaginary part of the residual) at the zero
    between two humps and at one zero either side of the outer humps. The design frequency is
    the middle hump (1 and 3 humps: V = V_tol there) or the middle zero (2 humps: V = 0 there).
    Unknowns: n - 1 amplitudes, n - 1 times, the free hump and zero frequencies; as many as
    equations (6, 10 and 14). They are solved by least squares, for omega = 1 and then scaled.

    Starting point: the undamped closed forms, impulses half a period T apart with symmetric
    amplitudes. Around the sequence's centre V is a polynomial in a cosine c:

    * 1 hump: ``((1+V)/4, (1-V)/2, (1+V)/4)``, zeros where ``cos(omega T/2) = -(1-V)/(1+V)``
      (the closed form of Singhose, Seering & Singer 1990).
    * 2 humps: ``(A1, 1/2 - A1, 1/2 - A1, A1)``, V = |8 A1 c^3 + (1 - 8 A1) c|, c = cos(omega T/4);
      at the humps h'(c) = 0 and |h| = V give ``4 a^3 = 27 V^2 (a + 1)``, ``a = 8 A1 - 1``, whose
      positive root is ``A1 = (3 X^2 + 2 X + 3 V^2) / (16 X)``,
      ``X = (V^2 (sqrt(1 - V^2) + 1))^(1/3)`` (the closed form of the literature; the tests check
      the two agree).
    * 3 humps: ``(A1, A2, A3, A2, A1)``, V = |4 A1 c^2 + 2 A2 c + A3 - 2 A1|, c = cos(omega T/2);
      g(-1) = V_tol at the design, the parabola's minimum = -V_tol at the side humps, and
      g(1) = 1 (sum of the amplitudes, omega = 0) give ``A2 = (1 - V)/4``,
      ``A1 = (1 + 3V + 2 sqrt(2 V (1 + V)))/16``, ``A3 = 1 - 2 A1 - 2 A2``.

    For zeta > 0 the solution is continued from zeta = 0 in steps of 0.02 (cached), so the
    damped design is exact for the damping given, not a curve fit. With damping the zero above
    the upper hump moves out fast (at high frequency V tends to the last amplitude) and, for
    three humps near zeta = 0.28 with V_tol = 5 %, jumps; the solver then retries with that
    zero further out. Every solution is checked: residual < 1e-9, positive amplitudes,
    increasing times, zeros and humps alternating, V <= V_tol between the outer zeros. Where no
    such solution exists (heavy damping with a large V_tol; for V_tol = 5 % all three families
    exist up to zeta = 0.3) a :class:`ShaperError` says so.
    """
    if humps not in (1, 2, 3):
        raise ShaperError(f"humps must be 1, 2 or 3, got {humps!r}")
    v = _check_tolerance(vibration_tolerance)
    x = _hump_at(humps, v, mode.zeta)
    if x is None:
        raise _hump_failure(humps, v, mode.zeta)
    amps, times, _, _ = _hump_unpack(np.array(x), humps, mode.zeta)
    return amps, times / mode.omega


def ei(mode: Mode, vibration_tolerance: float = DEFAULT_VIBRATION_TOLERANCE) -> Impulses:
    """Extra-insensitive (EI) shaper: three impulses, V = V_tol at the design mode, a local
    maximum there, and V = 0 at one frequency on either side (:func:`hump_ei` with one hump)."""
    return hump_ei(mode, 1, vibration_tolerance)

