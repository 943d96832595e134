"""Learning Input Shaping Technique (LIST): a two-impulse shaper tuned cycle by cycle.

Seed 003 (Learning Input Shaping Technique) tunes the two free parameters of a two-impulse
sequence, A1 at t = 0 and A2 = 1 - A1 at T2, from the residual vibration of the previous
repetitions of a task, without a model of the plant. The paper's equations were lost in the
text extraction; docs/list.md reconstructs them and gives the reasoning summarised here.

Residual factor. For an LTI mode (omega_n, zeta), sigma = zeta omega_n and omega_d =
omega_n sqrt(1 - zeta^2), the residual vibration of the shaped move is that of the unshaped
move multiplied, as a complex amplitude, by

    R(A1, T2) = A1 + (1 - A1) exp(sigma T2) exp(-j omega_d T2),

zero at A1n = 1 / (1 + K), K = exp(-zeta pi / sqrt(1 - zeta^2)), T2n = pi / omega_d (the paper's
eqs. (2)-(3)). Im R = -(1 - A1) exp(sigma T2) sin(omega_d T2) changes sign exactly at T2n
whatever A1 is; Re R changes sign at A1n when T2 = T2n. So M ~ |R| and phi = arg R (the phase
of the residual relative to the unshaped "original" vibration) say on which side of the right
value each parameter lies (the paper's Table 1).

Measurement (:func:`measure`). The residual window runs from ``motion_end + window_delay``
(after the shaped command has ended) to the cycle's end, times relative to the cycle's START.
Over it, the projected accelerometer signal is high-pass filtered (zero-phase Butterworth,
window only, so the operation stays linear in the window's data) and M is its RMS (eq. (4)).
The complex ratio rho ~ R is the least-squares fit of the filtered signal by the filtered
unshaped reference ``y_u(t)`` and its copy advanced by a quarter damped period
``y_u(t + tau)``: for an LTI plant the shaped residual lies exactly in that span, so
``rho = a + b exp((-sigma + j omega_d) tau)`` equals R; phi = arg rho.

Updates (:class:`ListLearner`). Steps 1-4 of the paper: vary T2 with A1 fixed until M is
minimal, then A1 with the best T2, and repeat. With two trials of a phase the next value is
the secant (eq. (5), both on one side) or the M-weighted average (eq. (6), on both sides),
which are the same secant step on the signed measure s M (:func:`paper_step`,
:func:`secant_step`). The default rule ``components`` applies the secant to the signed
components Im rho (for T2) and Re rho (for A1) instead, each linear in its own parameter's
mismatch and free of the noise in M. The first step of a phase uses the LTI sensitivity of R.
Where phi's relation fails (M rose against its prediction, or the error fell as the parameter
rose: strongly nonlinear or saturating plants), the phase minimises M alone (bracketing and
parabolic steps in M^2). Safeguards: bounds, maximum step, rejection of incomplete, saturated
or non-finite cycles, rollback to the best parameters when M grows, smaller steps after failed
ones, and holding at the best point once no step of at least ``switch_tol`` is wanted or
allowed.

Structures (:data:`STRUCTURES`): ``zv2`` is the paper's sequence; ``zvd3`` the same pair
convolved with itself (A1^2, 2 A1 A2, A2^2 at 0, T2, 2 T2; ZVD at the right values), tuned
through the same (A1, T2): its residual factor is R^2, and the square root nearest a
prediction (continued from the previous trial with the LTI model) recovers R.

Everything is deterministic: the same inputs give the same updates bit for bit, and
:meth:`ListLearner.to_dict` / :meth:`ListLearner.from_dict` carry the full state exactly.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.signal import butter, sosfiltfilt

from shaper_nodes.core.identification import IdentificationError, identify
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
#: the actions a ListUpdate reports
ACTIONS = ("reference", "first_step", "secant", "weighted", "search", "switch", "rollback", "rejected", "hold")
#: version of the dictionaries of :meth:`ListLearner.to_dict`
STATE_VERSION = 1
#: order of the Butterworth high-pass (applied forwards and backwards: zero phase)
HIGHPASS_ORDER = 2
#: a measured cycle's median sample step may differ from the reference's by this fraction
MAX_RATE_MISMATCH = 0.25
#: a cycle's motion_end may differ from the reference's by this many damped periods
MAX_MOTION_SHIFT = 0.05
#: components rule: a secant slope outside [1/SLOPE_BAND, SLOPE_BAND] times the LTI sensitivity
#: (noise between close trials) is replaced by the sensitivity step
SLOPE_BAND = 4.0
#: a residual with |rho| below this many standard errors is at the noise floor: nothing to learn
NOISE_SIGMAS = 3.0
#: smallest step scale after rollbacks
MIN_STEP_SCALE = 1.0 / 1024.0
#: relative tolerance when comparing the parameters a cycle ran with to those proposed
SAME_PARAMS_TOL = 1e-9
#: tolerance of the index arithmetic on sample grids, in samples
_GRID_EPS = 1e-6

_PARAMS = ("t2", "a1")


class ListError(ValueError):
    """Bad input to the learner, or a cycle it cannot learn from; the message names the problem."""


def _num(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ListError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ListError(f"{name} must be a number, got {value!r}") from None


def _finite(name: str, value: Any) -> float:
    x = _num(name, value)
    if not math.isfinite(x):
        raise ListError(f"{name} must be finite, got {value!r}")
    return x


def _int(name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ListError(f"{name} must be an integer, got {value!r}")
    if int(value) < lo:
        raise ListError(f"{name} must be >= {lo}, got {value!r}")
    return int(value)


# ---------------------------------------------------------------------------------------------
# Parameters and structures
# ---------------------------------------------------------------------------------------------


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
        object.__setattr__(self, "a1", _num("a1", self.a1))
        object.__setattr__(self, "t2", _num("t2", self.t2))

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

    def impulses(self, structure: str = "zv2") -> tuple[np.ndarray, np.ndarray]:
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
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        hp = _finite("highpass_hz", self.highpass_hz)
        if hp < 0.0:
            raise ListError(f"highpass_hz must be >= 0, got {hp!r}")
        put("highpass_hz", hp)
        if self.window_delay is not None:
            wd = _finite("window_delay", self.window_delay)
            if wd < 0.0:
                raise ListError(f"window_delay must be >= 0 s, got {wd!r}")
            put("window_delay", wd)
        put("a1_bounds", self._bounds("a1_bounds", self.a1_bounds, 0.0, 1.0))
        if self.t2_bounds is not None:
            put("t2_bounds", self._bounds("t2_bounds", self.t2_bounds, 0.0, MAX_DURATION / 2.0))
        for name, hi in (("max_step_a1", 1.0), ("max_step_t2", 10.0)):
            v = _finite(name, getattr(self, name))
            if not 0.0 < v <= hi:
                raise ListError(f"{name} must be in (0, {hi:g}], got {v!r}")
            put(name, v)
        put("phase_trials", _int("phase_trials", self.phase_trials, 1))
        put("patience", _int("patience", self.patience, 0))
        tol = _finite("switch_tol", self.switch_tol)
        if not 0.0 <= tol < 1.0:
            raise ListError(f"switch_tol must be in [0, 1), got {tol!r}")
        put("switch_tol", tol)
        if self.rule not in RULES:
            raise ListError(f"unknown rule {self.rule!r}; known: {', '.join(RULES)}")
        _power(self.structure)
        rf = _finite("rollback_factor", self.rollback_factor)
        if rf < 1.0:
            raise ListError(f"rollback_factor must be >= 1, got {rf!r}")
        put("rollback_factor", rf)
        sat = _num("saturation", self.saturation)
        if not sat > 0.0:  # also NaN
            raise ListError(f"saturation must be > 0 m/s^2 (inf: no limit), got {self.saturation!r}")
        put("saturation", sat)
        put("min_samples", _int("min_samples", self.min_samples, 2))
        gap = _finite("max_gap_periods", self.max_gap_periods)
        if gap <= 1.0:
            raise ListError(f"max_gap_periods must be > 1, got {gap!r}")
        put("max_gap_periods", gap)
        put("history", _int("history", self.history, 0))

    @staticmethod
    def _bounds(name: str, value: Any, lo: float, hi: float) -> tuple[float, float]:
        try:
            a, b = value
        except (TypeError, ValueError):
            raise ListError(f"{name} must be (low, high), got {value!r}") from None
        a, b = _finite(name, a), _finite(name, b)
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


# ---------------------------------------------------------------------------------------------
# Signals: checks, resampling, filtering
# ---------------------------------------------------------------------------------------------


def _direction(direction: Any) -> float:
    d = _finite("direction", direction)
    if d == 0.0:
        raise ListError("direction must be +1 or -1 (its sign is used), got 0")
    return math.copysign(1.0, d)


def _arrays(times: Any, accel: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        t = np.asarray(times, dtype=float)
        a = np.asarray(accel, dtype=float)
    except (TypeError, ValueError) as err:
        raise ListError(f"times and accel must be numeric arrays: {err}") from None
    if t.ndim != 1:
        raise ListError(f"times must be one-dimensional, got shape {t.shape}")
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] == 0:
        raise ListError(f"accel must be (N,) or (N, k), got shape {np.shape(accel)}")
    if a.shape[0] != t.size:
        raise ListError(f"times and accel lengths differ: {t.size} times, {a.shape[0]} samples")
    if t.size < 2:
        raise ListError(f"incomplete cycle: {t.size} samples")
    bad_t, bad_a = ~np.isfinite(t), ~np.all(np.isfinite(a), axis=1)
    if bad_t.any() or bad_a.any():
        i = int(np.flatnonzero(bad_t | bad_a)[0])
        raise ListError(f"non-finite data: {'time' if bad_t[i] else 'acceleration'} at sample {i}"
                        f" ({int(bad_t.sum())} bad times, {int(bad_a.sum())} bad acceleration samples)")
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        i = int(np.flatnonzero(steps <= 0.0)[0])
        raise ListError(f"times not strictly increasing: {t[i]:.6g} s then {t[i + 1]:.6g} s at sample {i}")
    return t, a


def _check_cycle(t: np.ndarray, a: np.ndarray, window: tuple[float, float], config: ListConfig) -> float:
    """Saturation, samples and gaps in the window; returns the median sample step, s."""
    peak = float(np.max(np.abs(a)))
    if peak >= config.saturation:
        raise ListError(f"saturated: |acceleration| reached {peak:.6g}, the sensor limit is {config.saturation:g}")
    dt = float(np.median(np.diff(t)))
    w0, w1 = window
    lo, hi = int(np.searchsorted(t, w0, "left")), int(np.searchsorted(t, w1, "right"))
    if hi - lo < config.min_samples:
        raise ListError(f"incomplete cycle: {hi - lo} samples in the residual window {w0:.4g}-{w1:.4g} s,"
                        f" need {config.min_samples}")
    limit = config.max_gap_periods * dt
    if t[0] > w0 + limit:
        raise ListError(f"incomplete cycle: data start at {t[0]:.4g} s, after the window start {w0:.4g} s")
    if t[-1] < w1 - limit:
        raise ListError(f"incomplete cycle: data end at {t[-1]:.4g} s, before the window end {w1:.4g} s")
    steps = np.diff(t[max(lo - 1, 0) : hi + 1])
    if steps.size and steps.max() > limit:
        i = int(np.argmax(steps)) + max(lo - 1, 0)
        raise ListError(f"incomplete cycle: a gap of {steps.max():.4g} s after {t[i]:.4g} s"
                        f" (more than {config.max_gap_periods:g} sample periods of {dt:.4g} s)")
    return dt


def _highpass(y: np.ndarray, dt: float, hz: float) -> np.ndarray:
    """Zero-phase high-pass of the window along axis 0; hz = 0: the window mean removed.

    Butterworth forwards and backwards over the window extended by its even reflection (as
    long as the window). Both are linear in the window's samples. The even reflection matters
    with noise: the default odd extension (2 x[0] - x[k]) and a short pad let the noise of the
    edge samples through the filter's transient, coherently over the first samples, where the
    residual is largest; it doubled the noise of rho in tests."""
    if hz == 0.0:
        return y - y.mean(axis=0)
    if hz >= 0.45 / dt:
        raise ListError(f"highpass_hz {hz:g} Hz is not below the Nyquist frequency {0.5 / dt:g} Hz")
    sos = np.array(_butter(hz, dt))  # a writable copy: sosfilt refuses read-only coefficients
    return sosfiltfilt(sos, y, axis=0, padtype="even", padlen=y.shape[0] - 1)


@lru_cache(maxsize=16)
def _butter(hz: float, dt: float) -> tuple[tuple[float, ...], ...]:
    sos = butter(HIGHPASS_ORDER, hz, btype="highpass", fs=1.0 / dt, output="sos")
    return tuple(tuple(float(x) for x in row) for row in sos)


def _ceil(x: float) -> int:
    return math.ceil(x - _GRID_EPS)


def _floor(x: float) -> int:
    return math.floor(x + _GRID_EPS)


def _rms(y: np.ndarray) -> float:
    return float(np.sqrt(np.mean(y * y)))


# ---------------------------------------------------------------------------------------------
# Reference and measurement
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Reference:
    """The unshaped ("original") residual vibration that shaped cycles are compared with.

    Attributes
    ----------
    t0 : float
        Time of ``signal[0]`` relative to the cycle's START, s; samples are ``t0 + i dt``.
    dt : float
        Sample step of the uniform grid, s.
    signal : numpy.ndarray
        The projected acceleration (unfiltered, multiplied by the cycle's direction sign) from
        MOTION_END to END, on the grid.
    axis : numpy.ndarray
        Unit vector (k,) the k-axis accelerometer is projected on: the principal direction of
        the reference's filtered residual, its largest component positive. Fixed afterwards.
    motion_end, end : float
        The reference cycle's MOTION_END and END, s from its START.
    omega, zeta : float
        Its mode identified by :func:`~shaper_nodes.core.identification.identify` (rad/s, -).
    m_u : float
        RMS of the filtered signal over [motion_end, end].
    highpass_hz : float
        The high-pass cut-off used for ``axis`` and ``m_u``, Hz.
    """

    t0: float
    dt: float
    signal: np.ndarray
    axis: np.ndarray
    motion_end: float
    end: float
    omega: float
    zeta: float
    m_u: float
    highpass_hz: float

    def __post_init__(self) -> None:
        for name in ("t0", "dt", "motion_end", "end", "omega", "zeta", "m_u", "highpass_hz"):
            object.__setattr__(self, name, _finite(f"reference {name}", getattr(self, name)))
        sig = np.array(self.signal, dtype=float).ravel()
        axis = np.array(self.axis, dtype=float).ravel()
        if not (self.dt > 0.0 and self.omega > 0.0 and 0.0 <= self.zeta < 1.0 and self.m_u > 0.0
                and self.end > self.motion_end and self.highpass_hz >= 0.0):
            raise ListError("reference: dt, omega, m_u must be > 0, zeta in [0, 1), end after motion_end")
        if sig.size < 2 * self.tau_steps + 2 or not np.all(np.isfinite(sig)):
            raise ListError(f"reference signal must be finite with more than {2 * self.tau_steps + 2} samples")
        if axis.size == 0 or not np.all(np.isfinite(axis)) or abs(float(np.linalg.norm(axis)) - 1.0) > 1e-9:
            raise ListError("reference axis must be a finite unit vector")
        sig.setflags(write=False)
        axis.setflags(write=False)
        object.__setattr__(self, "signal", sig)
        object.__setattr__(self, "axis", axis)

    @property
    def sigma(self) -> float:
        """Decay rate zeta omega, 1/s."""
        return self.zeta * self.omega

    @property
    def omega_d(self) -> float:
        """Damped frequency, rad/s."""
        return self.omega * math.sqrt(1.0 - self.zeta**2)

    @property
    def mode(self) -> Mode:
        return Mode(self.omega, self.zeta)

    @property
    def tau_steps(self) -> int:
        """A quarter damped period in samples (at least 1): the advance of the quadrature copy."""
        return max(1, int(round(0.5 * math.pi / self.omega_d / self.dt)))

    @property
    def times(self) -> np.ndarray:
        """Sample times of ``signal``, s from START."""
        return self.t0 + np.arange(self.signal.size) * self.dt

    def as_dict(self) -> dict[str, Any]:
        return {"t0": self.t0, "dt": self.dt, "signal": self.signal.tolist(), "axis": self.axis.tolist(),
                "motion_end": self.motion_end, "end": self.end, "omega": self.omega, "zeta": self.zeta,
                "m_u": self.m_u, "highpass_hz": self.highpass_hz}

    @classmethod
    def from_dict(cls, d: Any) -> Reference:
        if not isinstance(d, dict) or set(d) != set(cls.__dataclass_fields__):
            raise ListError("reference must be a dictionary with the keys of Reference")
        for key in ("signal", "axis"):
            if not isinstance(d[key], list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                       for x in d[key]):
                raise ListError(f"reference {key} must be a list of numbers")
        return cls(**d)


def make_reference(times: Any, accel: Any, motion_end: float, end: float, direction: float = 1.0,
                   config: ListConfig | None = None) -> Reference:
    """The reference from an unshaped cycle.

    Parameters
    ----------
    times : (N,) array_like
        Sample times, s, relative to the cycle's START, strictly increasing.
    accel : (N,) or (N, k) array_like
        Acceleration (m/s^2); k axes are projected on their principal direction.
    motion_end, end : float
        MOTION_END (the unshaped command reached its goal) and END, s from START.
    direction : float
        Sign of the move (+1 / -1): the signal is multiplied by it, so that moves in opposite
        directions compare alike (odd-symmetric plants).
    config : ListConfig
        ``highpass_hz``, ``saturation``, ``min_samples``, ``max_gap_periods`` are used.

    Raises
    ------
    ListError
        Non-finite, saturated or incomplete data, or no vibration mode found in the residual.
    """
    config = ListConfig() if config is None else config
    d = _direction(direction)
    me, en = _finite("motion_end", motion_end), _finite("end", end)
    if en <= me:
        raise ListError(f"end {en!r} s must come after motion_end {me!r} s")
    t, a = _arrays(times, accel)
    dt = _check_cycle(t, a, (me, en), config)
    i0, i1 = _ceil((me - t[0]) / dt), min(_floor((en - t[0]) / dt), _floor((t[-1] - t[0]) / dt))
    grid = t[0] + np.arange(max(i0, 0), i1 + 1) * dt
    raw = np.column_stack([np.interp(grid, t, a[:, j]) for j in range(a.shape[1])])
    filt = _highpass(raw, dt, config.highpass_hz)
    if a.shape[1] == 1:
        axis = np.ones(1)
    else:
        axis = np.linalg.svd(filt, full_matrices=False)[2][0]
        axis = axis / np.linalg.norm(axis)
        if axis[int(np.argmax(np.abs(axis)))] < 0.0:
            axis = -axis
    y = d * (raw @ axis)
    try:
        fits = identify(grid - grid[0], y, max_modes=2)
    except IdentificationError as err:
        raise ListError(f"reference: {err}") from None
    mode = fits[0]
    m_u = _rms(_highpass(y, dt, config.highpass_hz))
    if not m_u > 0.0:
        raise ListError("reference: no residual vibration (M = 0)")
    return Reference(float(grid[0]), dt, y, axis, me, en, mode.omega, mode.zeta, m_u, config.highpass_hz)


@dataclass(frozen=True)
class Measurement:
    """Residual vibration of one shaped cycle relative to the reference.

    Attributes
    ----------
    m : float
        M: RMS of the filtered residual over the window (signal units, m/s^2).
    phi : float
        Phase of the residual relative to the reference, arg rho, rad in (-pi, pi].
    rho : complex
        Complex ratio residual / reference; equals the LTI factor R for an LTI plant.
    samples : int
        Samples in the window.
    m_ref : float
        RMS of the filtered reference over the same window.
    window : (float, float)
        The window used, s from START.
    rho_se : float
        Standard error of rho (root of the summed variances of its real and imaginary parts)
        from the least-squares residual, as if it were white noise.
    """

    m: float
    phi: float
    rho: complex
    samples: int
    m_ref: float
    window: tuple[float, float]
    rho_se: float = math.nan


def _default_delay(config: ListConfig, reference: Reference) -> float:
    if config.window_delay is not None:
        return config.window_delay
    t2_hi = config.t2_bounds[1] if config.t2_bounds is not None else 2.0 * math.pi / reference.omega_d
    return config.power * t2_hi


def measure(times: Any, accel: Any, motion_end: float, end: float, reference: Reference, direction: float = 1.0,
            config: ListConfig | None = None, *, window_start: float | None = None) -> Measurement:
    """M, phi and rho of one shaped cycle against ``reference``.

    The window runs from ``window_start`` (default ``motion_end + window_delay``; with no
    window_delay, the T2 upper bound times 1 or 2 for the structure, or 2 pi / omega_d of the
    reference without bounds) to ``end``, cut to where the reference and its quarter-period
    advanced copy exist. The projected, direction-multiplied signal is resampled on the
    reference's grid and high-pass filtered over the window; so are the reference ``y_u(t)``
    and its advanced copy ``y_u(t + tau)``. Least squares ``y ~ a F y_u(t) + b F y_u(t + tau)``
    give ``rho = a + b exp((-sigma + j omega_d) tau)`` (sigma, omega_d of the reference).

    Raises
    ------
    ListError
        Non-finite, saturated or incomplete data, a different sensor layout or sample rate,
        a motion that ends at another time than the reference's, or a window too short.
    """
    config = ListConfig() if config is None else config
    if not isinstance(reference, Reference):
        raise ListError(f"reference must be a Reference, got {type(reference).__name__}")
    d = _direction(direction)
    me, en = _finite("motion_end", motion_end), _finite("end", end)
    w0 = me + _default_delay(config, reference) if window_start is None else _finite("window_start", window_start)
    if en <= w0:
        raise ListError(f"end {en:.6g} s must come after the window start {w0:.6g} s")
    ref, dt = reference, reference.dt
    shift = abs(me - ref.motion_end)
    if shift > MAX_MOTION_SHIFT * 2.0 * math.pi / ref.omega_d + dt:
        raise ListError(f"motion_end {me:.6g} s differs from the reference's {ref.motion_end:.6g} s: the task changed;"
                        " run an unshaped cycle for a new reference")
    t, a = _arrays(times, accel)
    if a.shape[1] != ref.axis.size:
        raise ListError(f"accel has {a.shape[1]} axes, the reference {ref.axis.size}")
    step = _check_cycle(t, a, (w0, en), config)
    if abs(step / dt - 1.0) > MAX_RATE_MISMATCH:
        raise ListError(f"sample step {step:.4g} s differs from the reference's {dt:.4g} s")
    k = ref.tau_steps
    lo = max(w0, ref.t0, t[0])
    hi = min(en, t[-1], ref.t0 + (ref.signal.size - 1 - k) * dt)
    i0, i1 = _ceil((lo - ref.t0) / dt), _floor((hi - ref.t0) / dt)
    n = i1 - i0 + 1
    if n < config.min_samples:
        raise ListError(f"residual window too short: {max(n, 0)} samples common with the reference"
                        f" ({lo:.4g}-{hi:.4g} s), need {config.min_samples}")
    grid = ref.t0 + np.arange(i0, i1 + 1) * dt
    y = _highpass(d * np.interp(grid, t, a @ ref.axis), dt, config.highpass_hz)
    u = _highpass(np.column_stack([ref.signal[i0 : i1 + 1], ref.signal[i0 + k : i1 + 1 + k]]), dt,
                  config.highpass_hz)
    gram = u.T @ u
    det = float(gram[0, 0] * gram[1, 1] - gram[0, 1] ** 2)
    if not det > 1e-12 * float(gram[0, 0] * gram[1, 1]):
        raise ListError("reference degenerate over the window: its quadrature copy is not independent")
    rhs = u.T @ y
    ca = float((gram[1, 1] * rhs[0] - gram[0, 1] * rhs[1]) / det)
    cb = float((gram[0, 0] * rhs[1] - gram[0, 1] * rhs[0]) / det)
    w = cmath.exp(complex(-ref.sigma, ref.omega_d) * (k * dt))
    rho = ca + cb * w
    resid = y - u @ np.array([ca, cb])
    s2 = float(resid @ resid) / max(n - 2, 1)
    var_a, var_b, cov = s2 * gram[1, 1] / det, s2 * gram[0, 0] / det, -s2 * gram[0, 1] / det
    var_re = var_a + w.real**2 * var_b + 2.0 * w.real * cov
    se = math.sqrt(max(float(var_re + w.imag**2 * var_b), 0.0))
    return Measurement(_rms(y), math.atan2(rho.imag, rho.real), rho, int(n), _rms(u[:, 0]),
                       (float(grid[0]), float(grid[-1])), se)


# ---------------------------------------------------------------------------------------------
# Learner
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ListUpdate:
    """The outcome of one cycle.

    Attributes
    ----------
    iteration : int
        Cycles seen by the learner, this one included (rejected ones too).
    m : float
        M of the cycle (for the reference: its M over the learning window); NaN if rejected.
    phi : float
        phi of the cycle, rad (0 for the reference; NaN if rejected).
    used : ListParams or None
        The parameters the cycle ran with (None: unshaped).
    next : ListParams or None
        The parameters to apply next (None only before any initial guess).
    parameter : str
        The parameter being varied, ``t2`` or ``a1``; ``none`` for reference, hold and
        rejected cycles, and for a rollback the phase that restarts.
    action : str
        One of :data:`ACTIONS`.
    reason : str
        Why, in words (bounds and step limits that clipped the step are named).
    rho : complex
        The measured complex ratio (NaN if none).
    best_m : float
        The best M so far (NaN if none).
    """

    iteration: int
    m: float
    phi: float
    used: ListParams | None
    next: ListParams | None
    parameter: str
    action: str
    reason: str
    rho: complex = complex(math.nan, math.nan)
    best_m: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (NaN as None)."""
        f = lambda x: x if math.isfinite(x) else None  # noqa: E731
        return {"iteration": self.iteration, "m": f(self.m), "phi": f(self.phi),
                "used": None if self.used is None else self.used.as_dict(),
                "next": None if self.next is None else self.next.as_dict(),
                "parameter": self.parameter, "action": self.action, "reason": self.reason,
                "rho": [f(self.rho.real), f(self.rho.imag)], "best_m": f(self.best_m)}


@dataclass(frozen=True)
class _Trial:
    """One measured shaped cycle: parameters, M, rho, the R estimate r, the signed errors, and
    the score that ranks trials (M for the paper rule, the coherent M_c = M_ref |rho| for the
    components rule)."""

    params: ListParams
    m: float
    rho: complex
    r: complex
    e_t2: float
    e_a1: float
    score: float
    floor: bool = False  # |rho| below NOISE_SIGMAS standard errors: the residual is noise

    def p(self, name: str) -> float:
        return self.params.t2 if name == "t2" else self.params.a1

    def e(self, name: str) -> float:
        return self.e_t2 if name == "t2" else self.e_a1

    def as_dict(self) -> dict[str, Any]:
        return {"a1": self.params.a1, "t2": self.params.t2, "m": self.m, "rho": [self.rho.real, self.rho.imag],
                "r": [self.r.real, self.r.imag], "e_t2": self.e_t2, "e_a1": self.e_a1, "score": self.score,
                "floor": self.floor}

    @classmethod
    def from_dict(cls, d: Any) -> _Trial:
        keys = {"a1", "t2", "m", "rho", "r", "e_t2", "e_a1", "score", "floor"}
        if not isinstance(d, dict) or set(d) != keys:
            raise ListError(f"trial must be a dictionary with keys {sorted(keys)}")
        pair = lambda name: complex(*(_finite(name, x) for x in _pair(name, d[name])))  # noqa: E731
        m, score = _finite("trial m", d["m"]), _finite("trial score", d["score"])
        if m < 0.0 or score < 0.0:
            raise ListError("trial m and score must be >= 0")
        if not isinstance(d["floor"], bool):
            raise ListError("trial floor must be true or false")
        return cls(_params({"a1": d["a1"], "t2": d["t2"]}), m, pair("rho"), pair("r"), _finite("e_t2", d["e_t2"]), _finite("e_a1", d["e_a1"]),
                   score, d["floor"])


@dataclass(frozen=True)
class _Step:
    """A proposed step: the parameters, the relative step taken and wanted (before the maximum
    step), whether the maximum step limited it, and a note for the reason."""

    name: str
    params: ListParams
    rel: float
    wanted: float
    limited: bool
    note: str


def _pair(name: str, v: Any) -> list:
    if not isinstance(v, list) or len(v) != 2:
        raise ListError(f"{name} must be a list of two numbers")
    return v


def _params(d: Any) -> ListParams:
    if not isinstance(d, dict) or set(d) != {"a1", "t2"}:
        raise ListError("parameters must be a dictionary with keys a1, t2")
    return ListParams(_finite("a1", d["a1"]), _finite("t2", d["t2"])).check()


def _other(name: str) -> str:
    return "a1" if name == "t2" else "t2"


def _same(p: ListParams, q: ListParams) -> bool:
    return (abs(p.a1 - q.a1) <= SAME_PARAMS_TOL * abs(q.a1)
            and abs(p.t2 - q.t2) <= SAME_PARAMS_TOL * abs(q.t2))


def _fmt(p: ListParams | None) -> str:
    return "none" if p is None else f"A1 {p.a1:.6g}, T2 {p.t2:.6g} s"


class ListLearner:
    """The LIST learner: one :meth:`update` per finished cycle; :attr:`params` to apply next.

    Parameters
    ----------
    config : ListConfig
        Settings.
    params : ListParams, optional
        Initial guess (e.g. from a mode estimate). Without it, the first unshaped cycle's
        identified mode gives it (ZV formulas).
    reference : Reference, optional
        A reference made earlier (:func:`make_reference`); otherwise the first cycle reported
        with ``used=None`` (unshaped) becomes it. Shaped cycles before a reference are rejected.

    Raises
    ------
    ListError
        Invalid arguments, or initial parameters outside the bounds.
    """

    def __init__(self, config: ListConfig | None = None, params: ListParams | None = None,
                 reference: Reference | None = None) -> None:
        config = ListConfig() if config is None else config
        if not isinstance(config, ListConfig):
            raise ListError(f"config must be a ListConfig, got {type(config).__name__}")
        if reference is not None and not isinstance(reference, Reference):
            raise ListError(f"reference must be a Reference, got {type(reference).__name__}")
        self._config = config
        self._t2_bounds: tuple[float, float] | None = config.t2_bounds
        self._params: ListParams | None = None
        self._reference = reference
        self._iteration = 0
        self._phase = "t2"
        self._trials: list[_Trial] = []
        self._best: _Trial | None = None
        self._last: _Trial | None = None
        self._scale = {"t2": 1.0, "a1": 1.0}  # per parameter, multiplies its maximum step
        self._limited = False  # the step to the last proposal was cut by the maximum step
        self._searching = False  # this phase minimises M alone (phi's model failed)
        self._stale = 0  # trials in a row without a new best M
        self._parked = False  # holding at the best point after `patience` such trials
        self._history: list[dict[str, Any]] = []
        if params is None and reference is not None:
            params, _ = self._clip(ListParams.from_mode(reference.mode), bounds_from=True)
        if params is not None:
            self._set_initial(params)

    # ------------------------------------------------------------------ state
    @property
    def config(self) -> ListConfig:
        return self._config

    @property
    def _score_name(self) -> str:
        return "M_c" if self._config.rule == "components" else "M"

    @property
    def params(self) -> ListParams | None:
        """The parameters to apply to the next cycle (None: run it unshaped for a reference)."""
        return self._params

    @property
    def best(self) -> tuple[ListParams, float] | None:
        """The best parameters measured so far and their M, or None."""
        return None if self._best is None else (self._best.params, self._best.m)

    @property
    def reference(self) -> Reference | None:
        return self._reference

    @property
    def needs_reference(self) -> bool:
        """True until a reference exists: run the next cycle unshaped and report ``used=None``."""
        return self._reference is None

    @property
    def phase(self) -> str:
        """``t2`` or ``a1`` (the parameter being varied) or ``hold``."""
        return self._phase

    @property
    def t2_bounds(self) -> tuple[float, float] | None:
        """The T2 bounds in force (resolved from the initial T2 when not configured), s."""
        return self._t2_bounds

    @property
    def history(self) -> list[dict[str, Any]]:
        """The last ``config.history`` updates, as :meth:`ListUpdate.as_dict`."""
        return [dict(h) for h in self._history]

    def hold(self) -> ListParams | None:
        """Stop exploring: hold at the best parameters so far (returned; the current ones if
        nothing was measured yet) until :meth:`resume`, or until M there rises above
        ``rollback_factor`` times the best (the plant changed)."""
        if self._best is None:
            return self._params
        self._parked, self._phase, self._trials, self._searching = True, "hold", [], False
        self._last = self._best
        self._params = self._best.params
        return self._params

    def resume(self) -> None:
        """Explore again after :meth:`hold` (or after holding for ``patience``)."""
        self._parked, self._stale = False, 0

    @property
    def holding(self) -> bool:
        """Whether the learner holds at its best parameters (:meth:`hold`, or ``patience``)."""
        return self._parked

    def _set_initial(self, params: ListParams) -> None:
        if not isinstance(params, ListParams):
            raise ListError(f"params must be ListParams, got {type(params).__name__}")
        params.check()
        if self._t2_bounds is None:
            self._t2_bounds = (0.5 * params.t2, min(2.0 * params.t2, MAX_DURATION / 2.0))
        lo, hi = self._config.a1_bounds
        tlo, thi = self._t2_bounds
        if not (lo <= params.a1 <= hi and tlo <= params.t2 <= thi):
            raise ListError(f"initial parameters {_fmt(params)} outside the bounds A1 {lo:g}-{hi:g},"
                            f" T2 {tlo:.6g}-{thi:.6g} s")
        self._params = params

    # ------------------------------------------------------------------ the update
    def update(self, times: Any, accel: Any, motion_end: float, end: float, used: ListParams | None,
               direction: float = 1.0) -> ListUpdate:
        """Learn from one finished cycle and return what to apply next.

        Parameters
        ----------
        times : (N,) array_like
            Sample times, s, relative to the cycle's START.
        accel : (N,) or (N, k) array_like
            Acceleration, m/s^2 (k axes: the reference's principal direction is used).
        motion_end, end : float
            The cycle's MOTION_END and END, s from its START.
        used : ListParams or None
            The parameters the cycle ran with; None: it ran unshaped, and becomes the reference.
        direction : float
            Sign of the move, +1 or -1: the residual is multiplied by it.

        Returns
        -------
        ListUpdate
            ``rejected`` cycles (incomplete, saturated, non-finite, no reference yet, or an
            unusable reference cycle) leave the parameters and the learning state unchanged.

        Raises
        ------
        ListError
            ``used`` or ``direction`` invalid (the caller's mistake, not the cycle's).
        """
        if used is not None:
            if not isinstance(used, ListParams):
                raise ListError(f"used must be ListParams or None, got {type(used).__name__}")
            used.check()
        sign = _direction(direction)
        self._iteration += 1
        if used is None:
            try:
                ref = make_reference(times, accel, motion_end, end, sign, self._config)
                if self._params is None:
                    guess, note = self._clip(ListParams.from_mode(ref.mode), bounds_from=True)
                else:
                    guess, note = self._params, ""
                m_ref = self._reference_m(ref, float(motion_end))
            except ListError as err:
                return self._record(math.nan, math.nan, None, self._params, "none", "rejected",
                                    f"unshaped cycle not usable as the reference: {err}")
            self._reference = ref
            if self._params is None:
                self._set_initial(guess)
            self._phase, self._trials, self._best, self._last = "t2", [], None, None
            self._scale = {"t2": 1.0, "a1": 1.0}
            self._limited = self._searching = self._parked = False
            self._stale = 0
            return self._record(m_ref, 0.0, None, self._params, "none", "reference",
                                f"reference: mode {ref.omega / (2 * math.pi):.4g} Hz, damping {ref.zeta:.4g}"
                                f" identified; next {_fmt(self._params)}{note}", complex(1.0, 0.0))
        if self._reference is None:
            return self._record(math.nan, math.nan, used, self._params, "none", "rejected",
                                "no reference yet: run one cycle unshaped (used=None) first")
        if self._params is None:  # a reference given without parameters cannot happen; keep safe
            self._set_initial(used)
        try:
            window = self._window(self._reference, _finite("motion_end", motion_end))
            meas = measure(times, accel, motion_end, end, self._reference, sign, self._config, window_start=window[0])
        except ListError as err:
            return self._record(math.nan, math.nan, used, self._params, "none", "rejected", f"cycle rejected: {err}")
        trial = self._trial(used, meas)
        nxt, parameter, action, reason = self._learn(trial)
        nxt, note = self._clip(nxt)  # only ever clips a foreign (out-of-bounds) point held or rolled back to
        self._params = nxt
        reason += note
        return self._record(meas.m, meas.phi, used, nxt, parameter, action, reason, meas.rho)

    def _window(self, ref: Reference, motion_end: float) -> tuple[float, float]:
        cfg = self._config
        if cfg.window_delay is not None:
            delay = cfg.window_delay
        else:
            hi = self._t2_bounds[1] if self._t2_bounds is not None else 2.0 * math.pi / ref.omega_d
            delay = cfg.power * hi
        return motion_end + delay, ref.t0 + (ref.signal.size - 1 - ref.tau_steps) * ref.dt

    def _reference_m(self, ref: Reference, motion_end: float) -> float:
        """M of the reference over the learning window (what a shaped cycle's M compares with)."""
        w0, w1 = self._window(ref, motion_end)
        i0, i1 = max(_ceil((w0 - ref.t0) / ref.dt), 0), _floor((w1 - ref.t0) / ref.dt)
        if i1 - i0 + 1 < self._config.min_samples:
            raise ListError(f"residual window too short: {max(i1 - i0 + 1, 0)} samples after the window delay"
                            f" ({w0:.4g}-{w1:.4g} s), need {self._config.min_samples}")
        return _rms(_highpass(ref.signal[i0 : i1 + 1], ref.dt, self._config.highpass_hz))

    def _record(self, m: float, phi: float, used: ListParams | None, nxt: ListParams | None, parameter: str,
                action: str, reason: str, rho: complex = complex(math.nan, math.nan)) -> ListUpdate:
        best = self._best.m if self._best is not None else math.nan
        upd = ListUpdate(self._iteration, float(m), float(phi), used, nxt, parameter, action, reason, rho, best)
        if self._config.history:
            self._history.append(upd.as_dict())
            del self._history[: -self._config.history]
        return upd

    # ------------------------------------------------------------------ trials and steps
    def _trial(self, used: ListParams, meas: Measurement) -> _Trial:
        ref = self._reference
        assert ref is not None
        n = self._config.power
        if n == 1:
            r = meas.rho
        else:
            model = lambda p: lti_factor(p, ref.sigma, ref.omega_d)  # noqa: E731
            pred = model(used) if self._last is None else self._last.r + model(used) - model(self._last.params)
            s = cmath.sqrt(meas.rho)
            r = s if abs(s - pred) <= abs(s + pred) else -s
        if self._config.rule == "components":
            e_t2, e_a1, score = r.imag, r.real, meas.m_ref * abs(meas.rho)
        else:
            ratio = meas.m / meas.m_ref
            mag = ratio if n == 1 else math.sqrt(ratio)
            e_t2, e_a1, score = math.copysign(mag, r.imag), math.copysign(mag, r.real), meas.m
        floor = abs(meas.rho) < NOISE_SIGMAS * meas.rho_se
        return _Trial(used, meas.m, meas.rho, r, e_t2, e_a1, score, floor)

    def _slope(self, name: str, params: ListParams) -> float:
        """LTI sensitivity of the error to the parameter, near T2 = pi / omega_d:
        d Im R / d T2 = (1 - A1) e^{sigma T2} omega_d, d Re R / d A1 = 1 + e^{sigma T2}."""
        ref = self._reference
        assert ref is not None
        g = math.exp(ref.sigma * params.t2)
        return params.a2 * g * ref.omega_d if name == "t2" else 1.0 + g

    def _first_step(self, name: str, trial: _Trial) -> float:
        """The LTI-sensitivity (Newton) step from one trial: p - e / slope (none at the noise floor)."""
        if trial.floor:
            return trial.p(name)
        return trial.p(name) - trial.e(name) / self._slope(name, trial.params)

    def _clip(self, params: ListParams, bounds_from: bool = False) -> tuple[ListParams, str]:
        """Parameters clipped into the bounds, and a note naming each clip."""
        lo, hi = self._config.a1_bounds
        tb = self._t2_bounds if not (bounds_from and self._config.t2_bounds is None) else None
        a1, t2, notes = params.a1, params.t2, []
        if not lo <= a1 <= hi:
            notes.append(f"A1 {a1:.6g} clipped to its bound {min(max(a1, lo), hi):g}")
            a1 = min(max(a1, lo), hi)
        if tb is not None and not tb[0] <= t2 <= tb[1]:
            notes.append(f"T2 {t2:.6g} s clipped to its bound {min(max(t2, tb[0]), tb[1]):.6g} s")
            t2 = min(max(t2, tb[0]), tb[1])
        return ListParams(a1, t2), ("; " + "; ".join(notes)) if notes else ""

    def _limit(self, name: str, base: ListParams, target: float) -> _Step:
        """Step ``name`` from ``base`` towards ``target`` within the bounds and the maximum step
        (times the step scale)."""
        cur = base.t2 if name == "t2" else base.a1
        scale = self._scale[name]
        cap = scale * self._max_step(name, base)
        note = ""
        if not math.isfinite(target):
            target, note = cur, "; non-finite step ignored"
        wanted_params, clip_note = self._clip(ListParams(base.a1, target) if name == "t2" else ListParams(target, base.t2))
        wanted = (wanted_params.t2 if name == "t2" else wanted_params.a1) - cur
        step, limited = wanted, abs(wanted) > cap
        if limited:
            step = math.copysign(cap, wanted)
            note += f"; step limited to {cap:.6g}{' s' if name == 't2' else ''}" + (
                f" (maximum x {scale:.3g} after failed steps)" if scale < 1.0 else "")
        new = ListParams(base.a1, cur + step) if name == "t2" else ListParams(cur + step, base.t2)
        return _Step(name, new, abs(step) / abs(cur), abs(wanted) / abs(cur), limited, note + clip_note)

    def _moves(self, step: _Step) -> bool:
        """Whether a step is worth a cycle: it moves, the parameter is not converged (the step
        wanted is at least switch_tol), and after failed steps the allowed step is not below it."""
        tol = self._config.switch_tol
        return step.rel > 0.0 and step.wanted >= tol and not (self._scale[step.name] < 1.0 and step.rel < tol)

    def _max_step(self, name: str, base: ListParams) -> float:
        return self._config.max_step_t2 * base.t2 if name == "t2" else self._config.max_step_a1

    def _shrink(self, name: str, base: ListParams | None = None, tried: tuple[ListParams, ...] = ()) -> str:
        """Halve the maximum step of ``name`` after a failed step (a rollback); after a phase that
        found nothing better (``tried`` from ``base``), at most half its largest step, so that the
        same first step is not tried again. Returns a note."""
        ratio = 1.0
        if base is not None and tried:
            biggest = max(abs((q.t2 - base.t2) if name == "t2" else (q.a1 - base.a1)) for q in tried)
            ratio = biggest / self._max_step(name, base) or 1.0
        self._scale[name] = max(MIN_STEP_SCALE, 0.5 * min(self._scale[name], ratio))
        return f"; {name.upper()} steps now at most {self._scale[name]:.3g} x the maximum"

    def _from_base(self, base: _Trial, prefer: str, why: str) -> tuple[ListParams, str, str, str]:
        """Start a phase from ``base``: the preferred parameter's first step if it is worth a cycle
        (:meth:`_moves`), else the other's, else hold at the best point."""
        previous = self._phase
        small = []
        for name in (prefer, _other(prefer)):
            step = self._limit(name, base.params, self._first_step(name, base))
            if self._moves(step):
                self._phase, self._trials, self._limited, self._searching = name, [base], step.limited, False
                action = "switch" if previous in _PARAMS and name != previous else "first_step"
                return step.params, name, action, (
                    f"{why}; {name.upper()} phase from {_fmt(base.params)} (M {base.m:.4g}):"
                    f" first step {100 * step.rel:.3g} %{step.note}")
            small.append(f"{name.upper()} step {100 * step.rel:.2g} % (wanted {100 * step.wanted:.2g} %){step.note}"
                         + (" (at the noise floor)" if base.floor else ""))
        assert self._best is not None
        self._phase, self._trials, self._searching = "hold", [], False
        return self._best.params, "none", "hold", (
            f"{why}; holding at the best {_fmt(self._best.params)} (M {self._best.m:.4g}): "
            + ", ".join(small) + f"; switch_tol {self._config.switch_tol:g}")

    def _learn(self, trial: _Trial) -> tuple[ListParams, str, str, str]:
        cfg = self._config
        proposed = self._params
        best = self._best
        if self._parked:
            assert best is not None
            if _same(trial.params, best.params) and trial.m <= cfg.rollback_factor * best.m:
                self._last = trial
                return best.params, "none", "hold", (
                    f"holding at the best {_fmt(best.params)} (best M {best.m:.4g}, now {trial.m:.4g}):"
                    f" {cfg.patience} trials in a row found nothing better")
            self._parked, self._stale = False, 0  # M rose at the best point, or another shaper ran
        previous_last, self._last = self._last, trial
        notes = ""
        if best is None or trial.score < best.score:
            self._best, self._stale = trial, 0
        elif not _same(trial.params, best.params) and cfg.patience and self._stale + 1 >= cfg.patience:
            self._stale += 1
            self._parked, self._phase, self._trials, self._searching = True, "hold", [], False
            self._last = best
            return best.params, "none", "hold", (
                f"{self._stale} trials in a row without a better M than {best.m:.4g}: holding at the best"
                f" {_fmt(best.params)} until M there rises above {cfg.rollback_factor:g} x")
        elif _same(trial.params, best.params):
            if trial.m > cfg.rollback_factor * best.m and min(self._scale.values()) < 1.0:
                self._scale = {"t2": 1.0, "a1": 1.0}
                notes = f"; M at the best point rose from {best.m:.4g} to {trial.m:.4g} (plant changed?): steps reset"
            self._best = trial  # the latest measurement of a point is the one that counts
        elif trial.m > cfg.rollback_factor * best.m:
            self._stale += 1
            phase, kept = self._phase, ""
            in_phase = (phase in _PARAMS and bool(self._trials) and proposed is not None
                        and _same(trial.params, proposed)
                        and best.p(_other(phase)) == self._trials[0].p(_other(phase)) == trial.p(_other(phase)))
            if in_phase:
                # the phase goes on from the best point, minimising M alone, its bad trial kept as a bound
                kept = self._shrink(phase)
                self._trials, self._searching = self._trials + [trial], True
                kept += f"; the {phase.upper()} phase continues from there on M alone"
            else:
                for name in _PARAMS:
                    if trial.p(name) != best.p(name):
                        kept += self._shrink(name)
                self._trials, self._searching = [], False
            self._last = best
            return best.params, phase if phase in _PARAMS else "none", "rollback", (
                f"M {trial.m:.4g} > {cfg.rollback_factor:g} x best M {best.m:.4g}: back to {_fmt(best.params)}{kept}")
        if proposed is None or not _same(trial.params, proposed):
            prefer = self._phase if self._phase in _PARAMS else "t2"
            return self._from_base(trial, prefer, f"the cycle ran with {_fmt(trial.params)}, not the proposed"
                                                  f" {_fmt(proposed)}: phase restarted from it" + notes)
        if self._phase == "hold" or not self._trials:
            prefer = self._phase if self._phase in _PARAMS else "t2"
            why = "holding: re-measured" if self._phase == "hold" else "phase start"
            return self._from_base(trial, prefer, why + notes)
        name = self._phase
        trials = self._trials + [trial]
        self._trials = trials
        prev = trials[-2]
        improved = min(tr.score for tr in trials) < (1.0 - cfg.switch_tol) * trials[0].score
        rel_last = abs(trial.p(name) - prev.p(name)) / abs(trial.p(name))
        ended = ""
        if trial.floor:
            ended = "residual at the noise floor (|rho| below 3 standard errors)"
        elif rel_last < cfg.switch_tol and not self._limited and not self._searching:
            ended = f"{name.upper()} converged (last step {100 * rel_last:.2g} % < switch_tol)"
        elif len({tr.p(name) for tr in trials}) - 1 >= cfg.phase_trials:
            ended = f"{cfg.phase_trials} trials of {name.upper()} done"
        elif not self._searching and improved and trial.score > prev.score:
            ended = f"M rose ({self._score_name} {prev.score:.4g} -> {trial.score:.4g}): minimum passed"
        if ended:
            return self._end_phase(name, trials, ended + notes)
        p0, p1, e0, e1 = prev.p(name), trial.p(name), prev.e(name), trial.e(name)
        target: float | None = None
        if not self._searching:
            same_side = (e0 >= 0.0) == (e1 >= 0.0)
            action = "secant" if same_side else "weighted"
            if trial.score > prev.score:  # phi's step made M worse and nothing better was found
                notes += f"; M rose ({self._score_name} {prev.score:.4g} -> {trial.score:.4g}) against phi's prediction"
            elif secant_step(p0, p1, e0, e1) is None:
                notes += f"; the error fell as {name.upper()} rose (errors {e0:.4g}, {e1:.4g}), against the LTI model"
            elif cfg.rule == "paper":
                target = paper_step(p0, p1, abs(e0), abs(e1), same_side)
            else:
                target, model = secant_step(p0, p1, e0, e1), self._slope(name, trial.params)
                if not 1.0 / SLOPE_BAND <= (e1 - e0) / (p1 - p0) / model <= SLOPE_BAND:
                    target, action = self._first_step(name, trial), "first_step"
                    notes += (f"; secant slope {(e1 - e0) / (p1 - p0):.4g} more than {SLOPE_BAND:g} times off the"
                              f" LTI sensitivity {model:.4g}: sensitivity step instead")
            if target is None:
                self._searching = True
                notes += ": searching the minimum of M alone"
        if self._searching:
            action = "search"
            found = self._m_search(name, trials)
            if found is None:
                return self._end_phase(name, trials, f"{name.upper()} minimum of M bracketed within switch_tol" + notes)
            target, start, how = found
            notes = f" ({how}){notes}"
        else:
            start = trial
        assert target is not None
        step = self._limit(name, start.params, target)
        if step.rel == 0.0 or (self._scale[name] < 1.0 and step.rel < cfg.switch_tol):
            return self._end_phase(name, trials, f"{name.upper()} cannot move by switch_tol{step.note}" + notes)
        self._limited = step.limited
        return step.params, name, action, (f"{name.upper()} {action} from trials {p0:.6g}, {p1:.6g}"
                                           f" (errors {e0:.4g}, {e1:.4g}, M {prev.m:.4g}, {trial.m:.4g}):"
                                           f" step {100 * step.rel:.3g} %{step.note}{notes}")

    def _end_phase(self, name: str, trials: list[_Trial], why: str) -> tuple[ListParams, str, str, str]:
        """End the phase of ``name``: continue from its best trial with the other parameter."""
        base = min(trials, key=lambda tr: tr.score)
        if len(trials) > 1 and not base.score < (1.0 - self._config.switch_tol) * trials[0].score:
            # the phase found nothing (more than switch_tol) better: smaller steps
            why += "; no improvement in the phase" + self._shrink(name, trials[0].params,
                                                                  tuple(tr.params for tr in trials))
        return self._from_base(base, _other(name), why)

    def _m_search(self, name: str, trials: list[_Trial]) -> tuple[float, _Trial, str] | None:
        """The next point of a one-dimensional minimisation of M over the phase's trials, or None
        when the minimum is bracketed within switch_tol.

        Used when phi's model fails (M rose against its prediction, or the error fell as the
        parameter rose). Bracketed (the trial with the least M has trials on both sides): the
        vertex of the parabola through it and its neighbours in M^2 (for an LTI mode M^2 is exactly
        quadratic in each parameter, a constant noise floor included); otherwise a step as long as
        the last one, beyond the least M, away from its neighbour."""
        by_p: dict[float, _Trial] = {}
        for tr in trials:  # the latest measurement of a point counts
            by_p[tr.p(name)] = tr
        pts = [by_p[k] for k in sorted(by_p)]
        i = min(range(len(pts)), key=lambda k: pts[k].m)
        b = pts[i]
        pb = b.p(name)
        if len(pts) < 2:
            return None
        if 0 < i < len(pts) - 1:
            lo, hi = pts[i - 1], pts[i + 1]
            pl, ph = lo.p(name), hi.p(name)
            if ph - pl < 2.0 * self._config.switch_tol * abs(pb):
                return None
            ml, mb, mh = lo.m**2, b.m**2, hi.m**2
            den = (pl - pb) * (pl - ph) * (pb - ph)
            a = (ph * (mb - ml) + pb * (ml - mh) + pl * (mh - mb)) / den
            bb = (ph**2 * (ml - mb) + pb**2 * (mh - ml) + pl**2 * (mb - mh)) / den
            far = ph if ph - pb >= pb - pl else pl
            x = -bb / (2.0 * a) if a > 0.0 else math.nan
            if not (math.isfinite(x) and pl < x < ph) or abs(x - pb) < 0.05 * min(pb - pl, ph - pb):
                x, how = pb + 0.382 * (far - pb), "golden step into the wider side of the bracket"
            else:
                how = "vertex of the parabola through the bracket in M^2"
            return x, b, how
        nb = pts[1] if i == 0 else pts[-2]
        return pb + (pb - nb.p(name)), b, "step beyond the least M, away from its neighbour"

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """The full state as a JSON-serialisable dictionary (floats round-trip exactly)."""
        trial = lambda tr: None if tr is None else tr.as_dict()  # noqa: E731
        return {
            "format": "list_learner", "version": STATE_VERSION,
            "config": self._config.as_dict(),
            "params": None if self._params is None else self._params.as_dict(),
            "t2_bounds": None if self._t2_bounds is None else list(self._t2_bounds),
            "reference": None if self._reference is None else self._reference.as_dict(),
            "iteration": self._iteration, "phase": self._phase,
            "trials": [tr.as_dict() for tr in self._trials],
            "best": trial(self._best), "last": trial(self._last), "step_scale": dict(self._scale),
            "step_limited": self._limited, "searching": self._searching,
            "stale": self._stale, "parked": self._parked,
            "history": [dict(h) for h in self._history],
        }

    @classmethod
    def from_dict(cls, d: Any) -> ListLearner:
        """Restore :meth:`to_dict`'s state; :class:`ListError` names what is corrupt or inconsistent."""
        try:
            return cls._from_dict(d)
        except ListError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ListError(f"corrupt learner state: {type(err).__name__}: {err}") from None

    @classmethod
    def _from_dict(cls, d: Any) -> ListLearner:
        keys = {"format", "version", "config", "params", "t2_bounds", "reference", "iteration", "phase", "trials",
                "best", "last", "step_scale", "step_limited", "searching", "stale", "parked", "history"}
        if not isinstance(d, dict):
            raise ListError(f"learner state must be a dictionary, got {type(d).__name__}")
        if d.get("format") != "list_learner" or d.get("version") != STATE_VERSION:
            raise ListError(f"not a list_learner state of version {STATE_VERSION}:"
                            f" format {d.get('format')!r}, version {d.get('version')!r}")
        if set(d) != keys:
            raise ListError(f"learner state keys differ: missing {sorted(keys - set(d))},"
                            f" unknown {sorted(set(d) - keys)}")
        config = ListConfig.from_dict(d["config"])
        ref = None if d["reference"] is None else Reference.from_dict(d["reference"])
        self = cls(config, None, None)
        self._reference = ref
        if d["t2_bounds"] is not None:
            self._t2_bounds = ListConfig._bounds("t2_bounds", _pair("t2_bounds", d["t2_bounds"]), 0.0,
                                                 MAX_DURATION / 2.0)
        elif config.t2_bounds is not None:
            raise ListError("t2_bounds missing although configured")
        if config.t2_bounds is not None and self._t2_bounds != config.t2_bounds:
            raise ListError("t2_bounds differ from the configured ones")
        if d["params"] is not None:
            if self._t2_bounds is None:
                raise ListError("parameters without T2 bounds")
            self._set_initial(_params(d["params"]))
        elif ref is not None:
            raise ListError("a reference but no parameters")
        self._iteration = _int("iteration", d["iteration"], 0)
        if d["phase"] not in ("t2", "a1", "hold"):
            raise ListError(f"unknown phase {d['phase']!r}")
        self._phase = d["phase"]
        if not isinstance(d["trials"], list):
            raise ListError("trials must be a list")
        self._trials = [_Trial.from_dict(x) for x in d["trials"]]
        self._best = None if d["best"] is None else _Trial.from_dict(d["best"])
        self._last = None if d["last"] is None else _Trial.from_dict(d["last"])
        if (self._trials or self._best or self._last) and (ref is None or self._best is None or self._last is None):
            raise ListError("trials without a reference, a best or a last trial")
        if self._phase == "hold" and self._trials:
            raise ListError("trials recorded while holding")
        scale = d["step_scale"]
        if not isinstance(scale, dict) or set(scale) != set(_PARAMS):
            raise ListError("step_scale must be a dictionary with keys t2, a1")
        for name in _PARAMS:
            x = _finite("step_scale", scale[name])
            if not MIN_STEP_SCALE <= x <= 1.0:
                raise ListError(f"step_scale must be in [{MIN_STEP_SCALE:g}, 1], got {x!r}")
            self._scale[name] = x
        if not (isinstance(d["step_limited"], bool) and isinstance(d["searching"], bool)):
            raise ListError("step_limited and searching must be true or false")
        self._limited, self._searching = d["step_limited"], d["searching"]
        self._stale = _int("stale", d["stale"], 0)
        if not isinstance(d["parked"], bool) or (d["parked"] and (self._phase != "hold" or self._best is None)):
            raise ListError("parked must be true or false, and true only while holding at a best point")
        self._parked = d["parked"]
        if self._searching and len(self._trials) < 2:
            raise ListError("searching with fewer than two trials")
        if not isinstance(d["history"], list) or not all(isinstance(h, dict) for h in d["history"]):
            raise ListError("history must be a list of dictionaries")
        self._history = [dict(h) for h in d["history"]][-config.history:] if config.history else []
        return self
