"""Input shapers: impulse sequences designed from vibration modes, behind a registry.

An impulse sequence ``(amplitudes, times)`` is convolved with a command so that the impulse
responses of a lightly damped mode cancel (seeds 000, 002 and 004, and Singer & Seering 1990).
Units: natural frequency ``omega`` in rad/s, damping ratio ``zeta`` dimensionless, times in s.
The percentage vibration V(omega, zeta) of a sequence is defined in :mod:`.vibration`.

Families (``FAMILIES``)
-----------------------
none
    A single unit impulse at t = 0 (the command passes unchanged).
zv, zvd, zvdd, zvdn
    The zero-vibration shaper and its derivative-robust family ZV-D^n: n + 2 impulses half a
    damped period apart with binomial amplitudes ``C(n+1, i) K^i / (1 + K)^(n+1)``,
    ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` (seed 002 eqs. (5)-(6), seed 000 eqs. (5)-(8)).
mzv
    Modified ZV: three impulses a third of a damped period apart, V = 0 at the mode
    (:func:`mzv` derives it). Shorter than ZVD (2/3 of a period), more robust than ZV.
ei, 2hump_ei, 3hump_ei
    Extra-insensitive shapers with one, two or three humps (Singhose, Seering & Singer 1990;
    Singhose, Derezinski & Singer, extra-insensitive shapers for flexible spacecraft): 3, 4 or 5
    impulses whose V equals the tolerance ``V_tol`` at each hump, with zero slope there, and is
    zero between and around the humps (:func:`hump_ei`). The undamped closed forms are only the
    starting point; the constraints are solved numerically for the damping given.
si
    Specified insensitivity (Singer & Seering 1992, cited in seeds 002 and 004): the shortest
    positive sequence keeping V <= V_tol over the band ``omega (1 -+ I/2)`` of every mode, found
    by linear programming on a time grid and refined by SQP (:func:`si`). Several modes are
    designed jointly over the union of their bands.
custom
    An explicit sequence given by the user, validated.

Every design is exact for the damping ratio of the mode it is given (nothing assumes zeta = 0).
Designs of the other families for several modes are the convolution of the single-mode designs.
:func:`family_info` gives each family's description, impulse count and damping assumption, and
:func:`family_properties` the duration, V and 5 % insensitivity of a design.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.optimize import least_squares, linprog, minimize, minimize_scalar
from scipy.special import comb

from .vibration import insensitivity_width, percentage_vibration

#: tolerance on sum(amplitudes) == 1
SUM_TOL = 1e-9
#: the largest damping ratio a design accepts (the formulas need zeta < 1)
MAX_DAMPING = 0.95
#: shaper durations longer than this (s) are refused as almost surely a unit mistake
MAX_DURATION = 60.0
#: default tolerated percentage vibration of the ei, 2hump_ei, 3hump_ei and si families (fraction)
DEFAULT_VIBRATION_TOLERANCE = 0.05
#: default width of the si band, as a fraction of the design frequency (0.4 = +-20 %)
DEFAULT_INSENSITIVITY = 0.4
#: accepted vibration tolerance, fraction
VIBRATION_TOLERANCE_RANGE = (0.001, 0.3)
#: accepted si insensitivity: (0, 1.5], as a fraction of the design frequency
MAX_INSENSITIVITY = 1.5
#: highest ZV-D^n derivative order
MAX_DERIVATIVE_ORDER = 10


class ShaperError(ValueError):
    """An invalid shaper design request or impulse sequence; the message names the problem."""


@dataclass(frozen=True)
class Mode:
    """A vibration mode: natural frequency in rad/s and damping ratio (dimensionless)."""

    omega: float
    zeta: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.omega) and self.omega > 0.0):
            raise ShaperError(f"natural frequency must be finite and > 0 rad/s, got {self.omega!r}")
        if not (math.isfinite(self.zeta) and 0.0 <= self.zeta <= MAX_DAMPING):
            raise ShaperError(f"damping ratio must be in [0, {MAX_DAMPING}], got {self.zeta!r}")

    @property
    def damped_omega(self) -> float:
        """Damped natural frequency, rad/s."""
        return self.omega * math.sqrt(1.0 - self.zeta**2)

    @property
    def damped_period(self) -> float:
        """Damped period ``2 pi / omega_d``, s."""
        return 2.0 * math.pi / self.damped_omega

    @property
    def hz(self) -> float:
        """Natural frequency in Hz."""
        return self.omega / (2.0 * math.pi)

    @classmethod
    def from_hz(cls, hz: float, zeta: float) -> Mode:
        """Mode from a natural frequency in Hz."""
        return cls(2.0 * math.pi * float(hz), float(zeta))


@dataclass(frozen=True)
class Shaper:
    """A validated impulse sequence and where it came from.

    Attributes
    ----------
    amplitudes : numpy.ndarray
        Impulse amplitudes, dimensionless, summing to 1.
    times : numpy.ndarray
        Impulse times in s, first 0, non-decreasing.
    family : str
        Registry name of the design (``"custom"`` for user sequences).
    modes : tuple of Mode
        The modes it was designed for.
    params : dict
        Family parameters (``derivative_order``, ``vibration_tolerance``, ``insensitivity``).
    """

    amplitudes: np.ndarray
    times: np.ndarray
    family: str = "custom"
    modes: tuple[Mode, ...] = ()
    params: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        amps = np.array(self.amplitudes, dtype=float).ravel()
        times = np.array(self.times, dtype=float).ravel()
        if amps.size == 0:
            raise ShaperError("a shaper needs at least one impulse")
        if amps.size != times.size:
            raise ShaperError(f"{amps.size} amplitudes but {times.size} times")
        if not (np.all(np.isfinite(amps)) and np.all(np.isfinite(times))):
            raise ShaperError("amplitudes and times must be finite")
        if abs(times[0]) > 1e-12:
            raise ShaperError(f"the first impulse must be at t = 0 s, got {times[0]!r}")
        if np.any(np.diff(times) < 0.0):
            raise ShaperError("impulse times must be non-decreasing")
        if times[-1] > MAX_DURATION:
            raise ShaperError(f"shaper duration {times[-1]:.4g} s exceeds {MAX_DURATION} s")
        total = float(amps.sum())
        if abs(total - 1.0) > SUM_TOL:
            raise ShaperError(f"amplitudes must sum to 1, they sum to {total:.12g}")
        amps.setflags(write=False)
        times.setflags(write=False)
        object.__setattr__(self, "amplitudes", amps)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "modes", tuple(self.modes))

    @property
    def duration(self) -> float:
        """Time of the last impulse, s: how much the shaper lengthens a move."""
        return float(self.times[-1])

    def __len__(self) -> int:
        return int(self.amplitudes.size)


#: an impulse sequence (amplitudes, times in s)
Impulses = tuple[np.ndarray, np.ndarray]


# ---------------------------------------------------------------------------------------------
# Parameter checks
# ---------------------------------------------------------------------------------------------


def _check_tolerance(vibration_tolerance: float) -> float:
    v = _finite("vibration_tolerance", vibration_tolerance)
    lo, hi = VIBRATION_TOLERANCE_RANGE
    if not lo <= v <= hi:
        raise ShaperError(f"vibration_tolerance must be in [{lo}, {hi}] (a fraction), got {v!r}")
    return v


def _check_insensitivity(insensitivity: float) -> float:
    i = _finite("insensitivity", insensitivity)
    if not 0.0 < i <= MAX_INSENSITIVITY:
        raise ShaperError(
            f"insensitivity must be in (0, {MAX_INSENSITIVITY}] (band width / design frequency), got {i!r}")
    return i


def _check_order(derivative_order: int) -> int:
    try:
        ok = not isinstance(derivative_order, bool) and float(derivative_order).is_integer()
    except (TypeError, ValueError):
        ok = False
    if not ok or not 0 <= int(derivative_order) <= MAX_DERIVATIVE_ORDER:
        raise ShaperError(
            f"derivative_order must be an integer in [0, {MAX_DERIVATIVE_ORDER}], got {derivative_order!r}")
    return int(derivative_order)


def _finite(name: str, value: Any) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ShaperError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ShaperError(f"{name} must be finite, got {value!r}")
    return x


# ---------------------------------------------------------------------------------------------
# Closed-form families
# ---------------------------------------------------------------------------------------------


def _k(mode: Mode) -> float:
    return math.exp(-mode.zeta * math.pi / math.sqrt(1.0 - mode.zeta**2))


def zvdn(mode: Mode, derivative_order: int = 0) -> Impulses:
    """ZV-D^n impulses for one mode (n = 0: ZV, 1: ZVD, 2: ZVDD, ...).

    Amplitudes ``C(n+1, i) K^i / (1+K)^(n+1)`` at ``i * pi / omega_d``, i = 0..n+1.
    """
    n = _check_order(derivative_order)
    k = _k(mode)
    i = np.arange(n + 2)
    amps = comb(n + 1, i) * k**i / (1.0 + k) ** (n + 1)
    times = i * math.pi / mode.damped_omega
    return amps / amps.sum(), times


def mzv(mode: Mode) -> Impulses:
    """Modified ZV shaper: three impulses a third of a damped period apart, V = 0 at the mode.

    Derivation. V(omega, zeta) = 0 at the mode means the residual vector vanishes,

        sum_i A_i exp(zeta omega t_i) exp(j omega_d t_i) = 0.

    With ``t_i = i T`` and ``T = 2 pi / (3 omega_d)`` the phases ``omega_d t_i`` are 0, 2 pi/3
    and 4 pi/3: the three cube roots of unity, which sum to zero. The residual therefore
    vanishes exactly when the three terms have equal magnitude,
    ``A_i exp(zeta omega i T) = c``, i.e. ``A_i = c M^i`` with

        M = exp(-zeta omega T) = exp(-2 pi zeta / (3 sqrt(1 - zeta^2))),

    and ``sum A_i = 1`` gives ``c = 1 / (1 + M + M^2)``. (Written out: the imaginary part gives
    ``A_2 e^{zeta omega T} = A_3 e^{2 zeta omega T}``, the real part ``A_1 = A_2 e^{zeta omega T}``;
    three linear equations, one solution.) Undamped, the amplitudes are 1/3 each. Duration
    ``2 T_d / 3``, between ZV (``T_d / 2``) and ZVD (``T_d``); V has a simple zero at the mode
    (no zero derivative), so it is less robust than ZVD but more than ZV.
    """
    m = math.exp(-2.0 * math.pi * mode.zeta / (3.0 * math.sqrt(1.0 - mode.zeta**2)))
    i = np.arange(3)
    amps = m**i / (1.0 + m + m * m)
    times = i * mode.damped_period / 3.0
    return amps, times


# ---------------------------------------------------------------------------------------------
# Extra-insensitive family (one, two and three humps)
# ---------------------------------------------------------------------------------------------

#: the damped multi-hump EI constraints are continued from zeta = 0 in steps of this size
_HUMP_ZETA_STEP = 0.02


def _undamped_hump_ei(humps: int, v: float) -> tuple[np.ndarray, list[float], list[float]]:
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


def _hump_unpack(x: np.ndarray, humps: int, zeta: float) -> tuple[np.ndarray, np.ndarray, list[float], list[float]]:
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


def _hump_equations(x: np.ndarray, humps: int, v: float, zeta: float) -> np.ndarray:
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


def _hump_valid(x: np.ndarray, residual: float, humps: int, v: float, zeta: float) -> bool:
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


def _hump_solve(humps: int, v: float, zeta: float, x0: np.ndarray) -> np.ndarray | None:
    """Solve the multi-hump EI constraints at ``zeta`` (omega = 1) from ``x0``; None if no valid
    solution is found.

    With damping the zero above the upper hump moves up quickly with zeta (V decays towards
    the last amplitude at high frequency), so when the solve from ``x0`` fails it is retried
    with that zero moved further out.
    """
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
            sol = least_squares(_hump_equations, start, bounds=(lower, upper), args=(humps, v, zeta),
                                xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=40 * nx)
        if np.all(np.isfinite(sol.fun)) and _hump_valid(sol.x, float(np.max(np.abs(sol.fun))), humps, v, zeta):
            return np.asarray(sol.x)
    return None


def _hump_failure(humps: int, v: float, zeta: float) -> ShaperError:
    return ShaperError(
        f"no {humps}-hump EI shaper for zeta={zeta:.4g}, vibration_tolerance={v:.4g}: its defining"
        " constraints have no valid solution there (the outer zeros run off at high damping; try"
        " a smaller damping ratio or tolerance)")


def _hump_continue(humps: int, v: float, x: np.ndarray, z_from: float, z_to: float) -> np.ndarray | None:
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


# ---------------------------------------------------------------------------------------------
# Specified insensitivity
# ---------------------------------------------------------------------------------------------

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

Band = tuple[float, float, float]  # (omega_lo, omega_hi, zeta), omega = 1 for the lowest mode


def _vsq(x: np.ndarray, k: int, w: np.ndarray, zeta: float) -> tuple[np.ndarray, np.ndarray]:
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


def _si_worst(amps: np.ndarray, times: np.ndarray, bands: Sequence[Band]) -> tuple[float, list[tuple[float, float]]]:
    """Largest V over the bands (local maxima refined) and where V has its local maxima."""
    worst, peaks = 0.0, []
    span = max(float(times[-1]), 1e-9)
    for lo, hi, z in bands:
        n = int(min(20000, max(200, math.ceil((hi - lo) * span / 0.05))))
        w = np.linspace(lo, hi, n)
        v = percentage_vibration(amps, times, w, z)
        idx = [0, n - 1] + list(np.flatnonzero((v[1:-1] >= v[:-2]) & (v[1:-1] >= v[2:])) + 1)
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


def _si_clean(amps: np.ndarray, times: np.ndarray, merge: float) -> Impulses:
    """Drop impulses below 1e-7, merge those closer than ``merge`` (at their centroid), t_1 = 0."""
    keep_a: list[float] = []
    keep_t: list[float] = []
    for a, t in zip(np.clip(amps, 0.0, None), times):
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
    rows = []
    for lo, hi, z in bands:
        m = max(8, int(math.ceil((hi - lo) * duration / 0.25)) + 2)
        w = np.linspace(lo, hi, m)[:, None]
        e = np.exp(z * w * (t - duration) + 1j * w * math.sqrt(1.0 - z * z) * t)
        rows.append((dirs[:, None, None] * e[None]).real.reshape(-1, nt))
    a_ub = np.vstack(rows)
    cost = np.zeros(nt)
    cost[-1] = -1.0
    bound = v * math.cos(math.pi / _SI_DIRECTIONS) * (1.0 - 1e-6)  # vertices strictly inside
    res = linprog(cost, A_ub=a_ub, b_ub=np.full(a_ub.shape[0], bound),
                  A_eq=np.ones((1, nt)), b_eq=[1.0], bounds=(0.0, None), method="highs")
    if res.status != 0:
        return None
    return res.x, t


def _si_polish(amps: np.ndarray, times: np.ndarray, bands: Sequence[Band], v: float) -> Impulses | None:
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
        target = v * (1.0 - margin)
        k = amps.size
        if k < 2:
            return None
        w_all = np.array([s[0] for s in samples])
        z_all = np.array([s[1] for s in samples])
        groups = [(z, w_all[z_all == z]) for z in np.unique(z_all)]
        order = np.zeros((k - 1, 2 * k - 1))
        for i in range(k - 1):
            order[i, k + i] = 1.0
            if i:
                order[i, k + i - 1] = -1.0
        reg = 1e-6  # breaks ties between equally short sequences

        def cons(x: np.ndarray, groups: list = groups, k: int = k) -> np.ndarray:
            return np.concatenate([target * target - _vsq(x, k, w, z)[0] for z, w in groups])

        def cons_jac(x: np.ndarray, groups: list = groups, k: int = k) -> np.ndarray:
            return -np.vstack([_vsq(x, k, w, z)[1] for z, w in groups])

        def obj(x: np.ndarray, k: int = k) -> float:
            return float(x[-1] + reg * np.sum(x[:k] ** 2))

        def obj_jac(x: np.ndarray, k: int = k) -> np.ndarray:
            return np.concatenate([2.0 * reg * x[:k], np.zeros(k - 2), [1.0]])

        res = minimize(
            obj, np.concatenate([amps, times[1:]]), jac=obj_jac, method="SLSQP",
            bounds=[(0.0, 1.0)] * k + [(0.0, None)] * (k - 1),
            constraints=[
                {"type": "ineq", "fun": cons, "jac": cons_jac},
                {"type": "ineq", "fun": lambda x, m=order: m @ x, "jac": lambda x, m=order: m},
                {"type": "eq", "fun": lambda x, k=k: np.sum(x[:k]) - 1.0,
                 "jac": lambda x, k=k: np.concatenate([np.ones(k), np.zeros(k - 1)])},
            ],
            options={"maxiter": 100, "ftol": 1e-12},
        )
        if not np.all(np.isfinite(res.x)):
            return None
        t_new = np.concatenate([[0.0], res.x[k:]])
        if np.any(np.diff(t_new) < -1e-12):
            return None
        amps, times = _si_clean(res.x[:k], np.maximum.accumulate(t_new), 1e-7 * max(t_new[-1], 1e-9))
        worst, peaks = _si_worst(amps, times, bands)
        if worst <= v:
            return amps, times
        samples += peaks
    return None


@lru_cache(maxsize=256)
def _si_normalised(modes: tuple[tuple[float, float], ...], v: float, insensitivity: float) -> tuple[tuple, tuple]:
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
        Invalid parameters, or no sequence of at most 40 periods meets the specification.
    """
    v = _check_tolerance(vibration_tolerance)
    ins = _check_insensitivity(insensitivity)
    modes = tuple(modes)
    if not modes:
        raise ShaperError("shaper family 'si' needs at least one mode")
    w_ref = min(m.omega for m in modes)
    key = tuple(sorted({(m.omega / w_ref, m.zeta) for m in modes}))
    amps, times = _si_normalised(key, v, ins)
    return np.array(amps), np.array(times) / w_ref


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------


