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

Drift is a change: the baseline
-------------------------------
A mode outside the band from the first cycle on has not drifted: the arm behind a position loop shows the
loop's damped pole (30-41 Hz, zeta 0.2-0.7 on the demo's arm) in every cycle, and once a learner has taken
the arm's modes out of the residual it is the strongest thing left. The watch therefore keeps a
:class:`Baseline`: every mode identified in its first ``baseline_cycles`` watched cycles (at any strength,
with its uncertainty; a cycle where nothing was identified counts as one). The node gives it the modes sharp
enough to rate (``watch.max_uncertainty``): a fit at the noise floor, uncertain by 10 % or more, would
otherwise open a window wide enough to take a payload's shift for the same mode. :func:`rate_modes` sets
aside a mode outside the band that is the same mode as a baseline mode itself outside the band
(:meth:`Baseline.nearest`): it does not count toward ``confirm``, and when nothing else is left the rating
says so ("present since the move's first cycles: not drift"). The same-mode rule (:func:`same_mode`) is in
frequency and damping:

- frequency within ``sigmas`` combined one-sigma uncertainties plus ``max(margin, zeta_b)`` of the baseline
  mode's frequency f_b: zeta_b f_b is the half-power half-width of its resonance, within which two fits of
  one damped pole cannot be told apart (measured on the arm: the loop pole's fitted frequency moved 31.9 ->
  41.1 Hz at zeta 0.65 in one move as MRILC learned; the arm's lightly damped modes (zeta 0.03-0.08) get the
  ``margin``, under the 5-30 % a payload moves them);
- damping within a factor :data:`DAMPING_FACTOR` (plus ``sigmas`` uncertainties): a payload lowers a lightly
  damped mode towards a damped pole's frequency but does not make it a damped pole (17.0 Hz at zeta 0.05 is
  not the 34 Hz pole at zeta 0.55, though within its half-width).

A mode that is the same as an *in-band* baseline mode (the nearest match) has moved out of the band: drift,
rated as before.

A baseline sees only the modes the first cycles show: a learner that takes the strong modes out of the
residual uncovers weaker ones (on the demo's arm, 89.6 Hz at zeta 0.24 in pick -> home's third MRILC cycle,
found in no earlier cycle of that move). With ``max_shift`` a mode more than that fraction above the
shaper's highest design mode is set aside as well: a payload moves the modes a shaper was designed for by
5-30 % (``max_shift`` 0.3 by default in the node), so a mode far above all of them is none of them, moved.
Modes below are all rated (a heavier payload lowers a mode below every design mode: the strongest-mode
check). The baseline is the plant's, not the shaper's: a move's watch keeps it; the active shaper's
watch takes a new one when the active shaper changes (a retune for a new payload makes the old modes moot).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from shaper_nodes.core.shaping.vibration import percentage_vibration

from .modes import ModeFit

#: the band is searched from this fraction to this multiple of the reference frequency
BAND_SEARCH = (0.2, 3.0)
#: grid points per unit of frequency ratio in the search (resolution 0.05 % of the reference)
BAND_POINTS_PER_RATIO = 2000
#: the same mode: damping ratios within this factor of each other (plus the uncertainties)
DAMPING_FACTOR = 2.0
#: the same mode: within this many combined one-sigma uncertainties (plus the margins)
BASELINE_SIGMAS = 3.0


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


def same_mode(mode: ModeFit, base: ModeFit, margin: float, sigmas: float = BASELINE_SIGMAS) -> float:
    """How far ``mode`` is from the baseline mode ``base``, in units of the same-mode window (module docstring):
    <= 1 is the same mode. The larger of the frequency and the damping distance.

    Parameters
    ----------
    mode, base : ModeFit
        An identified mode and a baseline mode.
    margin : float
        Relative frequency margin, fraction (the window is at least this fraction of the base's frequency).
    sigmas : float
        Combined one-sigma uncertainties added to both windows.
    """
    f_win = sigmas * math.hypot(mode.omega_std, base.omega_std) + max(margin, max(base.zeta, 0.0)) * base.omega
    z_lo, z_hi = sorted((max(mode.zeta, 0.0), max(base.zeta, 0.0)))
    z_win = sigmas * math.hypot(mode.zeta_std, base.zeta_std) + (DAMPING_FACTOR - 1.0) * z_lo
    df = abs(mode.omega - base.omega) / f_win if f_win > 0 else math.inf
    dz = (z_hi - z_lo) / z_win if z_win > 0 else (0.0 if z_hi == z_lo else math.inf)
    return max(df, dz)


