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
    band stays under a target, with every candidate ranked.
"""

from .modes import METHODS, ModeFit, combine_modes, identify, identify_records
from .recommend import Recommendation, recommend_shaper
from .record import IdentificationError

__all__ = [
    "METHODS",
    "IdentificationError",
    "ModeFit",
    "Recommendation",
    "combine_modes",
    "identify",
    "identify_records",
    "recommend_shaper",
]