def none_shaper() -> Shaper:
    """The identity shaper: one unit impulse at t = 0."""
    return Shaper(np.array([1.0]), np.array([0.0]), family="none")


def convolve(a: Impulses, b: Impulses) -> Impulses:
    """Convolution of two impulse sequences (amplitudes multiply, times add), merged and sorted."""
    amps = np.outer(a[0], b[0]).ravel()
    times = np.add.outer(a[1], b[1]).ravel()
    order = np.argsort(times, kind="stable")
    amps, times = amps[order], times[order]
    keep_t: list[float] = []
    keep_a: list[float] = []
    for t, x in zip(times, amps):
        if keep_t and abs(t - keep_t[-1]) < 1e-12:
            keep_a[-1] += x
        else:
            keep_t.append(float(t))
            keep_a.append(float(x))
    return np.array(keep_a), np.array(keep_t)


Design = Callable[..., Impulses]

_EXACT = "exact for the mode's damping ratio (closed form)"
_SOLVED = ("designed for the mode's damping ratio (constraints solved numerically; the undamped"
           " closed form is only the starting point)")


@dataclass(frozen=True)
class FamilyInfo:
    """What the registry knows about a family.

    Attributes
    ----------
    description : str
        One line.
    impulses : str
        Number of impulses for one mode (``"n + 2"``, ``"varies"``, ...).
    damping : str
        The damping the design assumes.
    params : tuple of str
        The :func:`design` keywords it uses.
    design : callable or None
        ``design(mode, **params)``, or ``design(modes, **params)`` if ``joint``; None for
        ``none`` and ``custom``.
    joint : bool
        Several modes are designed jointly (otherwise single-mode designs are convolved).
    """

    description: str
    impulses: str
    damping: str
    params: tuple[str, ...] = ()
    design: Design | None = None
    joint: bool = False


