"""Input shaping, free of ROS: impulse sequences, their vibration, their FIR, whole trajectories.

Modules
-------
types
    The mode and shaper types (:class:`Mode`, :class:`Shaper`, :class:`ShaperError`), modes from
    lists of frequencies and damping ratios (:func:`modes_from_hz`), the limits of a design
    (damping, duration, parameter ranges) and the checks of its parameters.
families
    The registry of named designs (:data:`FAMILIES`, :func:`design`), the closed-form families
    (ZV, ZVD, ZV-D^n, MZV), custom sequences, and each family's description and figures of merit.
ei
    The extra-insensitive families with one, two or three humps (EI, 2-hump EI, 3-hump EI),
    solved numerically for the mode's damping ratio.
si
    The specified-insensitivity family: the shortest sequence keeping V <= V_tol over a band
    around every mode (linear programming, then SQP).
vibration
    The percentage vibration V(omega, zeta) of an impulse sequence, sensitivity curves and
    insensitivity widths, and the residual vibration of measured cycles.
fir
    Discretisation of an impulse sequence to a causal FIR at the command rate (split, round,
    exact), and the streaming multi-joint FIR with bumpless switching and re-timing; the FIR itself
    (:class:`SparseFir`) in :mod:`.sparse_fir`, a stage's history and paths in :mod:`.fir_stage`, the exact
    discretisation's correction in :mod:`.fir_exact`.
trajectory
    Whole-trajectory shaping (resampling, convolution, derivatives) for
    joint_trajectory_controller.
limits
    Joint limits of the shaper's output (parameters, a URDF's) and the checks of an output.
stream
    The rules of the shaper node's streamed commands (:class:`CommandStream`): input bounds, joint
    limits, time order, the output check and the filters' restart after a refused output, blocks of
    samples (their number: :func:`shaper_nodes.core.lockstep.block_rows`), trajectory fields that
    appear or vanish.
policy
    The shaper node's update policy: who may change the active shaper, and whether a change
    switches bumplessly or re-times the motion already commanded (the stage limit).
"""

from .families import FAMILIES, design, family_info, family_params, none_shaper
from .fir import MAX_STAGES, RetimingShaper, StreamingShaper, discretize, fir_impulses
from .policy import PolicyError, UpdatePolicy
from .sparse_fir import SparseFir
from .stream import CommandStream, check_times
from .trajectory import shape_trajectory
from .types import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_MAX_GAIN,
    DEFAULT_VIBRATION_TOLERANCE,
    MAX_DAMPING,
    MAX_DESIGN_MODES,
    MAX_DURATION,
    MAX_GAIN,
    MAX_IMPULSES,
    Mode,
    Shaper,
    ShaperError,
    modes_from_hz,
)
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
    "DEFAULT_MAX_GAIN",
    "DEFAULT_VIBRATION_TOLERANCE",
    "FAMILIES",
    "MAX_DAMPING",
    "MAX_DESIGN_MODES",
    "MAX_DURATION",
    "MAX_GAIN",
    "MAX_IMPULSES",
    "MAX_STAGES",
    "CommandStream",
    "Mode",
    "PolicyError",
    "ResidualVibration",
    "RetimingShaper",
    "Shaper",
    "ShaperError",
    "SparseFir",
    "StreamingShaper",
    "UpdatePolicy",
    "check_times",
    "design",
    "discretize",
    "family_info",
    "family_params",
    "fir_impulses",
    "insensitivity_width",
    "modes_from_hz",
    "none_shaper",
    "percentage_vibration",
    "residual_vibration",
    "settle_time",
    "settling_time",
    "shape_trajectory",
]
