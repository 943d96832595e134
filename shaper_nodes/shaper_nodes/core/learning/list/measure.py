"""The LIST measurement: the unshaped reference cycle, and M, phi, rho of each shaped cycle.

Measurement (:func:`measure`). The residual window runs from ``motion_end + window_delay``
(after the shaped command has ended, :func:`window_delay`) to the cycle's end, times relative to
the cycle's START. Over it, the projected accelerometer signal is high-pass filtered (zero-phase
Butterworth, window only, so the operation stays linear in the window's data) and M is its RMS
(eq. (4)). The complex ratio rho ~ R is the least-squares fit of the filtered signal by the
filtered unshaped reference ``y_u(t)`` and its copy advanced by a quarter damped period
``y_u(t + tau)``: for an LTI plant the shaped residual lies exactly in that span, so
``rho = a + b exp((-sigma + j omega_d) tau)`` equals R (:func:`~.params.lti_factor`); phi = arg rho.

The reference (:class:`Reference`, :func:`make_reference`) is an unshaped cycle: its residual
on a uniform grid, the direction the accelerometer axes are projected on, and its mode
identified by :func:`~shaper_nodes.core.identification.identify`. Cycles that are incomplete,
saturated, non-finite, at another sample rate, or whose motion ends at another time than the
reference's are refused with :class:`~.params.ListError`.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, cast

import numpy as np
import numpy.typing as npt
from scipy.signal import butter, sosfiltfilt

from shaper_nodes.core.identification import IdentificationError, identify
from shaper_nodes.core.shaping import Mode

from .params import ListConfig, ListError, finite_value

#: order of the Butterworth high-pass (applied forwards and backwards: zero phase)
HIGHPASS_ORDER = 2
#: a measured cycle's median sample step may differ from the reference's by this fraction
MAX_RATE_MISMATCH = 0.25
#: a cycle's motion_end may differ from the reference's by this many damped periods
MAX_MOTION_SHIFT = 0.05
#: tolerance of the index arithmetic on sample grids, in samples
_GRID_EPS = 1e-6



# ---------------------------------------------------------------------------------------------
# Signals: checks, resampling, filtering
# ---------------------------------------------------------------------------------------------


def direction_sign(direction: Any) -> float:
    """The sign (+1 or -1) of a move's direction; 0 or a non-number is refused."""
    d = finite_value("direction", direction)
    if d == 0.0:
        raise ListError("direction must be +1 or -1 (its sign is used), got 0")
    return math.copysign(1.0, d)


def _arrays(times: Any, accel: Any) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
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


def _check_cycle(t: npt.NDArray[np.float64], a: npt.NDArray[np.float64], window: tuple[float, float],
                 config: ListConfig) -> float:
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


def _highpass(y: npt.NDArray[np.float64], dt: float, hz: float) -> npt.NDArray[np.float64]:
    """Zero-phase high-pass of the window along axis 0; hz = 0: the window mean removed.

    Butterworth forwards and backwards over the window extended by its even reflection (as
    long as the window). Both are linear in the window's samples. The even reflection matters
    with noise: the default odd extension (2 x[0] - x[k]) and a short pad let the noise of the
    edge samples through the filter's transient, coherently over the first samples, where the
    residual is largest; it doubled the noise of rho in tests."""
    if hz == 0.0:
        return cast(npt.NDArray[np.float64], y - y.mean(axis=0))
    if hz >= 0.45 / dt:
        raise ListError(f"highpass_hz {hz:g} Hz is not below the Nyquist frequency {0.5 / dt:g} Hz")
    sos = np.array(_butter(hz, dt))  # a writable copy: sosfilt refuses read-only coefficients
    return cast(npt.NDArray[np.float64], sosfiltfilt(sos, y, axis=0, padtype="even", padlen=y.shape[0] - 1))


@lru_cache(maxsize=16)
def _butter(hz: float, dt: float) -> tuple[tuple[float, ...], ...]:
    sos = butter(HIGHPASS_ORDER, hz, btype="highpass", fs=1.0 / dt, output="sos")
    return tuple(tuple(float(x) for x in row) for row in sos)