@dataclass
class Baseline:
    """The modes identified in a watch's first ``cycles`` watched cycles (module docstring).

    Attributes
    ----------
    cycles : int
        Cycles the baseline is taken from (0: none; every mode outside the band is rated).
    margin : float
        Relative frequency margin of the same-mode rule, fraction.
    modes : list of ModeFit
        The modes taken so far.
    taken : int
        Cycles taken so far.
    """

    cycles: int = 0
    margin: float = 0.03
    modes: list[ModeFit] = field(default_factory=list)
    taken: int = 0

    def __post_init__(self) -> None:
        if self.cycles < 0:
            raise ValueError(f"baseline cycles must be >= 0, got {self.cycles}")
        if not (math.isfinite(self.margin) and 0.0 <= self.margin < 1.0):
            raise ValueError(f"baseline margin must be in [0, 1), got {self.margin!r}")

    @property
    def taking(self) -> bool:
        """Still taking cycles."""
        return self.taken < self.cycles

    def take(self, modes: Sequence[ModeFit]) -> bool:
        """Add a watched cycle's modes while still taking; returns whether taken. A cycle in which nothing was
        identified counts too: the baseline closes after ``cycles`` watched cycles, so a mode that comes later
        (a payload changed after them) is never in it."""
        if not self.taking:
            return False
        self.modes.extend(m for m in modes if m.omega > 0 and math.isfinite(m.omega))
        self.taken += 1
        return True

    def restart(self) -> None:
        """Forget the modes and take new ones."""
        self.modes, self.taken = [], 0

    def nearest(self, mode: ModeFit) -> ModeFit | None:
        """The baseline mode ``mode`` is the same as (the nearest within the window), or None."""
        scored = [(same_mode(mode, b, self.margin), i) for i, b in enumerate(self.modes)]
        best = min(scored, default=(math.inf, -1))
        return self.modes[best[1]] if best[0] <= 1.0 else None

    def describe(self) -> str:
        """The baseline in words."""
        return ", ".join(f"{b.hz:.4g} Hz zeta {b.zeta:.2g}" for b in sorted(self.modes, key=lambda m: m.omega)) \
            or "none"


@dataclass(frozen=True)
class Aside:
    """A mode outside the band that does not count as drift, and why (:func:`rate_modes`).

    Attributes
    ----------
    check : ModeCheck
        Its check.
    baseline : ModeFit or None
        The baseline mode outside the band it is the same as (present since the first cycles), or None.
    above_hz : float or None
        Else the frequency it is above, Hz: the shaper's highest design mode plus ``max_shift`` of it.
    """

    check: ModeCheck
    baseline: ModeFit | None = None
    above_hz: float | None = None

    def why(self, since: str = "the first cycles") -> str:
        """Why it does not count, in words."""
        if self.baseline is not None:
            return f"present since {since} ({self.baseline.hz:.4g} Hz zeta {self.baseline.zeta:.2g} then)"
        return (f"above {self.above_hz:.4g} Hz, farther above the shaper's highest design mode than a payload moves"
                " a mode")


@dataclass(frozen=True)
class Rating:
    """A cycle's rating (:func:`rate_modes`).

    Attributes
    ----------
    check : ModeCheck
        The check that decides: the worst of the modes rated, or, when every mode was set aside, the worst of
        those.
    aside : Aside or None
        ``check`` set aside (it then does not count as drift), or None.
    set_aside : tuple of Aside
        Every mode outside the band set aside.
    """

    check: ModeCheck
    aside: Aside | None = None
    set_aside: tuple[Aside, ...] = ()

    @property
    def drift(self) -> bool:
        """The rating counts as a check outside the band (toward ``confirm``)."""
        return self.aside is None and not self.check.inside

    def describe(self, shaper: str = "the active shaper", since: str = "the first cycles") -> str:
        """The numbers in one line; a mode set aside says why."""
        text = self.check.describe(shaper)
        if self.aside is not None:
            return f"{text}; {self.aside.why(since)}: not drift"
        if self.set_aside:
            text += "; set aside: " + ", ".join(f"{a.check.mode_hz:.4g} Hz ({a.why(since)})" for a in self.set_aside)
        return text


