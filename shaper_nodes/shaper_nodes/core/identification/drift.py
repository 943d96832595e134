"""Drift of a vibration mode against the active shaper: is the mode still where the shaper works?

An input shaper leaves little residual vibration only near the modes it was designed for. Its
percentage vibration V(omega, zeta) (:func:`~shaper_nodes.core.shaping.vibration.percentage_vibration`)
stays under a tolerance V_tol over a band of frequencies around each design mode: the
*working band*. A payload change, a loosening joint or wear moves the robot's mode; once the
mode identified from ordinary cycles leaves the working band, the shaper no longer does its job
and should be retuned.

:func:`working_band` finds the band (Hz) at a damping ratio: the connected interval of
frequencies around a reference frequency where V <= V_tol, searched on a fine grid from
``BAND_SEARCH[0]`` to ``BAND_SEARCH[1]`` times the reference. :func:`check_mode` rates one
identified mode against the active shaper: V at the mode and whether it lies inside the band.
:class:`DriftWatch` keeps the verdicts of successive cycles and calls for a warning once
``confirm`` checks in a row find the mode outside its band (so one noisy cycle raises nothing),
and clears it at the first check inside.

Which band: the shaper's design mode nearest the identified mode gives the reference frequency
(a scheduled or recommended shaper says what it was designed on); a shaper without design
modes (a custom or learned impulse sequence) takes the identified mode itself as reference, so
its band is where V stays under the tolerance around the mode, if any. An identity shaper
("none", one impulse) shapes nothing: it has no band and is not watched.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.shaping.vibration import percentage_vibration

from .modes import ModeFit

#: the band is searched from this fraction to this multiple of the reference frequency
BAND_SEARCH = (0.2, 3.0)
#: grid points per unit of frequency ratio in the search (resolution 0.05 % of the reference)
BAND_POINTS_PER_RATIO = 2000


@dataclass(frozen=True)
class ModeCheck:
    """One identified mode against the active shaper.

    Attributes
    ----------
    mode_hz, zeta : float
        The identified mode: natural frequency (Hz) and damping ratio.
    mode_std_hz : float
        Its one-sigma frequency uncertainty, Hz.
    vibration : float
        V of the active shaper at the identified mode, fraction.
    tolerance : float
        V_tol, fraction.
    band_hz : (float, float) or None
        The working band, Hz (None: V exceeds the tolerance at the reference frequency itself).
    reference_hz : float
        The frequency the band is taken around (a design mode, or the identified mode).
    """

    mode_hz: float
    zeta: float
    mode_std_hz: float
    vibration: float
    tolerance: float
    band_hz: tuple[float, float] | None
    reference_hz: float

    @property
    def inside(self) -> bool:
        """The mode lies inside the working band (V at the mode within the tolerance)."""
        return self.band_hz is not None and self.band_hz[0] <= self.mode_hz <= self.band_hz[1] \
            and self.vibration <= self.tolerance

    def describe(self, shaper: str = "the active shaper") -> str:
        """The numbers in one line (what a warning says); ``shaper`` names the shaper rated against, in words."""
        band = (f"the band {self.band_hz[0]:.4g}-{self.band_hz[1]:.4g} Hz" if self.band_hz is not None
                else f"no band (V > {100 * self.tolerance:.3g} % already at {self.reference_hz:.4g} Hz)")
        where = "inside" if self.inside else "outside"
        return (f"mode {self.mode_hz:.4g} Hz (+-{self.mode_std_hz:.2g}) zeta {self.zeta:.3g} is {where} {band}"
                f" where {shaper} keeps V under {100 * self.tolerance:.3g} % (designed at"
                f" {self.reference_hz:.4g} Hz); V at the mode {100 * self.vibration:.3g} %")


def working_band(amplitudes: Sequence[float] | np.ndarray, times: Sequence[float] | np.ndarray,
                 reference_hz: float, zeta: float, tolerance: float) -> tuple[float, float] | None:
    """The connected band of frequencies (Hz) around ``reference_hz`` where V <= ``tolerance``.

    Parameters
    ----------
    amplitudes, times : array_like
        The impulse sequence (times in s).
    reference_hz : float
        Frequency the band must contain, Hz (> 0).
    zeta : float
        Damping ratio V is evaluated at, in [0, 1).
    tolerance : float
        V_tol, fraction in (0, 1).

    Returns
    -------
    (float, float) or None
        Lower and upper edge, Hz (an edge at the end of the search range is reported as that
        end); None if V exceeds the tolerance at ``reference_hz`` itself.
    """
    if not (math.isfinite(reference_hz) and reference_hz > 0.0):
        raise ValueError(f"reference frequency must be finite and > 0 Hz, got {reference_hz!r}")
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"vibration tolerance must be in (0, 1), got {tolerance!r}")
    lo, hi = BAND_SEARCH
    n = int((hi - lo) * BAND_POINTS_PER_RATIO) + 1
    ratios = np.linspace(lo, hi, n)
    v = percentage_vibration(np.asarray(amplitudes, float), np.asarray(times, float),
                             2 * math.pi * reference_hz * ratios, zeta)
    i0 = int(np.argmin(np.abs(ratios - 1.0)))
    if v[i0] > tolerance:
        return None
    below = v <= tolerance
    a = i0
    while a > 0 and below[a - 1]:
        a -= 1
    b = i0
    while b < n - 1 and below[b + 1]:
        b += 1
    return float(reference_hz * ratios[a]), float(reference_hz * ratios[b])


def check_mode(amplitudes: Sequence[float] | np.ndarray, times: Sequence[float] | np.ndarray,
               design_hz: Sequence[float], mode: ModeFit, tolerance: float) -> ModeCheck:
    """Rate the identified ``mode`` against the shaper (see the module docstring).

    ``design_hz`` are the shaper's design frequencies, Hz (may be empty).
    """
    mode_hz = mode.omega / (2 * math.pi)
    ref = min(design_hz, key=lambda f: abs(f - mode_hz)) if len(design_hz) else mode_hz
    zeta = min(max(mode.zeta, 0.0), 0.99)
    v = float(percentage_vibration(np.asarray(amplitudes, float), np.asarray(times, float), mode.omega, zeta))
    band = working_band(amplitudes, times, float(ref), zeta, tolerance)
    return ModeCheck(mode_hz, mode.zeta, mode.omega_std / (2 * math.pi), v, tolerance, band, float(ref))


@dataclass
class DriftWatch:
    """Successive checks of the identified mode; a warning after ``confirm`` out-of-band checks in a row.

    Attributes
    ----------
    confirm : int
        Checks in a row that must find the mode outside its band before :attr:`warning` is set.
    """

    confirm: int = 2
    outside_in_a_row: int = 0
    last: ModeCheck | None = None
    checks: int = 0

    def __post_init__(self) -> None:
        if self.confirm < 1:
            raise ValueError(f"confirm must be >= 1 check, got {self.confirm}")

    def update(self, check: ModeCheck) -> bool:
        """Take one check; returns :attr:`warning` after it."""
        self.checks += 1
        self.last = check
        self.outside_in_a_row = 0 if check.inside else self.outside_in_a_row + 1
        return self.warning

    def quiet(self) -> bool:
        """A cycle whose residual holds no mode sharp enough to rate (the shaper leaves the noise floor):
        the mode is where the shaper works, so the count starts again; returns :attr:`warning` (False)."""
        self.checks += 1
        self.outside_in_a_row = 0
        return self.warning

    def reset(self) -> None:
        """Forget the checks (the active shaper changed: its band is another)."""
        self.outside_in_a_row, self.last = 0, None

    @property
    def warning(self) -> bool:
        """The mode has been outside the band for ``confirm`` checks in a row."""
        return self.outside_in_a_row >= self.confirm
