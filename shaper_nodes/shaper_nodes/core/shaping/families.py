"""Input shapers: impulse sequences designed from vibration modes, behind a registry.

An impulse sequence ``(amplitudes, times)`` is convolved with a command so that the impulse
responses of a lightly damped mode cancel (seeds 000, 002 and 004, and Singer & Seering 1990).
Units: natural frequency ``omega`` in rad/s, damping ratio ``zeta`` dimensionless, times in s.
The percentage vibration V(omega, zeta) of a sequence is defined in :mod:`.vibration`; the
mode and shaper types and the parameter limits in :mod:`.types`.

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
    zero between and around the humps (:func:`.ei.hump_ei`). The undamped closed forms are only the
    starting point; the constraints are solved numerically for the damping given.
si
    Specified insensitivity (Singer & Seering 1992, cited in seeds 002 and 004): the shortest
    positive sequence keeping V <= V_tol over the band ``omega (1 -+ I/2)`` of every mode, found
    by linear programming on a time grid and refined by SQP (:func:`.si.si`). Several modes are
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
from dataclasses import dataclass
from typing import Any

import numpy as np

from .ei import ei, hump_ei
from .si import si
from .types import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_MAX_GAIN,
    DEFAULT_VIBRATION_TOLERANCE,
    MAX_DESIGN_MODES,
    MAX_GAIN,
    MAX_IMPULSES,
    Impulses,
    Mode,
    Shaper,
    ShaperError,
    _check_insensitivity,
    _check_order,
    _check_tolerance,
)
from .vibration import insensitivity_width, percentage_vibration

# the families of .ei and .si and the types of .types are importable from here too
__all__ = [
    "DEFAULT_INSENSITIVITY",
    "DEFAULT_VIBRATION_TOLERANCE",
    "FAMILIES",
    "Design",
    "FamilyInfo",
    "FamilyProperties",
    "Impulses",
    "Mode",
    "Shaper",
    "ShaperError",
    "convolve",
    "design",
    "ei",
    "family_info",
    "family_params",
    "family_properties",
    "hump_ei",
    "mzv",
    "none_shaper",
    "si",
    "zvdn",
]


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
    # exact binomials (math.comb; the same floats as scipy.special.comb for every order up to 29, and
    # MAX_DERIVATIVE_ORDER is 10), without scipy.special's 0.1-0.3 s of CPU at a node's first design
    binomials = np.array([math.comb(n + 1, int(j)) for j in i], dtype=np.float64)
    amps = binomials * k**i / (1.0 + k) ** (n + 1)
    times = i * math.pi / mode.damped_omega
    return amps / amps.sum(), np.asarray(times, dtype=np.float64)


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
    return np.asarray(amps, dtype=np.float64), np.asarray(times, dtype=np.float64)



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
    for t, x in zip(times, amps, strict=True):
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
    max_gain: float = DEFAULT_MAX_GAIN,
) -> Shaper:
    """Design a shaper of a registry family, or validate a custom sequence.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES`.
    modes : sequence of Mode
        Modes to design for (one or more). ``si`` designs them jointly; the other families
        convolve single-mode designs. Ignored for ``none``; for ``custom`` recorded as the
        modes it is meant for. A design mode's damped period may not exceed
        :data:`~.types.MAX_DESIGN_PERIOD` (checked before any design divides by its frequency).
    derivative_order : int
        n of the ZV-D^n family (``zvdn`` only), in [0, 10].
    vibration_tolerance : float
        V_tol of ``ei``, ``2hump_ei``, ``3hump_ei`` and ``si``, as a fraction (0.05 = 5 %), in
        [0.001, 0.3].
    insensitivity : float
        Width of the ``si`` band where V <= V_tol, as a fraction of each design frequency
        (0.4: from 0.8 to 1.2 omega), in (0, 1.5].
    amplitudes, times : sequence of float
        The impulse sequence of a ``custom`` shaper (times in s), at most
        :data:`~.types.MAX_IMPULSES` impulses.
    max_gain : float
        Largest gain sum |A| a ``custom`` shaper may have, in [1, :data:`~.types.MAX_GAIN`]; the
        default 1 admits non-negative impulses only, so no input is amplified.

    Only the parameters a family uses are checked and recorded in ``Shaper.params``.

    Raises
    ------
    ShaperError
        Unknown family, missing or invalid modes or parameters (a design mode too slow to design
        for), or an invalid sequence (an amplitude beyond :data:`~.types.MAX_AMPLITUDE` among
        them); the message names the problem.
    """
    name = str(family).strip().lower()
    info = family_info(name)
    modes = tuple(modes)
    if len(modes) > MAX_DESIGN_MODES:
        raise ShaperError(f"{len(modes)} design modes exceed the limit of {MAX_DESIGN_MODES}")
    for m in modes:
        if not isinstance(m, Mode):
            raise ShaperError(f"modes must be Mode objects, got {type(m).__name__}")
    if name == "none":
        return none_shaper()
    if name == "custom":
        return _custom(amplitudes, times, modes, max_gain)
    if not modes:
        raise ShaperError(f"shaper family {name!r} needs at least one mode")
    for i, m in enumerate(modes):  # before any design divides by a frequency
        m.check_designable(f"design mode {i}")
    params = family_params(name, derivative_order=derivative_order, vibration_tolerance=vibration_tolerance,
                           insensitivity=insensitivity)
    assert info.design is not None
    if info.joint:
        amps, ts = info.design(modes, **params)
    else:
        amps, ts = info.design(modes[0], **params)
        for mode in modes[1:]:
            more = info.design(mode, **params)
            if amps.size * more[0].size > MAX_IMPULSES:  # refused before the convolution's work
                raise ShaperError(f"{name} for {len(modes)} modes needs more than {MAX_IMPULSES} impulses")
            amps, ts = convolve((amps, ts), more)
    return Shaper(amps / amps.sum(), ts, name, modes, params)


def _custom(amplitudes: Sequence[float] | None, times: Sequence[float] | None, modes: tuple[Mode, ...],
            max_gain: float) -> Shaper:
    """A custom sequence, validated, whose gain sum |A| stays within ``max_gain``."""
    if not (math.isfinite(max_gain) and 1.0 <= max_gain <= MAX_GAIN):
        raise ShaperError(f"max_gain must be in [1, {MAX_GAIN:g}], got {max_gain!r}")
    if amplitudes is None or times is None:
        raise ShaperError("a custom shaper needs amplitudes and times")
    if len(amplitudes) > MAX_IMPULSES:  # before any conversion of a long sequence
        raise ShaperError(f"{len(amplitudes)} impulses exceed the limit of {MAX_IMPULSES}")
    shaper = Shaper(np.asarray(amplitudes, float), np.asarray(times, float), "custom", modes)
    if shaper.gain > max_gain * (1.0 + 1e-9):
        raise ShaperError(f"the impulses amplify: their gain sum |A| = {shaper.gain:.6g} exceeds max_gain"
                          f" {max_gain:g} (a unit step would peak at {shaper.step_peak:.6g}); negative impulses"
                          " need a larger max_gain")
    return shaper


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
        (:func:`~shaper_nodes.core.shaping.vibration.insensitivity_width`).
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