def rate_modes(amplitudes: Sequence[float] | np.ndarray, times: Sequence[float] | np.ndarray,
               design_hz: Sequence[float], modes: Sequence[ModeFit], tolerance: float,
               baseline: Baseline | None = None, max_shift: float | None = None) -> Rating | None:
    """Rate a cycle's identified ``modes`` against the shaper (None: no mode to rate).

    A mode outside the band is set aside (:class:`Aside`) if it is the same as a baseline mode outside the band
    (:meth:`Baseline.nearest`; the module docstring), or, with ``max_shift`` (fraction) and design modes, if it
    lies more than ``max_shift`` above the highest design frequency: no payload moves a mode the shaper was
    designed for that far (a lighter one raises modes by as much as a heavier one lowers them). Of the rest,
    the mode nearest each design frequency (Hz, ``design_hz``) and the strongest (``amplitude``: the one that
    rings most, which a payload may have moved below every design mode) are checked (:func:`check_mode`); the
    one with the largest V decides. When every mode was set aside, the worst of them decides, marked so.
    """
    modes = [m for m in modes if m.omega > 0]
    if not modes:
        return None

    def check(m: ModeFit) -> ModeCheck:
        return check_mode(amplitudes, times, design_hz, m, tolerance)

    top = (1.0 + max_shift) * max(design_hz) if max_shift is not None and len(design_hz) else math.inf
    aside: list[Aside] = []
    rest: list[ModeFit] = []
    for m in modes:
        c = check(m)
        base = baseline.nearest(m) if baseline is not None and not c.inside else None
        if base is not None and not check(base).inside:
            aside.append(Aside(c, baseline=base))
        elif not c.inside and m.hz > top:
            aside.append(Aside(c, above_hz=top))
        else:
            rest.append(m)
    if not rest:
        worst = max(aside, key=lambda a: a.check.vibration)
        return Rating(worst.check, worst, tuple(aside))
    chosen = [min(rest, key=lambda m: abs(m.hz - hz)) for hz in design_hz]
    chosen.append(max(rest, key=lambda m: m.amplitude))
    return Rating(max((check(m) for m in dict.fromkeys(chosen)), key=lambda c: c.vibration), None, tuple(aside))


@dataclass
class DriftWatch:
    """Successive checks of the identified mode; a warning after ``confirm`` out-of-band checks in a row.

    Attributes
    ----------
    confirm : int
        Checks in a row that must find the mode outside its band before :attr:`warning` is set.
    baseline : Baseline
        The modes present since the first cycles (module docstring; ``Baseline()``: none, every mode rated).
    max_shift : float or None
        Modes more than this fraction above the shaper's highest design mode are not rated
        (:func:`rate_modes`); None: every mode is.
    """

    confirm: int = 2
    outside_in_a_row: int = 0
    last: ModeCheck | None = None
    checks: int = 0
    baseline: Baseline = field(default_factory=Baseline)
    max_shift: float | None = None

    def __post_init__(self) -> None:
        if self.confirm < 1:
            raise ValueError(f"confirm must be >= 1 check, got {self.confirm}")
        if self.max_shift is not None and not (math.isfinite(self.max_shift) and self.max_shift >= 0.0):
            raise ValueError(f"max_shift must be a fraction >= 0, got {self.max_shift!r}")

    def update(self, check: ModeCheck | Rating) -> bool:
        """Take one check (a :class:`Rating` whose mode is set aside counts as inside);
        returns :attr:`warning` after it."""
        drift = check.drift if isinstance(check, Rating) else not check.inside
        self.checks += 1
        self.last = check.check if isinstance(check, Rating) else check
        self.outside_in_a_row = self.outside_in_a_row + 1 if drift else 0
        return self.warning

    def quiet(self) -> bool:
        """A cycle whose residual holds no mode sharp enough to rate (the shaper leaves the noise floor):
        the mode is where the shaper works, so the count starts again; returns :attr:`warning` (False)."""
        self.checks += 1
        self.outside_in_a_row = 0
        return self.warning

    def reset(self, baseline: bool = False) -> None:
        """Forget the checks (the active shaper changed: its band is another); with ``baseline``, the baseline
        too (a new one is taken from the next cycles)."""
        self.outside_in_a_row, self.last = 0, None
        if baseline:
            self.baseline.restart()

    @property
    def warning(self) -> bool:
        """The mode has been outside the band for ``confirm`` checks in a row."""
        return self.outside_in_a_row >= self.confirm
