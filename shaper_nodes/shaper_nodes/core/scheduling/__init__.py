"""Pose-dependent shaping by Takagi-Sugeno fuzzy interpolation (seed 004), free of ROS.

Modules
-------
fuzzy
    Membership functions, the rule base over one or more premises, the interpolated linear
    model and its lightly damped modes (or the mode parameters interpolated directly).
scheduler
    The shaper at the present pose (or any pose), the premise values of a pose given by joint
    names, and the learner's corrections kept per operating region.
moves
    The learner's corrections kept per move (start and goal poses), applied over the schedule.
rate_limit
    When a new scheduled shaper is sent: enough change of a mode, not too soon after the last,
    never faster than the shaper node retires shapers.
"""

from .fuzzy import FuzzyError, Interpolation, RuleBase, modes_of, rule_base_from_dict, triangular_partition
from .moves import MAX_MOVES, MOVE_TOLERANCE, MoveCorrection, MoveCorrections
from .rate_limit import RateLimit
from .scheduler import GRADE_TOLERANCE, MAX_POSE_JOINTS, Scheduler, premise_values, relative_change

__all__ = [
    "GRADE_TOLERANCE",
    "MAX_MOVES",
    "MAX_POSE_JOINTS",
    "MOVE_TOLERANCE",
    "FuzzyError",
    "Interpolation",
    "MoveCorrection",
    "MoveCorrections",
    "RateLimit",
    "RuleBase",
    "Scheduler",
    "modes_of",
    "premise_values",
    "relative_change",
    "rule_base_from_dict",
    "triangular_partition",
]
