"""Model-Reference Iterative Learning Control (MRILC, seed 000), free of ROS.

Modules
-------
model
    The reference model G_m = C P_nom / (1 + C P_nom), the exact ZOH sampled loop, the
    convergence check of eq. (11) over a plant set, the learning laws and the Q filter.
learner
    :class:`MrilcLearner` (the profile u2 and its divergence guard), :class:`MrilcSession`
    (whole cycles on the sample grid from the streams), and the node's parameters
    (:data:`DEFAULTS`, :data:`RANGES`, :func:`model_from_params`).
"""

from .learner import DEFAULTS, RANGES, MrilcLearner, MrilcSession, model_from_params
from .model import PAPER_CONTROLLER, MrilcError, MrilcModel, controller

__all__ = [
    "DEFAULTS",
    "PAPER_CONTROLLER",
    "RANGES",
    "MrilcError",
    "MrilcLearner",
    "MrilcModel",
    "MrilcSession",
    "controller",
    "model_from_params",
]