_REGISTRY: dict[str, FamilyInfo] = {
    "none": FamilyInfo("no shaping: one unit impulse at t = 0", "1", "none (no mode)"),
    "zv": FamilyInfo("zero vibration: V = 0 at the mode; half a damped period", "2", _EXACT,
                     design=lambda m: zvdn(m, 0)),
    "zvd": FamilyInfo("zero vibration and derivative: V = dV/domega = 0; one damped period", "3", _EXACT,
                      design=lambda m: zvdn(m, 1)),
    "zvdd": FamilyInfo("ZV-D^2: V and two derivatives zero; 1.5 damped periods", "4", _EXACT,
                       design=lambda m: zvdn(m, 2)),
    "zvdn": FamilyInfo("ZV-D^n: V and n derivatives zero, binomial amplitudes (derivative_order)", "n + 2",
                       _EXACT, ("derivative_order",), lambda m, derivative_order: zvdn(m, derivative_order)),
    "mzv": FamilyInfo("modified ZV: V = 0 with impulses a third of a damped period apart; 2/3 period",
                      "3", _EXACT, design=mzv),
    "ei": FamilyInfo("extra-insensitive: V = V_tol at the mode (a hump), zero either side (vibration_tolerance)",
                     "3", _SOLVED, ("vibration_tolerance",), ei),
    "2hump_ei": FamilyInfo("two-hump EI: V = 0 at the mode, humps V = V_tol either side (vibration_tolerance)",
                           "4", _SOLVED, ("vibration_tolerance",),
                           lambda m, vibration_tolerance: hump_ei(m, 2, vibration_tolerance)),
    "3hump_ei": FamilyInfo("three-hump EI: humps V = V_tol at and either side of the mode (vibration_tolerance)",
                           "5", _SOLVED, ("vibration_tolerance",),
                           lambda m, vibration_tolerance: hump_ei(m, 3, vibration_tolerance)),
    "si": FamilyInfo("specified insensitivity: shortest with V <= V_tol over a band (vibration_tolerance,"
                     " insensitivity); modes designed jointly", "varies (optimised)",
                     "designed for each mode's damping ratio (optimised over the band at that damping)",
                     ("vibration_tolerance", "insensitivity"), si, joint=True),
    "custom": FamilyInfo("an explicit impulse sequence (amplitudes, times)", "any",
                         "whatever it was designed for (not known to the registry)"),
}

