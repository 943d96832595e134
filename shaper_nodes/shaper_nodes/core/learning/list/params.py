"""The LIST parameters (A1, T2), their structures and update formulas, and the learner's settings.

Seed 003 (Learning Input Shaping Technique) tunes the two free parameters of a two-impulse
sequence, A1 at t = 0 and A2 = 1 - A1 at T2, from the residual vibration of the previous
repetitions of a task, without a model of the plant. The paper's equations were lost in the
text extraction; docs/design/list.md reconstructs them and gives the reasoning summarised here.

Residual factor (:func:`lti_factor`). For an LTI mode (omega_n, zeta), sigma = zeta omega_n and
omega_d = omega_n sqrt(1 - zeta^2), the residual vibration of the shaped move is that of the
unshaped move multiplied, as a complex amplitude, by

    R(A1, T2) = A1 + (1 - A1) exp(sigma T2) exp(-j omega_d T2),

zero at A1n = 1 / (1 + K), K = exp(-zeta pi / sqrt(1 - zeta^2)), T2n = pi / omega_d (the paper's
eqs. (2)-(3)). Im R = -(1 - A1) exp(sigma T2) sin(omega_d T2) changes sign exactly at T2n
whatever A1 is; Re R changes sign at A1n when T2 = T2n. So M ~ |R| and phi = arg R (the phase
of the residual relative to the unshaped "original" vibration) say on which side of the right
value each parameter lies (the paper's Table 1).

Update formulas. With two trials of a phase the next value is the secant (eq. (5), both on one
side) or the M-weighted average (eq. (6), on both sides), which are the same secant step on the
signed measure s M (:func:`paper_step`, :func:`secant_step`).

Structures (:data:`STRUCTURES`): ``zv2`` is the paper's sequence; ``zvd3`` the same pair
convolved with itself (A1^2, 2 A1 A2, A2^2 at 0, T2, 2 T2; ZVD at the right values), tuned
through the same (A1, T2): its residual factor is R^2.

:class:`ListConfig` holds the learner's settings (rules in :data:`RULES`), validated on
construction.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.checks import finite, integer, number
from shaper_nodes.core.shaping import MAX_DURATION, Mode, Shaper, ShaperError

#: impulse structures, name -> description
STRUCTURES: dict[str, str] = {
    "zv2": "two impulses A1, 1 - A1 at 0, T2 (the paper's sequence)",
    "zvd3": "the two-impulse pair convolved with itself: A1^2, 2 A1 A2, A2^2 at 0, T2, 2 T2",
}
#: update rules, name -> description
RULES: dict[str, str] = {
    "components": "secant on Im rho (T2) and Re rho (A1), each linear in its own mismatch (default)",
    "paper": "the paper's eqs. (5)-(6): secant or M-weighted average of the last two trials by the side phi gives",
}


class ListError(ValueError):
    """Bad input to the learner, or a cycle it cannot learn from; the message names the problem."""


def number_value(name: str, value: Any) -> float:
    """``value`` as a float (:func:`~shaper_nodes.core.checks.number`), or :class:`ListError`."""
    return number(name, value, ListError)


def finite_value(name: str, value: Any) -> float:
    """``value`` as a finite float (:func:`~shaper_nodes.core.checks.finite`), or :class:`ListError`."""
    return finite(name, value, ListError)


def int_at_least(name: str, value: Any, lo: int) -> int:
    """``value`` as an int of at least ``lo``: an int or numpy integer (a float, even integral,
    or a boolean is refused)."""
    if not isinstance(value, (int, np.integer)):
        raise ListError(f"{name} must be an integer, got {value!r}")
    n = integer(name, value, error=ListError)
    if n < lo:
        raise ListError(f"{name} must be >= {lo}, got {value!r}")
    return n



def _power(structure: str) -> int:
    name = str(structure)
    if name not in STRUCTURES:
        raise ListError(f"unknown structure {structure!r}; known: {', '.join(STRUCTURES)}")
    return 1 if name == "zv2" else 2


@dataclass(frozen=True)
class ListParams:
    """The learned parameters: A1 (dimensionless) at T1 = 0 and A2 = 1 - A1 at T2 (s).

    Construction only converts to float; :meth:`check` (called by :meth:`shaper` and by the
    learner) validates 0 < A1 < 1 and 0 < T2 <= 30 s.
    """

    a1: float
    t2: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "a1", number_value("a1", self.a1))
        object.__setattr__(self, "t2", number_value("t2", self.t2))

    @property
    def a2(self) -> float:
        """Amplitude of the second impulse, 1 - A1."""
        return 1.0 - self.a1

    def check(self) -> ListParams:
        """Return self if valid, else raise :class:`ListError`."""
        if not (math.isfinite(self.a1) and 0.0 < self.a1 < 1.0):
            raise ListError(f"A1 must be in (0, 1), got {self.a1!r}")
        if not (math.isfinite(self.t2) and 0.0 < self.t2 <= MAX_DURATION / 2.0):
            raise ListError(f"T2 must be in (0, {MAX_DURATION / 2.0:g}] s, got {self.t2!r}")
        return self

    def impulses(self, structure: str = "zv2") -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(amplitudes, times in s) of the sequence of ``structure`` (:data:`STRUCTURES`)."""
        self.check()
        a1, a2, t2 = self.a1, self.a2, self.t2
        if _power(structure) == 1:
            return np.array([a1, a2]), np.array([0.0, t2])
        return np.array([a1 * a1, 2.0 * a1 * a2, a2 * a2]), np.array([0.0, t2, 2.0 * t2])

    def mode(self) -> Mode | None:
        """The mode these parameters cancel exactly (inverse ZV formulas); None if A1 < 0.5
        (negative damping) or the damping exceeds what :class:`Mode` accepts."""
        self.check()
        k = self.a2 / self.a1
        if k > 1.0:
            return None
        log_dec = -math.log(k)  # zeta pi / sqrt(1 - zeta^2)
        zeta = log_dec / math.hypot(math.pi, log_dec)
        omega = math.pi / self.t2 / math.sqrt(1.0 - zeta * zeta)
        try:
            return Mode(omega, zeta)
        except ShaperError:
            return None

    def t2_band(self, band: float) -> tuple[float, float]:
        """T2 bounds (s) that keep the learned frequency within ``band`` of these parameters' own.

        A two-impulse pair cancels the damped frequency 1 / (2 T2); bounding T2 to
        [T2 / (1 + band), T2 / (1 - band)] keeps that frequency within +-``band`` (a fraction) of the
        start's. Started from a mode that rings (the identifier's or the schedule's lowest mode), the
        learner then stays on that mode: on a multi-mode plant the single-mode measure M can otherwise
        be lowered by a pair between two modes that covers neither (on the arm, a factor started at
        12.15 Hz drifted to 14-15 Hz, docs/results/arm_learning.md).

        Raises
        ------
        ListError
            ``band`` not in (0, 1), or the parameters invalid.
        """
        self.check()
        b = finite_value("band", band)
        if not 0.0 < b < 1.0:
            raise ListError(f"band must be in (0, 1), got {band!r}")
        return self.t2 / (1.0 + b), min(self.t2 / (1.0 - b), MAX_DURATION / 2.0)

    def shaper(self, structure: str = "zv2") -> Shaper:
        """The impulse sequence as a ``custom`` :class:`Shaper` (design mode: :meth:`mode`)."""
        amps, times = self.impulses(structure)
        mode = self.mode()
        try:
            return Shaper(amps, times, "custom", (mode,) if mode is not None else ())
        except ShaperError as err:
            raise ListError(str(err)) from None

    @classmethod
    def from_mode(cls, mode: Mode) -> ListParams:
        """The zero-vibration parameters of a mode: A1 = 1 / (1 + K), T2 = pi / omega_d."""
        mode = getattr(mode, "mode", mode)  # a ModeFit
        if not isinstance(mode, Mode):
            raise ListError(f"from_mode needs a Mode, got {type(mode).__name__}")
        k = math.exp(-mode.zeta * math.pi / math.sqrt(1.0 - mode.zeta**2))
        return cls(1.0 / (1.0 + k), math.pi / mode.damped_omega).check()

    def as_dict(self) -> dict[str, float]:
        return {"a1": self.a1, "t2": self.t2}


