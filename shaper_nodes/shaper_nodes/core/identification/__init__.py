"""Identification of vibration modes and the shaper recommendation, free of ROS.

Modules
-------
modes
    Vibration modes (frequency, damping, one-sigma uncertainties) from free decays: nonlinear
    least squares by variable projection (``fit``), spectral peak with envelope decay
    (``spectral``) and matrix pencil (``matrix_pencil``); combining estimates over records.
recommend
    The shortest shaper whose worst-case percentage vibration over the modes' uncertainty
    band stays under a target, with every candidate ranked.
"""

from .modes import (
    METHODS,
    IdentificationError,
    ModeFit,
    combine_modes,
    identify,
    identify_records,
)
from .recommend import Recommendation, recommend_shaper

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