#: every family name :func:`design` accepts, with a one-line description
FAMILIES: dict[str, str] = {name: info.description for name, info in _REGISTRY.items()}


def family_info(family: str) -> FamilyInfo:
    """Registry entry of a family (description, impulse count, damping assumed, parameters)."""
    name = str(family).strip().lower()
    if name not in _REGISTRY:
        raise ShaperError(f"unknown shaper family {family!r}; known: {', '.join(_REGISTRY)}")
    return _REGISTRY[name]


def family_params(
    family: str,
    *,
    derivative_order: int = 1,
    vibration_tolerance: float = DEFAULT_VIBRATION_TOLERANCE,
    insensitivity: float = DEFAULT_INSENSITIVITY,
) -> dict[str, float]:
    """The parameters ``family`` uses, checked, as :func:`design` records them in ``params``.

    Raises
    ------
    ShaperError
        Unknown family, or a parameter it uses out of range or not finite (the message names it).
    """
    checks: dict[str, Callable[[Any], float]] = {
        "derivative_order": _check_order, "vibration_tolerance": _check_tolerance,
        "insensitivity": _check_insensitivity,
    }
    given = {"derivative_order": derivative_order, "vibration_tolerance": vibration_tolerance,
             "insensitivity": insensitivity}
    return {p: checks[p](given[p]) for p in family_info(family).params}