def lti_factor(params: ListParams, sigma: float, omega_d: float, structure: str = "zv2") -> complex:
    """Residual factor of ``structure`` for an LTI mode: R = A1 + A2 e^{sigma T2} e^{-j omega_d T2}
    (``zv2``) or R^2 (``zvd3``). sigma = zeta omega_n (1/s), omega_d the damped frequency (rad/s).

    The shaped residual's complex amplitude, over a window after the shaped command has ended, is
    that of the unshaped residual times this factor (times relative to the move's start)."""
    r = params.a1 + params.a2 * cmath.exp(complex(sigma, -omega_d) * params.t2)
    return r ** _power(structure)


def secant_step(p_prev: float, p: float, e_prev: float, e: float) -> float | None:
    """The secant root step on a signed error e(p): ``p - e (p - p_prev) / (e - e_prev)``.

    Returns None when the slope (e - e_prev) / (p - p_prev) is not positive and finite (both
    learned errors grow with their parameter, so such a pair carries no usable step)."""
    dp, de = p - p_prev, e - e_prev
    if dp == 0.0 or de == 0.0 or not math.isfinite(de / dp) or de / dp <= 0.0:
        return None
    return p - e * dp / de


def paper_step(p_prev: float, p: float, m_prev: float, m: float, same_side: bool) -> float:
    """The paper's update from trials j-1 and j (M >= 0).

    Same side (eq. (5)), the secant on M: ``p_j - M_j (p_j - p_{j-1}) / (M_j - M_{j-1})``.
    Opposite sides (eq. (6)), the weighted average
    ``(M_{j-1} p_j + M_j p_{j-1}) / (M_{j-1} + M_j)``, which leans towards the trial with the
    smaller M. Both are :func:`secant_step` on the signed measure s M with s = +-1 the side.
    """
    if same_side:
        return p - m * (p - p_prev) / (m - m_prev)
    return (m_prev * p + m * p_prev) / (m_prev + m)


# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ListConfig:
    """Settings of the learner; validated on construction (:class:`ListError`).

    Attributes
    ----------
    highpass_hz : float
        Cut-off of the zero-phase high-pass applied to the residual window, Hz; 0: the window
        mean is removed instead. Keep it well below the mode (a factor 2 or more).
    window_delay : float or None
        The residual window starts this long after MOTION_END, s; None: the largest shaper
        duration the bounds allow (T2 upper bound, twice that for ``zvd3``).
    a1_bounds : (float, float)
        Bounds of A1, within (0, 1).
    t2_bounds : (float, float) or None
        Bounds of T2, s; None: 0.5 to 2 times the initial T2.
    max_step_a1 : float
        Largest change of A1 per cycle.
    max_step_t2 : float
        Largest change of T2 per cycle, as a fraction of the current T2.
    phase_trials : int
        Most steps of one parameter before switching to the other (Steps 2-3).
    switch_tol : float
        A phase ends when its last step was below this fraction of the parameter; the
        learner holds when neither parameter would move by that much.
    rule : str
        ``components`` (default) or ``paper`` (:data:`RULES`).
    structure : str
        ``zv2`` or ``zvd3`` (:data:`STRUCTURES`).
    rollback_factor : float
        M above this times the best M rolls back to the best parameters.
    patience : int
        After this many trials in a row without a new best M, the learner holds at the best
        parameters, and stays there until M at them rises above ``rollback_factor`` times the
        best (the plant changed); 0: never give up.
    saturation : float
        A cycle with any |acceleration| at or above this is rejected (saturated sensor), m/s^2.
    min_samples : int
        Fewest samples in the residual window.
    max_gap_periods : float
        Largest step between samples in the window, in median sample periods; larger is a gap.
    history : int
        Updates kept in the state (:meth:`ListLearner.to_dict`), for inspection only.
    """

    highpass_hz: float = 2.0
    window_delay: float | None = None
    a1_bounds: tuple[float, float] = (0.5, 0.95)
    t2_bounds: tuple[float, float] | None = None
    max_step_a1: float = 0.1
    max_step_t2: float = 0.25
    phase_trials: int = 4
    switch_tol: float = 0.01
    rule: str = "components"
    structure: str = "zv2"
    rollback_factor: float = 1.5
    patience: int = 6
    saturation: float = math.inf
    min_samples: int = 50
    max_gap_periods: float = 5.0
    history: int = 100

    def __post_init__(self) -> None:
        put = self._set
        hp = finite_value("highpass_hz", self.highpass_hz)
        if hp < 0.0:
            raise ListError(f"highpass_hz must be >= 0, got {hp!r}")
        put("highpass_hz", hp)
        if self.window_delay is not None:
            wd = finite_value("window_delay", self.window_delay)
            if wd < 0.0:
                raise ListError(f"window_delay must be >= 0 s, got {wd!r}")
            put("window_delay", wd)
        put("a1_bounds", self._bounds("a1_bounds", self.a1_bounds, 0.0, 1.0))
        if self.t2_bounds is not None:
            put("t2_bounds", self._bounds("t2_bounds", self.t2_bounds, 0.0, MAX_DURATION / 2.0))
        for name, hi in (("max_step_a1", 1.0), ("max_step_t2", 10.0)):
            v = finite_value(name, getattr(self, name))
            if not 0.0 < v <= hi:
                raise ListError(f"{name} must be in (0, {hi:g}], got {v!r}")
            put(name, v)
        put("phase_trials", int_at_least("phase_trials", self.phase_trials, 1))
        put("patience", int_at_least("patience", self.patience, 0))
        tol = finite_value("switch_tol", self.switch_tol)
        if not 0.0 <= tol < 1.0:
            raise ListError(f"switch_tol must be in [0, 1), got {tol!r}")
        put("switch_tol", tol)
        if self.rule not in RULES:
            raise ListError(f"unknown rule {self.rule!r}; known: {', '.join(RULES)}")
        _power(self.structure)
        rf = finite_value("rollback_factor", self.rollback_factor)
        if rf < 1.0:
            raise ListError(f"rollback_factor must be >= 1, got {rf!r}")
        put("rollback_factor", rf)
        sat = number_value("saturation", self.saturation)
        if not sat > 0.0:  # also NaN
            raise ListError(f"saturation must be > 0 m/s^2 (inf: no limit), got {self.saturation!r}")
        put("saturation", sat)
        put("min_samples", int_at_least("min_samples", self.min_samples, 2))
        gap = finite_value("max_gap_periods", self.max_gap_periods)
        if gap <= 1.0:
            raise ListError(f"max_gap_periods must be > 1, got {gap!r}")
        put("max_gap_periods", gap)
        put("history", int_at_least("history", self.history, 0))

    def _set(self, name: str, value: object) -> None:
        object.__setattr__(self, name, value)

    @staticmethod
    def _bounds(name: str, value: Any, lo: float, hi: float) -> tuple[float, float]:
        try:
            a, b = value
        except (TypeError, ValueError):
            raise ListError(f"{name} must be (low, high), got {value!r}") from None
        a, b = finite_value(name, a), finite_value(name, b)
        if not lo < a < b or b > hi or (hi == 1.0 and b >= hi):
            raise ListError(f"{name} must satisfy {lo:g} < low < high {'<' if hi == 1.0 else '<='} {hi:g},"
                            f" got {value!r}")
        return (a, b)

    @property
    def power(self) -> int:
        """Residual factor exponent of the structure: 1 (zv2) or 2 (zvd3)."""
        return _power(self.structure)

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (infinite saturation as None)."""
        return {
            "highpass_hz": self.highpass_hz, "window_delay": self.window_delay,
            "a1_bounds": list(self.a1_bounds),
            "t2_bounds": None if self.t2_bounds is None else list(self.t2_bounds),
            "max_step_a1": self.max_step_a1, "max_step_t2": self.max_step_t2,
            "phase_trials": self.phase_trials, "switch_tol": self.switch_tol, "rule": self.rule,
            "structure": self.structure, "rollback_factor": self.rollback_factor, "patience": self.patience,
            "saturation": self.saturation if math.isfinite(self.saturation) else None,
            "min_samples": self.min_samples, "max_gap_periods": self.max_gap_periods, "history": self.history,
        }

    @classmethod
    def from_dict(cls, d: Any) -> ListConfig:
        """Inverse of :meth:`as_dict`; :class:`ListError` on unknown or missing keys or bad values."""
        if not isinstance(d, dict):
            raise ListError(f"config must be a dictionary, got {type(d).__name__}")
        names = set(cls.__dataclass_fields__)
        if set(d) != names:
            raise ListError(f"config keys differ: missing {sorted(names - set(d))}, unknown {sorted(set(d) - names)}")
        kw = dict(d)
        if kw["saturation"] is None:
            kw["saturation"] = math.inf
        for key in ("a1_bounds", "t2_bounds"):
            if isinstance(kw[key], list):
                kw[key] = tuple(kw[key])
        return cls(**kw)

