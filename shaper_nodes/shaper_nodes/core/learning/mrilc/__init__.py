"""Model-Reference Iterative Learning Control (MRILC, seed 000), free of ROS.

Modules
-------
model
    The reference model G_m = C P_nom / (1 + C P_nom), the exact ZOH sampled loop, the
    convergence check of eq. (11) over a plant set, the learning laws and the Q filter.
learner
    :class:`MrilcLearner`: the profile u2, learned cycle by cycle, and its divergence guard; its
    saved state checked fully (:func:`learner_from_state`).
session
    :class:`MrilcSession`: whole cycles on the sample grid from the streams (joint states, the
    applied reference, cycle events), handed to the learner; memory bounded (the cycle duration
    limit, a margin between cycles), implausible samples refused.
moves
    MRILC per move: :class:`~.moves.MoveLearner`, a lifted (matrix) ILC of a move's joint profile
    correction on B-splines, kept inside :class:`~.profile.JointLimits`, with a divergence guard and a
    versioned state per move (:func:`~.moves.moves_to_dict`, :func:`~.moves.moves_from_dict`).
profile
    A move's correction (the B-spline basis, :class:`~.profile.Profile`) and the joint limits it must hold:
    their breach measured, the coefficients projected inside, the points sent clipped.
plan
    A move's MRILC set-up from its commanded profile (motion end, output grid, weights) and its error from
    the measured accelerometer.
payload
    The payload worked out from a drifted mode (:func:`~.payload.payload_from_modes`), for the operators.
params
    The learner node's parameters (:data:`DEFAULTS`, :data:`RANGES`, :data:`DESCRIPTIONS`) and
    the model and settings they build (:func:`model_from_params`, :class:`MrilcSettings`), and the check of one value
    (:func:`check_parameter`).
"""

from .learner import MrilcLearner, MrilcUpdate, learner_from_state
from .model import PAPER_CONTROLLER, MrilcError, MrilcModel, controller
from .params import DEFAULTS, DESCRIPTIONS, RANGES, MrilcSettings, check_parameter, model_from_params
from .session import MrilcCycle, MrilcSession

__all__ = [
    "DEFAULTS",
    "DESCRIPTIONS",
    "PAPER_CONTROLLER",
    "RANGES",
    "MrilcCycle",
    "MrilcError",
    "MrilcLearner",
    "MrilcModel",
    "MrilcSession",
    "MrilcSettings",
    "MrilcUpdate",
    "check_parameter",
    "controller",
    "learner_from_state",
    "model_from_params",
]