def design(
    family: str,
    modes: Sequence[Mode] = (),
    *,
    derivative_order: int = 1,
    vibration_tolerance: float = DEFAULT_VIBRATION_TOLERANCE,
    insensitivity: float = DEFAULT_INSENSITIVITY,
    amplitudes: Sequence[float] | None = None,
    times: Sequence[float] | None = None,
) -> Shaper:
    """Design a shaper of a registry family, or validate a custom sequence.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES`.
    modes : sequence of Mode
        Modes to design for (one or more). ``si`` designs them jointly; the other families
        convolve single-mode designs. Ignored for ``none``; for ``custom`` recorded as the
        modes it is meant for.
    derivative_order : int
        n of the ZV-D^n family (``zvdn`` only), in [0, 10].
    vibration_tolerance : float
        V_tol of ``ei``, ``2hump_ei``, ``3hump_ei`` and ``si``, as a fraction (0.05 = 5 %), in
        [0.001, 0.3].
    insensitivity : float
        Width of the ``si`` band where V <= V_tol, as a fraction of each design frequency
        (0.4: from 0.8 to 1.2 omega), in (0, 1.5].
    amplitudes, times : sequence of float
        The impulse sequence of a ``custom`` shaper (times in s).

    Only the parameters a family uses are checked and recorded in ``Shaper.params``.

    Raises
    ------
    ShaperError
        Unknown family, missing or invalid modes or parameters, or an invalid sequence; the
        message names the problem.
    """
    name = str(family).strip().lower()
    info = family_info(name)
    modes = tuple(modes)
    for m in modes:
        if not isinstance(m, Mode):
            raise ShaperError(f"modes must be Mode objects, got {type(m).__name__}")
    if name == "none":
        return none_shaper()
    if name == "custom":
        if amplitudes is None or times is None:
            raise ShaperError("a custom shaper needs amplitudes and times")
        return Shaper(np.asarray(amplitudes, float), np.asarray(times, float), "custom", modes)
    if not modes:
        raise ShaperError(f"shaper family {name!r} needs at least one mode")
    params = family_params(name, derivative_order=derivative_order, vibration_tolerance=vibration_tolerance,
                           insensitivity=insensitivity)
    assert info.design is not None
    if info.joint:
        amps, ts = info.design(modes, **params)
    else:
        amps, ts = info.design(modes[0], **params)
        for mode in modes[1:]:
            amps, ts = convolve((amps, ts), info.design(mode, **params))
    return Shaper(amps / amps.sum(), ts, name, modes, params)