def _ceil(x: float) -> int:
    return math.ceil(x - _GRID_EPS)


def _floor(x: float) -> int:
    return math.floor(x + _GRID_EPS)


def _rms(y: npt.NDArray[np.float64]) -> float:
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
    signal: npt.NDArray[np.float64]
    axis: npt.NDArray[np.float64]
    motion_end: float
    end: float
    omega: float
    zeta: float
    m_u: float
    highpass_hz: float

    def __post_init__(self) -> None:
        for name in ("t0", "dt", "motion_end", "end", "omega", "zeta", "m_u", "highpass_hz"):
            object.__setattr__(self, name, finite_value(f"reference {name}", getattr(self, name)))
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
    def times(self) -> npt.NDArray[np.float64]:
        """Sample times of ``signal``, s from START."""
        return cast(npt.NDArray[np.float64], self.t0 + np.arange(self.signal.size) * self.dt)

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
    d = direction_sign(direction)
    me, en = finite_value("motion_end", motion_end), finite_value("end", end)
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


def residual_window(motion_end: float, reference: Reference, config: ListConfig,
                    t2_bounds: tuple[float, float] | None) -> tuple[float, float]:
    """The residual window of a cycle: its start and the latest end the reference allows, s from START.

    The one source of the window for :func:`measure` and the learner. It starts at
    ``motion_end`` plus ``config.window_delay``, or without one, plus the longest shaper the T2
    bounds allow: the upper bound of ``t2_bounds`` times 1 (``zv2``) or 2 (``zvd3``), or
    2 pi / omega_d of the reference without bounds. The learner passes the bounds in force
    (configured, or resolved from the initial T2); :func:`measure` on its own the configured
    ones. The latest end is the last sample time at which the reference's quarter-period
    advanced copy still exists.
    """
    if config.window_delay is not None:
        delay = config.window_delay
    else:
        t2_hi = t2_bounds[1] if t2_bounds is not None else 2.0 * math.pi / reference.omega_d
        delay = config.power * t2_hi
    last = reference.t0 + (reference.signal.size - 1 - reference.tau_steps) * reference.dt
    return motion_end + delay, last


def reference_m(reference: Reference, window: tuple[float, float], config: ListConfig) -> float:
    """M of the reference itself over ``window`` (s from START), high-pass filtered as a cycle's
    residual is: what a shaped cycle's M compares with."""
    ref, (w0, w1) = reference, window
    i0, i1 = max(_ceil((w0 - ref.t0) / ref.dt), 0), _floor((w1 - ref.t0) / ref.dt)
    if i1 - i0 + 1 < config.min_samples:
        raise ListError(f"residual window too short: {max(i1 - i0 + 1, 0)} samples after the window delay"
                        f" ({w0:.4g}-{w1:.4g} s), need {config.min_samples}")
    return _rms(_highpass(ref.signal[i0 : i1 + 1], ref.dt, config.highpass_hz))


def measure(times: Any, accel: Any, motion_end: float, end: float, reference: Reference, direction: float = 1.0,
            config: ListConfig | None = None, *, window_start: float | None = None) -> Measurement:
    """M, phi and rho of one shaped cycle against ``reference``.

    The window runs from ``window_start`` (default: the start of :func:`residual_window` with
    the configured T2 bounds, ``motion_end + window_delay``; with no window_delay, the T2 upper
    bound times 1 or 2 for the structure, or 2 pi / omega_d of the reference without bounds) to
    ``end``, cut to where the reference and its quarter-period advanced copy exist. The
    projected, direction-multiplied signal is resampled on the reference's grid and high-pass
    filtered over the window; so are the reference ``y_u(t)`` and its advanced copy
    ``y_u(t + tau)``. Least squares ``y ~ a F y_u(t) + b F y_u(t + tau)``
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
    d = direction_sign(direction)
    me, en = finite_value("motion_end", motion_end), finite_value("end", end)
    start, last = residual_window(me, reference, config, config.t2_bounds)
    w0 = start if window_start is None else finite_value("window_start", window_start)
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
    hi = min(en, t[-1], last)
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

