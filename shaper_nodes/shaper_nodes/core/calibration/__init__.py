"""Calibration of a robot's workspace, free of ROS: the plan, and the pose map it measures.

Modules
-------
plan
    The poses (a grid over the joints that change the dynamics, or a list), the excitation at
    each (an out-and-back quintic move, repeated), their order, their duration, and every
    limit checked before anything moves (:class:`PlanError`).
posemap
    The modes at each pose from its free decays (identified per repeat, combined, flagged when
    repeats disagree), the scheduler's rule base built from the grid, the fallback shaper at
    home, and the residual vibration a shaper is predicted to leave.
"""

from .plan import Limits, Plan, PlanConfig, PlanError, PoseStep, Waypoint, make_limits, make_plan, plan_to_dict
from .posemap import (
    Decay,
    IdentifySettings,
    PoseResult,
    fallback,
    identify_pose,
    predicted_residual,
    rule_base_spec,
    worst_residual,
)

__all__ = [
    "Decay",
    "IdentifySettings",
    "Limits",
    "Plan",
    "PlanConfig",
    "PlanError",
    "PoseResult",
    "PoseStep",
    "Waypoint",
    "fallback",
    "identify_pose",
    "make_limits",
    "make_plan",
    "plan_to_dict",
    "predicted_residual",
    "rule_base_spec",
    "worst_residual",
]
