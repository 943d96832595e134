"""The types every shaper design shares: modes, validated impulse sequences, limits and checks.

Units: natural frequency ``omega`` in rad/s, damping ratio ``zeta`` dimensionless, times in s.
The design parameters (derivative order, vibration tolerance, insensitivity) are checked here,
once, with messages that name the parameter, for the families (:mod:`.families`, :mod:`.ei`,
:mod:`.si`) and for :func:`~.families.family_params`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.checks import in_range, integer, number

#: tolerance on sum(amplitudes) == 1
SUM_TOL = 1e-9
#: the largest damping ratio a design accepts (the formulas need zeta < 1)
MAX_DAMPING = 0.95
#: shaper durations longer than this (s) are refused as almost surely a unit mistake
MAX_DURATION = 60.0
#: most impulses a shaper may have, designed or custom: each change does bounded work and memory
MAX_IMPULSES = 1000
#: most modes one design may cover (a convolved design has the product of the single-mode counts)
MAX_DESIGN_MODES = 8
#: the longest damped period (s) of a mode a family is designed for: every design lasts a sizeable
#: fraction of its mode's period (ZV 0.5, the shortest si, I = 0.01 at V_tol = 0.3, 0.405, measured),
#: so a slower mode's shaper would exceed MAX_DURATION some 400 times over; refused before the design
#: divides by its frequency (a frequency near 5e-324 rad/s has no finite period)
MAX_DESIGN_PERIOD = 1000.0 * MAX_DURATION
#: the largest |amplitude| a shaper may hold, far beyond any gain a shaper may have (MAX_GAIN):
#: checked before any sum, so that sums over MAX_IMPULSES of them stay finite (1.7e308 + 1.7e308 is not)
MAX_AMPLITUDE = 1e300
#: a custom shaper's default gain bound, sum |A|: 1 admits non-negative impulses only (no overshoot)
DEFAULT_MAX_GAIN = 1.0
#: the largest gain bound that may be allowed (``max_gain``), for shapers with negative impulses
MAX_GAIN = 100.0
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

#: a float array (amplitudes, times in s, frequencies in rad/s, ...)
FloatArray = npt.NDArray[np.float64]


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

    def check_designable(self, name: str = "design mode") -> None:
        """Refuse a mode too slow to design a shaper for.

        The damped period may not exceed :data:`MAX_DESIGN_PERIOD` (s); checked by multiplying, as a
        frequency near 5e-324 rad/s has no finite period to compare.

        Parameters
        ----------
        name : str
            What the message calls the mode (``"design mode 0"``).

        Raises
        ------
        ShaperError
            The damped period exceeds the limit; the message names the mode, in rad/s, and the limit.
        """
        if not self.damped_omega * MAX_DESIGN_PERIOD >= 2.0 * math.pi:
            lowest = 2.0 * math.pi / MAX_DESIGN_PERIOD / math.sqrt(1.0 - self.zeta**2)
            raise ShaperError(f"{name} {self.omega!r} rad/s (damping ratio {self.zeta:g}) is too slow to design for:"
                              f" its damped period exceeds the limit of {MAX_DESIGN_PERIOD:g} s (at least"
                              f" {lowest:.3g} rad/s at this damping)")


def modes_from_hz(frequencies_hz: Sequence[float], damping_ratios: Sequence[float]) -> tuple[Mode, ...]:
    """Modes from natural frequencies in Hz and damping ratios, one of each per mode.

    Raises
    ------
    ShaperError
        More than :data:`MAX_DESIGN_MODES` modes (refused before any other work), lists of
        different lengths, or an invalid mode (the message names the mode by its index and says
        what is wrong).
    """
    if len(frequencies_hz) > MAX_DESIGN_MODES or len(damping_ratios) > MAX_DESIGN_MODES:
        raise ShaperError(f"{max(len(frequencies_hz), len(damping_ratios))} modes exceed the limit of"
                          f" {MAX_DESIGN_MODES}")
    if len(frequencies_hz) != len(damping_ratios):
        raise ShaperError(f"{len(frequencies_hz)} frequencies but {len(damping_ratios)} damping ratios:"
                          " give one damping ratio per frequency")
    modes = []
    for i, (hz, zeta) in enumerate(zip(frequencies_hz, damping_ratios, strict=True)):
        try:
            modes.append(Mode.from_hz(number(f"frequency {i}", hz, ShaperError),
                                      number(f"damping ratio {i}", zeta, ShaperError)))
        except ShaperError as err:
            raise ShaperError(f"mode {i} ({hz!r} Hz, damping ratio {zeta!r}): {err}") from None
    return tuple(modes)


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

    amplitudes: FloatArray
    times: FloatArray
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
        if amps.size > MAX_IMPULSES:
            raise ShaperError(f"{amps.size} impulses exceed the limit of {MAX_IMPULSES}")
        if not (np.all(np.isfinite(amps)) and np.all(np.isfinite(times))):
            raise ShaperError("amplitudes and times must be finite")
        big = np.abs(amps) > MAX_AMPLITUDE
        if np.any(big):  # before any sum of them
            i = int(np.flatnonzero(big)[0])
            raise ShaperError(f"amplitude {amps[i]:.6g} of impulse {i} exceeds the limit of {MAX_AMPLITUDE:g}"
                              " in magnitude")
        if abs(times[0]) > 1e-12:
            raise ShaperError(f"the first impulse must be at t = 0 s, got {times[0]!r}")
        if np.any(times[1:] < times[:-1]):  # compared, not subtracted: a difference may overflow
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

    @property
    def gain(self) -> float:
        """sum |A|: the most the shaper amplifies any bounded input (1 for non-negative impulses)."""
        return float(np.abs(self.amplitudes).sum())

    @property
    def step_peak(self) -> float:
        """The largest |partial sum| of the amplitudes: the peak of its response to a unit step."""
        return float(np.max(np.abs(np.cumsum(self.amplitudes))))

    def __len__(self) -> int:
        return int(self.amplitudes.size)


#: an impulse sequence (amplitudes, times in s)
Impulses = tuple[FloatArray, FloatArray]


# ---------------------------------------------------------------------------------------------
# Parameter checks
# ---------------------------------------------------------------------------------------------


def _check_tolerance(vibration_tolerance: Any) -> float:
    """The vibration tolerance V_tol, a fraction in :data:`VIBRATION_TOLERANCE_RANGE`."""
    lo, hi = VIBRATION_TOLERANCE_RANGE
    return in_range("vibration_tolerance", vibration_tolerance, lo, hi, error=ShaperError, unit="(a fraction)")


def _check_insensitivity(insensitivity: Any) -> float:
    """The si band width I, a fraction of the design frequency in (0, :data:`MAX_INSENSITIVITY`]."""
    return in_range("insensitivity", insensitivity, 0.0, MAX_INSENSITIVITY, lo_open=True, error=ShaperError,
                    unit="(band width / design frequency)")


def _check_order(derivative_order: Any) -> int:
    """The ZV-D^n derivative order n, an integer in [0, :data:`MAX_DERIVATIVE_ORDER`]."""
    return integer("derivative_order", derivative_order, 0, MAX_DERIVATIVE_ORDER, ShaperError)
