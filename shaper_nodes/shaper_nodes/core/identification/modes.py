"""Identification of vibration modes from free residual vibration.

One record is the accelerometer (or any vibration signal) after a move, while the structure
rings freely. It is modelled, per axis j, as an offset, a linear drift and a sum of M damped
sinusoids sharing their poles across axes:

    y_j(t) = c_j + d_j t + sum_m exp(-s_m t) (a_mj cos(w_m t) + b_mj sin(w_m t)) + noise,

with decay rate ``s_m = zeta_m omega_m`` (1/s) and damped frequency ``w_m = omega_m sqrt(1 -
zeta_m^2)`` (rad/s), so ``omega_m = sqrt(s_m^2 + w_m^2)`` and ``zeta_m = s_m / omega_m``.

Methods (:data:`METHODS`)
-------------------------
fit (default)
    Nonlinear least squares of the model above by variable projection (Golub & Pereyra 1973):
    the residual is minimised over the poles (s_m, w_m) only, the linear coefficients being
    solved by linear least squares at every step; Kaufman's (1975) Jacobian. Modes are added
    one at a time (successive peak extraction on the residual spectrum, each start refined by
    a small grid over damping) and refitted jointly; a mode is kept if it lowers the residual
    sum of squares by more than the BIC penalty. Uncertainty: ``sigma^2 (J^T J)^-1``.
spectral
    Tapered, zero-padded FFT peak refined by parabolic interpolation of the log power; the
    analytic signal (FFT band-pass around the peak) gives the envelope and phase, whose
    weighted straight-line fits give the decay rate (log decrement) and the damped frequency.
    Uncertainty from the regression residuals, corrected for the correlation the band-pass
    introduces. Successive extraction for further modes.
matrix_pencil
    Hua & Sarkar (1990): SVD of a Hankel matrix (stacked over axes), truncated to the model
    order, poles as eigenvalues of the shifted singular-vector pencil. Uncertainty: the same
    Jacobian covariance as ``fit``, evaluated at the pencil estimate.

Preprocessing (all methods): validation, resampling onto a uniform grid when the time stamps
jitter a little, removal of the offset and linear drift, and block-averaging decimation of
long, heavily oversampled records (block means keep a sum of damped exponentials a sum of the
same exponentials, so the poles are unchanged).

Modules: the record's checks and preprocessing in :mod:`.record`, the three methods in
:mod:`.estimators`, and here the public API (:func:`identify`, :func:`identify_records`,
:func:`combine_modes`). The shaper recommended for the modes found is in :mod:`.recommend`.
See docs/design/identification.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.shaping import Mode

from .estimators import ESTIMATORS, PoleModel, covariance, hac_covariance
from .record import FloatArray, IdentificationError, Record, prepare

#: fewest damped periods of the strongest mode a record must span
MIN_PERIODS = 3.0
#: modes weaker than this fraction of the strongest (initial amplitude) are dropped
MIN_RELATIVE_AMPLITUDE = 0.05
#: identified damping ratios must lie in (0, MAX_IDENTIFIED_DAMPING)
MAX_IDENTIFIED_DAMPING = 0.9
#: relative frequency difference within which modes of different records are the same mode
MATCH_TOLERANCE = 0.1

#: identification methods, name -> description
METHODS: dict[str, str] = {
    "fit": "nonlinear least squares (variable projection) of damped sinusoids + offset + drift;"
    " Jacobian covariance",
    "spectral": "FFT peak with parabolic interpolation, Hilbert envelope log decrement and phase"
    " slope; regression-residual uncertainty",
    "matrix_pencil": "Hankel-SVD matrix pencil (Hua & Sarkar 1990); Jacobian covariance at the"
    " estimate",
}


@dataclass(frozen=True)
class ModeFit:
    """An identified vibration mode with one-sigma uncertainties.

    Attributes
    ----------
    omega : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio, dimensionless.
    omega_std, zeta_std : float
        One-sigma uncertainties of omega (rad/s) and zeta.
    amplitude : float
        Initial amplitude of the decay (norm over axes), in signal units; ranks modes.
    method : str
        The method that produced it (a key of :data:`METHODS`).
    """

    omega: float
    zeta: float
    omega_std: float
    zeta_std: float
    amplitude: float
    method: str

    @property
    def mode(self) -> Mode:
        """The mode (omega, zeta) for shaper design."""
        return Mode(self.omega, self.zeta)

    @property
    def hz(self) -> float:
        """Natural frequency, Hz."""
        return self.omega / (2.0 * math.pi)



def _to_modes(rec: Record, theta: FloatArray, cov: FloatArray | None, method: str) -> list[ModeFit]:
    model = PoleModel(rec)
    if cov is None:
        cov = covariance(model, theta)
    coef = model.solve(theta)[1]
    m = theta.size // 2
    out = []
    for i in range(m):
        s, w = float(theta[2 * i]), float(theta[2 * i + 1])
        omega = math.hypot(s, w)
        zeta = s / omega
        g = np.array([[s / omega, w / omega], [w * w / omega**3, -s * w / omega**3]])
        c = g @ cov[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] @ g.T
        amp = float(np.sqrt(np.sum(coef[2 + i] ** 2 + coef[2 + m + i] ** 2)))
        out.append(ModeFit(omega, zeta, float(math.sqrt(max(c[0, 0], 0.0))),
                           float(math.sqrt(max(c[1, 1], 0.0))), amp, method))
    return out


def _check_method(method: str, max_modes: int) -> str:
    name = str(method).strip().lower()
    if name not in METHODS:
        raise IdentificationError(f"unknown identification method {method!r}; known: {sorted(METHODS)}")
    if isinstance(max_modes, bool) or int(max_modes) != max_modes or not 1 <= int(max_modes) <= 8:
        raise IdentificationError(f"max_modes must be an integer in [1, 8], got {max_modes!r}")
    return name


def identify(
    times: Sequence[float] | FloatArray,
    signal: Sequence[float] | FloatArray,
    *,
    method: str = "fit",
    max_modes: int = 2,
    band_hz: tuple[float, float] | None = None,
    covariance: str = "white",
) -> list[ModeFit]:
    """Identify the vibration modes of one record of free residual vibration.

    Parameters
    ----------
    times : (N,) array_like
        Sample times, s, strictly increasing and near-uniform (steps within
        :data:`MAX_JITTER` of the median; resampled linearly onto a uniform grid).
    signal : (N,) or (N, k) array_like
        The vibration (e.g. acceleration in m/s^2, k axes). Axes share the modes' poles and
        are fitted jointly; offset and linear drift per axis are part of the model.
    method : str
        One of :data:`METHODS`; ``"fit"`` (default) is the most accurate.
    max_modes : int
        Most modes to identify (1 to 8).
    band_hz : (float, float), optional
        Only look for natural frequencies in this band, Hz.
    covariance : str
        How the uncertainties are computed: ``"white"`` (default) takes the residual as white
        noise, sigma^2 (J^T J)^-1; ``"hac"`` does not (:func:`.estimators.hac_covariance`), so
        what the model leaves out (a mode not fitted, the start of the record) widens them.

    Returns
    -------
    list of ModeFit
        Strongest (largest initial amplitude) first. Modes with damping outside (0,
        :data:`MAX_IDENTIFIED_DAMPING`), fewer than :data:`MIN_PERIODS` damped periods in the
        record, or weaker than :data:`MIN_RELATIVE_AMPLITUDE` of the strongest are dropped.

    Raises
    ------
    IdentificationError
        Bad input (non-finite, mismatched lengths, non-increasing or irregular times, too few
        samples), a record shorter than MIN_PERIODS periods of its strongest mode, or no mode
        significantly above the noise.
    """
    name = _check_method(method, max_modes)
    rec = prepare(times, signal, band_hz)
    if covariance not in ("white", "hac"):
        raise IdentificationError(f"covariance must be 'white' or 'hac', got {covariance!r}")
    theta, cov = ESTIMATORS[name](rec, int(max_modes))
    if covariance == "hac" and theta.size:
        cov = hac_covariance(PoleModel(rec), theta)
    if theta.size == 0:
        raise IdentificationError(
            "no mode found: no damped oscillation significantly above the noise"
            + (f" in {rec.band[0]:.4g}-{rec.band[1]:.4g} Hz" if band_hz is not None else "")
        )
    modes = [mf for mf, inside in zip(_to_modes(rec, theta, cov, name), rec.in_band(theta), strict=True) if inside]
    if not modes:
        raise IdentificationError(
            f"no mode found in {rec.band[0]:.4g}-{rec.band[1]:.4g} Hz: the oscillations found lie outside"
        )
    modes.sort(key=lambda mf: -mf.amplitude)
    duration = float(rec.t[-1] + rec.dt)
    strongest = modes[0]
    periods = duration * strongest.omega * math.sqrt(max(1.0 - strongest.zeta**2, 0.0)) / (2 * math.pi)
    if periods < MIN_PERIODS and 0.0 < strongest.zeta < MAX_IDENTIFIED_DAMPING:
        raise IdentificationError(
            f"record too short: {duration:.4g} s holds {periods:.2f} periods of the strongest mode"
            f" ({strongest.hz:.4g} Hz), need at least {MIN_PERIODS:g}"
        )
    kept = []
    for mf in modes:
        wd = mf.omega * math.sqrt(max(1.0 - mf.zeta**2, 0.0))
        if not 0.0 < mf.zeta < MAX_IDENTIFIED_DAMPING:
            continue
        if duration * wd / (2 * math.pi) < MIN_PERIODS:
            continue
        kept.append(mf)
    if not kept:
        raise IdentificationError(
            "no mode found: the oscillations found have damping outside"
            f" (0, {MAX_IDENTIFIED_DAMPING}) (growing, undamped or overdamped)"
        )
    top = kept[0].amplitude
    return [mf for mf in kept if mf.amplitude >= MIN_RELATIVE_AMPLITUDE * top]


def identify_records(
    records: Sequence[tuple[Sequence[float] | FloatArray, Sequence[float] | FloatArray]],
    *,
    method: str = "fit",
    max_modes: int = 2,
    band_hz: tuple[float, float] | None = None,
) -> list[ModeFit]:
    """Identify modes in several records (e.g. one per move) and combine them.

    Each record is identified with :func:`identify`. Modes are matched across records by
    natural frequency (within :data:`MATCH_TOLERANCE`, strongest first, at most one per
    record); a mode is kept if found in at least half of the records. The combined omega and
    zeta are the means; each uncertainty is the larger of the RMS per-record one-sigma and the
    standard deviation between records, i.e. the spread of a single record's mode, which the
    shaper must tolerate (not the standard error of the mean).

    Raises
    ------
    IdentificationError
        No records, or a record that cannot be identified (the message names its index).
    """
    records = list(records)
    if not records:
        raise IdentificationError("no records to identify")
    name = _check_method(method, max_modes)
    per_record: list[list[ModeFit]] = []
    for i, rec in enumerate(records):
        try:
            times, signal = rec
        except (TypeError, ValueError) as exc:
            raise IdentificationError(f"record {i}: expected a (times, signal) pair") from exc
        try:
            per_record.append(identify(times, signal, method=name, max_modes=max_modes, band_hz=band_hz))
        except IdentificationError as exc:
            raise IdentificationError(f"record {i}: {exc}") from exc
    return combine_modes(per_record, method=name, max_modes=max_modes)


def combine_modes(per_record: Sequence[Sequence[ModeFit]], *, method: str = "fit", max_modes: int = 2
                  ) -> list[ModeFit]:
    """Combine the modes identified in several records, as :func:`identify_records` does.

    ``per_record`` holds each record's modes (from :func:`identify`); matching, the at-least-half
    rule and the uncertainties are those described in :func:`identify_records`.
    """
    clusters: list[list[tuple[int, ModeFit]]] = []
    entries = sorted(((i, mf) for i, mfs in enumerate(per_record) for mf in mfs), key=lambda e: -e[1].amplitude)
    for i, mf in entries:
        best, best_d = None, MATCH_TOLERANCE
        for cl in clusters:
            if any(j == i for j, _ in cl):
                continue
            ref = float(np.mean([m.omega for _, m in cl]))
            d = abs(mf.omega - ref) / ref
            if d < best_d:
                best, best_d = cl, d
        if best is None:
            clusters.append([(i, mf)])
        else:
            best.append((i, mf))
    need = math.ceil(len(per_record) / 2)
    out = []
    for cl in clusters:
        if len(cl) < need:
            continue
        om = np.array([m.omega for _, m in cl])
        ze = np.array([m.zeta for _, m in cl])
        om_std = math.sqrt(float(np.mean([m.omega_std**2 for _, m in cl])))
        ze_std = math.sqrt(float(np.mean([m.zeta_std**2 for _, m in cl])))
        if len(cl) > 1:
            om_std = max(om_std, float(np.std(om, ddof=1)))
            ze_std = max(ze_std, float(np.std(ze, ddof=1)))
        out.append(ModeFit(float(om.mean()), float(ze.mean()), om_std, ze_std,
                           float(np.mean([m.amplitude for _, m in cl])), method))
    out.sort(key=lambda mf: -mf.amplitude)
    return out[: int(max_modes)]

