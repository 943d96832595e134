"""Identification of vibration modes and the shaper recommendation, free of ROS.

Modules
-------
modes
    The public API: vibration modes (frequency, damping, one-sigma uncertainties) from free
    decays (:func:`identify`), over several records (:func:`identify_records`,
    :func:`combine_modes`), by one of :data:`METHODS`.
record
    The record's checks and preprocessing (resampling, detrending, decimation), its spectrum
    and peaks, and :class:`IdentificationError`.
estimators
    The methods: nonlinear least squares by variable projection (``fit``), spectral peak with
    envelope decay (``spectral``) and matrix pencil (``matrix_pencil``), and the Jacobian
    covariance of the poles.
recommend
    The shortest shaper whose worst-case percentage vibration over the modes' uncertainty
    band stays under a target, with every candidate ranked; modes that do not ring (heavily
    damped, or at the noise floor) set aside.
drift
    Drift of a vibration mode against the active shaper: the mode out of the shaper's working band,
    confirmed over cycles (:class:`~.drift.DriftWatch`, :func:`~.drift.check_mode`).
"""

from .modes import METHODS, ModeFit, combine_modes, identify, identify_records
from .recommend import (
    MAX_RINGING_DAMPING,
    NO_SHAPER_NEEDED,
    NOISE_FLOOR_SIGMAS,
    Recommendation,
    recommend_shaper,
    ringing_issue,
    split_ringing,
)
from .record import IdentificationError

__all__ = [
    "MAX_RINGING_DAMPING",
    "METHODS",
    "NOISE_FLOOR_SIGMAS",
    "NO_SHAPER_NEEDED",
    "IdentificationError",
    "ModeFit",
    "Recommendation",
    "combine_modes",
    "identify",
    "identify_records",
    "recommend_shaper",
    "ringing_issue",
    "split_ringing",
]
