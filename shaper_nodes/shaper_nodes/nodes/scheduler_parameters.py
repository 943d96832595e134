"""The scheduler node's parameters (config/scheduler.yaml): :class:`SchedulerParams`, whose table :data:`PARAMETERS`
nodes/scheduler.py declares, and each rule's ``rules.<name>.*`` (:class:`RuleParams`, :func:`rule_table`).

Split from :mod:`shaper_nodes.nodes.scheduler` (which imports them from here, as before) to keep the node module
short.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from rclpy.parameter import Parameter

from shaper_nodes.core.scheduling import (
    MOVE_TOLERANCE,
    RateLimit,
    Scheduler,
    rule_base_from_dict,
)
from shaper_nodes.core.shaping import FAMILIES
from shaper_nodes.ros.parameters import Spec, param, table

_SHAPED = tuple(k for k in FAMILIES if k not in ("none", "custom"))


def _one_rule_base(family: str = "zv", **extra: Any) -> Scheduler:
    """A one-rule scheduler (to hold one parameter value against the core)."""
    rule = {"membership": ["triangular"], "membership_params": [0.0, 0.5, 1.0],
            "natural_frequency": [10.0], "damping_ratio": [0.05]}
    return Scheduler(rule_base_from_dict({"premises": ["joint_1"], "rules": {"r": rule}, **extra}), "modes", family)


@dataclass(frozen=True)
class SchedulerParams:
    """The scheduler node's parameters (see config/scheduler.yaml); each rule adds rules.<name>.* (RuleParams)."""

    premises: tuple[str, ...] = param(
        None, "Joints whose positions (from joint_states, rad or m) are the premise variables, in the"
        " order of each rule's membership functions.", read_only=True, type=Parameter.Type.STRING_ARRAY)
    range: tuple[float, ...] = param(
        None, "Valid range per premise [lo1, hi1, lo2, hi2, ...] (rad or m); outside it premises are"
        " clamped. Default: from the lowest to the highest membership peak.", read_only=True,
        type=Parameter.Type.DOUBLE_ARRAY)
    rule_names: tuple[str, ...] = param(
        None, "Names of the rules (operating points); each has rules.<name>.membership (one kind per"
        " premise: triangular, trapezoidal, gaussian), .membership_params (their parameters, concatenated), and"
        " .a_matrix (n*n, row-major) with .b_matrix (n*m), and/or .frequency_hz (Hz) with"
        " .damping_ratio, one per mode.", read_only=True, type=Parameter.Type.STRING_ARRAY)
    interpolation: str = param(
        "model", "'model': interpolate the linear models and take the modes of the result (seed"
        " 004); 'modes': interpolate the mode parameters directly.", choices=("model", "modes"), read_only=True)
    max_damping: float = param(0.3, "Modes with a damping ratio at or above this are not shaped for.", (0.01, 0.95),
                               read_only=True, check=lambda v: _one_rule_base(max_damping=v))
    family: str = param("zv", "Shaper family designed on the interpolated modes: " + ", ".join(_SHAPED) + ".",
                        read_only=True, check=lambda v: _one_rule_base(family=v))
    shaper: str = param("/shaper", "Fully qualified name of the shaper node.", read_only=True)
    joint_states: str = param("/joint_states", "Joint state topic.", read_only=True)
    feed: str = param("take", "Who takes joint_states on the lean node <name>_joint_states: 'take' (a take loop,"
                      " ros/take_loop.py) or 'thread' (rclpy's SingleThreadedExecutor).", choices=("take", "thread"),
                      read_only=True)
    period: float = param(0.05, "How often the rule base is evaluated, s (node clock; with lockstep, the joint"
                          " states' stamps).", (0.001, 60.0),
                          read_only=True)
    lockstep: bool = param(False, "A lockstep sim plant waits for this node (it names it in lockstep.readers, with"
                           " lockstep.lead one period): period counts on the joint states' stamps, and each joint"
                           " state is acknowledged once the shaper decided on it is answered, so a retune takes"
                           " effect at the next step whatever the load. False on a robot.", read_only=True)
    min_interval: float = param(0.1, "Least time between two shapers sent, s.", (0.0, 3600.0),
                                check=lambda v: RateLimit(min_interval=v))
    service_timeout: float = param(
        2.0, "A set_shaper call unanswered this long (wall time) is given up and sent again, s.", (0.01, 600.0))
    relative_change: float = param(
        0.01, "Least change that sends a new shaper: |d omega| / omega or |d zeta| / max(zeta,"
        " 0.01), fraction.", (0.0, 10.0), check=lambda v: RateLimit(relative_change=v))
    stale_timeout: float = param(1.0, "No joint states for this long, on the node's clock and on the steady"
                                 " clock, stops the updates, s.", (0.001, 3600.0))
    error_throttle: float = param(1.0, "Least time between two reports of the same problem, s.", (0.0, 3600.0))
    move_tolerance: float = param(
        MOVE_TOLERANCE, "A ~/shaper_at request is a move the learner corrected (~/set_move_shaper) when every"
        " joint of its start and pose is within this of the move's start and goal, rad or m.", (1e-6, 1.0),
        read_only=True)


@dataclass(frozen=True)
class RuleParams:
    """The parameters rules.<name>.* of one rule (declared for each name of rule_names)."""

    membership: tuple[str, ...] = param(None, "Rule <name>: membership.", read_only=True,
                                        type=Parameter.Type.STRING_ARRAY)
    membership_params: tuple[float, ...] = param(None, "Rule <name>: membership_params.", read_only=True,
                                                 type=Parameter.Type.DOUBLE_ARRAY)
    a_matrix: tuple[float, ...] = param(None, "Rule <name>: a_matrix.", read_only=True,
                                        type=Parameter.Type.DOUBLE_ARRAY)
    b_matrix: tuple[float, ...] = param(None, "Rule <name>: b_matrix.", read_only=True,
                                        type=Parameter.Type.DOUBLE_ARRAY)
    frequency_hz: tuple[float, ...] = param(None, "Rule <name>: natural frequency of each mode, Hz.",
                                            read_only=True, type=Parameter.Type.DOUBLE_ARRAY)
    damping_ratio: tuple[float, ...] = param(None, "Rule <name>: damping_ratio.", read_only=True,
                                             type=Parameter.Type.DOUBLE_ARRAY)


#: the scheduler node's parameters (derived from SchedulerParams)
PARAMETERS: tuple[Spec, ...] = table(SchedulerParams)


def rule_table(name: str) -> tuple[Spec, ...]:
    """The parameters rules.<name>.* of rule ``name``."""
    return tuple(replace(s, description=s.description.replace("<name>", name))
                 for s in table(RuleParams, f"rules.{name}."))