@dataclass(frozen=True)
class FamilyProperties:
    """Figures of merit of one family's design for one mode.

    Attributes
    ----------
    family : str
    impulses : int
        Number of impulses.
    duration : float
        Time of the last impulse, s.
    v_at_design : float
        Percentage vibration at the design mode, fraction.
    insensitivity_5pct : float
        Width of the band around the design frequency where V <= 5 %, as a fraction of it
        (:func:`~shaper_nodes.core.vibration.insensitivity_width`).
    damping_assumed : str
        The registry's statement of the damping the design assumes.
    """

    family: str
    impulses: int
    duration: float
    v_at_design: float
    insensitivity_5pct: float
    damping_assumed: str


def family_properties(family: str, mode: Mode, **params: Any) -> FamilyProperties:
    """Design ``family`` for ``mode`` (keywords as :func:`design`) and measure it."""
    shaper = design(family, [mode], **params)
    return FamilyProperties(
        family=shaper.family,
        impulses=len(shaper),
        duration=shaper.duration,
        v_at_design=float(percentage_vibration(shaper.amplitudes, shaper.times, mode.omega, mode.zeta)),
        insensitivity_5pct=insensitivity_width(shaper.amplitudes, shaper.times, mode.omega, mode.zeta, 0.05),
        damping_assumed=family_info(shaper.family).damping,
    )
