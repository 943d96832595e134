"""The learner node's speed-up per move's parameters (``mode: speed_moves``, :mod:`.learner_speed`): one typed
declaration (:class:`SpeedMovesParams`), from which the node declares them and docs/reference/parameters.md is
generated, and the check of the joint limits, at start-up and when ``speed.max_effort`` is set at run time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rcl_interfaces.msg import SetParametersResult

from shaper_nodes.ros.parameters import Spec, param, table

from .learner_list import TopicParams

__all__ = ["PARAMETERS", "SpeedGroup", "SpeedMovesParams", "on_set", "refusal"]


@dataclass(frozen=True)
class SpeedGroup:
    """speed.*: where the scaled goals go, the tolerance, the limits and the learner's steps."""

    controller: str = param("/shaper/follow_joint_trajectory", "The FollowJointTrajectory action the time-scaled"
                            " goals go to (the shaper node's proxy: scaling comes before shaping).", read_only=True)
    scheduler: str = param("/scheduler", "The scheduler asked (<scheduler>/shaper_at) for the shaper and the lowest"
                           " mode at each goal's final pose ('' = none: speed.shaper_delay and speed.frequency_hz).",
                           read_only=True)
    action_timeout: float = param(30.0, "How long a goal waits for the next action server and its answer, s.",
                                  (0.1, 600.0), read_only=True)
    match_timeout: float = param(2.0, "How long a goal of a move not known yet waits for its START on the cycle"
                                 " events, s (a known move's goal is matched at once by its first and last points).",
                                 (0.0, 60.0), read_only=True)
    tolerance: float = param(5e-5, "Tolerance of the settled flange, m (0.05 mm), converted to the accelerometer"
                             " level tolerance x (2 pi f)^2 at the goal's lowest mode f.", (1e-7, 0.1))
    frequency_hz: float = param(0.0, "The mode f of the conversion, Hz (0 = the schedule's lowest mode at the"
                                " goal).", (0.0, 1000.0))
    window: float = param(1.0, "Length of the residual window after the commanded motion's end, s.", (0.05, 10.0),
                          read_only=True)
    transient: float = param(0.1, "The position loop's transient left out at the window's start, s.", (0.0, 5.0),
                             read_only=True)
    shaper_delay: float = param(0.0, "The shaper's duration assumed when no scheduler answers, s.", (0.0, 10.0),
                                read_only=True)
    step: float = param(0.1, "Raise of a move's factor after a good cycle (before any bad one).", (1e-3, 10.0),
                        read_only=True)
    resolution: float = param(0.02, "The factor holds once the good and the bad factor are closer than this.",
                              (1e-4, 1.0), read_only=True)
    max_factor: float = param(2.0, "Largest time-scaling factor (1 = the planned speed).", (1.0, 10.0),
                              read_only=True)
    velocity: tuple[float, ...] = param([math.pi], "Largest joint speeds, rad/s (one per joint, or one for all).",
                                        read_only=True)
    acceleration: tuple[float, ...] = param([15.0], "Largest joint accelerations, rad/s^2 (one per joint, or one"
                                            " for all).", read_only=True)
    joint_states: str = param("/joint_states", "The joint states whose efforts (N m) and velocities (rad/s) are"
                              " watched during each move against speed.max_effort and speed.velocity ('' = none).",
                              read_only=True)
    max_effort: tuple[float, ...] = param([math.inf], "Largest measured joint efforts, N m (one per joint, or one"
                                          " for all; > 0, inf = not watched): a move past one is a bad cycle.")
    limit_margin: float = param(0.05, "Before a move's factor is raised, its joint torques and speeds are predicted"
                                " at the new factor from those measured (torque: a + b s^2, speed: b s); the raise"
                                " stops where a prediction passes its limit (speed.max_effort, speed.velocity) less"
                                " this fraction of it.", (0.0, 0.5))
    drift_status: str = param("identifier: drift", "The /diagnostics status whose WARN (a drift warning: a payload"
                              " change) starts every move's factor again from 1 ('' = none).", read_only=True)


@dataclass(frozen=True)
class SpeedMovesParams:
    """The speed-per-move mode's parameters."""

    speed: SpeedGroup = field(default_factory=SpeedGroup)
    topics: TopicParams = field(default_factory=TopicParams)


#: the speed-per-move mode's parameters (derived from SpeedMovesParams)
PARAMETERS: tuple[Spec, ...] = table(SpeedMovesParams)


def refusal(name: str, values: Any) -> str | None:
    """Why ``speed.<name>`` (velocity, acceleration: finite; max_effort: inf allowed) is refused (None: taken)."""
    vals = list(values)
    if vals and all(x > 0 and (name == "max_effort" or math.isfinite(x)) for x in vals):  # (nan fails)
        return None
    kind = "numbers > 0 (inf: not watched)" if name == "max_effort" else "finite numbers > 0"
    return f"speed.{name} must be one or more {kind}, got {vals}"


def on_set(params: list[Any]) -> SetParametersResult:
    """A new speed.max_effort checked as at start-up (the only limit set at run time)."""
    for p in params:
        why = refusal("max_effort", p.value) if p.name == "speed.max_effort" else None
        if why:
            return SetParametersResult(successful=False, reason=why)
    return SetParametersResult(successful=True)
