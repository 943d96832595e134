"""Input shapers: impulse sequences designed from vibration modes, behind a registry.

An impulse sequence ``(amplitudes, times)`` is convolved with a command so that the impulse
responses of a lightly damped mode cancel (seeds 000, 002 and 004, and Singer & Seering 1990).
Units: natural frequency ``omega`` in rad/s, damping ratio ``zeta`` dimensionless, times in s.

Families (``FAMILIES``)
-----------------------
none
    A single unit impulse at t = 0 (the command passes unchanged).
zv, zvd, zvdd, zvdn
    The zero-vibration shaper and its derivative-robust family ZV-D^n: n + 2 impulses half a
    damped period apart with binomial amplitudes ``C(n+1, i) K^i / (1 + K)^(n+1)``,
    ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` (seed 002 eqs. (5)-(6), seed 000 eqs. (5)-(8)).
    They assume the damping ratio given and are exact for it.
ei
    The extra-insensitive shaper (Singhose, Seering & Singer 1990): three impulses whose
    percentage vibration equals the tolerance ``V_tol`` at the design mode, is a local maximum
    there, and is zero at one frequency on either side. For zeta = 0 the closed form is
    ``((1+V)/4, (1-V)/2, (1+V)/4)`` at ``(0, T/2, T)``; for zeta > 0 this module solves the same
    constraints numerically from that starting point (no curve fit), for the damping given.
custom
    An explicit sequence given by the user, validated.

Designs for several modes are the convolution of the single-mode designs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.special import comb

#: tolerance on sum(amplitudes) == 1
SUM_TOL = 1e-9
#: the largest damping ratio a design accepts (the formulas need zeta < 1)
MAX_DAMPING = 0.95
#: shaper durations longer than this (s) are refused as almost surely a unit mistake
MAX_DURATION = 60.0


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
        Family parameters (``derivative_order``, ``vibration_tolerance``).
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


def _k(mode: Mode) -> float:
    return math.exp(-mode.zeta * math.pi / math.sqrt(1.0 - mode.zeta**2))


def zvdn(mode: Mode, derivative_order: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """ZV-D^n impulses for one mode (n = 0: ZV, 1: ZVD, 2: ZVDD, ...).

    Amplitudes ``C(n+1, i) K^i / (1+K)^(n+1)`` at ``i * pi / omega_d``, i = 0..n+1.
    """
    n = int(derivative_order)
    if not 0 <= n <= 10:
        raise ShaperError(f"derivative order must be in [0, 10], got {derivative_order!r}")
    k = _k(mode)
    i = np.arange(n + 2)
    amps = comb(n + 1, i) * k**i / (1.0 + k) ** (n + 1)
    times = i * math.pi / mode.damped_omega
    return amps / amps.sum(), times


def _residual_vector(amps: np.ndarray, times: np.ndarray, omega: float, zeta: float) -> complex:
    """Sum_i A_i exp((zeta w + j w_d) (t_i - t_n)): its modulus is V (see vibration.py)."""
    wd = omega * math.sqrt(1.0 - zeta**2)
    tau = times - times[-1]
    return complex(np.sum(amps * np.exp(zeta * omega * tau + 1j * wd * times)))


def ei(mode: Mode, vibration_tolerance: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Extra-insensitive (EI) shaper: three impulses, V = V_tol at the design mode.

    Constraints (for the damping ratio of ``mode`` at every frequency): sum A = 1; V(omega) =
    V_tol; dV/domega (omega) = 0; V(omega_lo) = 0 and V(omega_hi) = 0 at two frequencies either
    side. Six equations in the unknowns A1, A2 (A3 = 1 - A1 - A2), t2, t3, omega_lo, omega_hi,
    solved by least squares from the undamped closed form.
    """
    v = float(vibration_tolerance)
    if not (0.0 < v <= 0.3):
        raise ShaperError(f"EI vibration tolerance must be in (0, 0.3], got {vibration_tolerance!r}")
    w, z = mode.omega, mode.zeta
    td = 2.0 * math.pi / mode.damped_omega
    theta = math.acos(-(1.0 - v) / (1.0 + v))  # undamped zero at omega * theta / pi
    k = _k(mode)
    a0 = np.array([(1 + v) / 4, (1 - v) / 2 * k, (1 + v) / 4 * k * k])
    a0 /= a0.sum()
    x0 = np.array([a0[0], a0[1], 0.5, 1.0, theta / math.pi, (2 * math.pi - theta) / math.pi])

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        amps = np.array([x[0], x[1], 1.0 - x[0] - x[1]])
        times = np.array([0.0, x[2] * td, x[3] * td])
        return amps, times, x[4] * w, x[5] * w

    def vib(amps: np.ndarray, times: np.ndarray, om: float) -> float:
        return abs(_residual_vector(amps, times, om, z))

    def equations(x: np.ndarray) -> np.ndarray:
        amps, times, wlo, whi = unpack(x)
        h = 1e-6 * w
        dv = (vib(amps, times, w + h) - vib(amps, times, w - h)) / (2 * h) * w
        rlo = _residual_vector(amps, times, wlo, z)
        rhi = _residual_vector(amps, times, whi, z)
        return np.array([vib(amps, times, w) - v, dv, rlo.real, rlo.imag, rhi.real, rhi.imag])

    sol = least_squares(equations, x0, xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=400)
    amps, times, wlo, whi = unpack(sol.x)
    if (
        not sol.success
        or np.max(np.abs(sol.fun)) > 1e-8
        or np.any(amps <= 0.0)
        or not (0.0 < times[1] < times[2])
        or not (wlo < w < whi)
    ):
        raise ShaperError(
            f"EI design did not converge for omega={w:.6g} rad/s, zeta={z:.4g}, V_tol={v:.4g}"
            f" (residual {np.max(np.abs(sol.fun)):.3g})"
        )
    return amps, times


