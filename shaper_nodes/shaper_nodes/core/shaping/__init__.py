"""Input shaping, free of ROS: impulse sequences, their vibration, their FIR, whole trajectories.

Modules
-------
families
    The registry of named designs (:data:`FAMILIES`, :func:`design`), the closed-form families
    (ZV, ZVD, ZV-D^n, MZV), the shaper and mode types, and custom sequences.
vibration
    The percentage vibration V(omega, zeta) of an impulse sequence, sensitivity curves and
    insensitivity widths, and the residual vibration of measured cycles.
fir
    Discretisation of an impulse sequence to a causal FIR at the command rate (split, round,
    exact), and the streaming multi-joint FIR with bumpless switching and re-timing.
trajectory
    Whole-trajectory shaping (resampling, convolution, derivatives) for
    joint_trajectory_controller.
"""

from .families import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_VIBRATION_TOLERANCE,
    FAMILIES,
    MAX_DAMPING,
    MAX_DURATION,
    Mode,
    Shaper,
    ShaperError,
    design,
    family_info,
    family_params,
    none_shaper,
)
from .fir import MAX_STAGES, RetimingShaper, SparseFir, StreamingShaper, discretize, fir_impulses
from .trajectory import shape_trajectory
from .vibration import (
    ResidualVibration,
    insensitivity_width,
    percentage_vibration,
    residual_vibration,
    settle_time,
    settling_time,
)

__all__ = [
    "DEFAULT_INSENSITIVITY",
    "DEFAULT_VIBRATION_TOLERANCE",
    "FAMILIES",
    "MAX_DAMPING",
    "MAX_DURATION",
    "MAX_STAGES",
    "Mode",
    "ResidualVibration",
    "RetimingShaper",
    "Shaper",
    "ShaperError",
    "SparseFir",
    "StreamingShaper",
    "design",
    "discretize",
    "family_info",
    "family_params",
    "fir_impulses",
    "insensitivity_width",
    "none_shaper",
    "percentage_vibration",
    "residual_vibration",
    "settle_time",
    "settling_time",
    "shape_trajectory",
]