def none_shaper() -> Shaper:
    """The identity shaper: one unit impulse at t = 0."""
    return Shaper(np.array([1.0]), np.array([0.0]), family="none")


def convolve(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
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


Design = Callable[..., tuple[np.ndarray, np.ndarray]]

_REGISTRY: dict[str, tuple[Design, str]] = {
    "zv": (lambda m, **_: zvdn(m, 0), "zero vibration: 2 impulses, duration half a damped period"),
    "zvd": (lambda m, **_: zvdn(m, 1), "zero vibration and derivative: 3 impulses, one damped period"),
    "zvdd": (lambda m, **_: zvdn(m, 2), "ZV-D^2: 4 impulses, 1.5 damped periods"),
    "zvdn": (
        lambda m, derivative_order=1, **_: zvdn(m, derivative_order),
        "ZV-D^n: n+2 impulses with binomial amplitudes (parameter derivative_order)",
    ),
    "ei": (
        lambda m, vibration_tolerance=0.05, **_: ei(m, vibration_tolerance),
        "extra-insensitive: 3 impulses, V = V_tol at the mode (parameter vibration_tolerance)",
    ),
}

#: every family name :func:`design` accepts, with a one-line description
FAMILIES: dict[str, str] = {
    "none": "no shaping: one unit impulse at t = 0",
    **{name: desc for name, (_, desc) in _REGISTRY.items()},
    "custom": "an explicit impulse sequence (amplitudes, times)",
}


def design(
    family: str,
    modes: Sequence[Mode] = (),
    *,
    derivative_order: int = 1,
    vibration_tolerance: float = 0.05,
    amplitudes: Sequence[float] | None = None,
    times: Sequence[float] | None = None,
) -> Shaper:
    """Design a shaper of a registry family, or validate a custom sequence.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES`.
    modes : sequence of Mode
        Modes to design for (one or more; the designs are convolved). Ignored for ``none``;
        for ``custom`` recorded as the modes it is meant for.
    derivative_order : int
        n of the ZV-D^n family (``zvdn`` only).
    vibration_tolerance : float
        V_tol of the EI family, as a fraction (0.05 = 5 %).
    amplitudes, times : sequence of float
        The impulse sequence of a ``custom`` shaper (times in s).

    Raises
    ------
    ShaperError
        Unknown family, missing or invalid modes or parameters, or an invalid sequence.
    """
    family = str(family).strip().lower()
    modes = tuple(modes)
    if family == "none":
        return none_shaper()
    if family == "custom":
        if amplitudes is None or times is None:
            raise ShaperError("a custom shaper needs amplitudes and times")
        return Shaper(np.asarray(amplitudes, float), np.asarray(times, float), "custom", modes)
    if family not in _REGISTRY:
        raise ShaperError(f"unknown shaper family {family!r}; known: {sorted(FAMILIES)}")
    if not modes:
        raise ShaperError(f"shaper family {family!r} needs at least one mode")
    fn = _REGISTRY[family][0]
    params: dict[str, float] = {}
    if family == "zvdn":
        params["derivative_order"] = int(derivative_order)
    if family == "ei":
        params["vibration_tolerance"] = float(vibration_tolerance)
    seq = fn(modes[0], derivative_order=derivative_order, vibration_tolerance=vibration_tolerance)
    for mode in modes[1:]:
        seq = convolve(seq, fn(mode, derivative_order=derivative_order, vibration_tolerance=vibration_tolerance))
    amps, ts = seq
    amps = amps / amps.sum()
    return Shaper(amps, ts, family, modes, params)
