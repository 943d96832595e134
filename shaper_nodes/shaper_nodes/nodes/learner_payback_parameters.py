"""The learner node's payback mode's parameters (``payback.*``, :mod:`.learner_payback`): one typed declaration
(:class:`PaybackParams`), from which the per-move LIST mode declares them and docs/reference/parameters.md is
generated."""

from __future__ import annotations

from dataclasses import dataclass, field

from shaper_nodes.core.learning.list.pole_rule import POOL_CYCLES
from shaper_nodes.core.learning.list.stack import MAX_FACTORS
from shaper_nodes.ros.parameters import Spec, param, table

__all__ = ["PARAMETERS", "PaybackGroup", "PaybackParams"]


@dataclass(frozen=True)
class PaybackGroup:
    """payback.*: LIST per move with each factor chosen to pay before it is tried (nodes/learner_payback.py)."""

    enabled: bool = param(False, "With list.per_move: choose each move's factor from its reference cycle's"
                          " components and its predicted time cost (the reproduction's scheduled_list_factor)"
                          " instead of the iterative LIST learner; needs payback.controller.", read_only=True)
    controller: str = param("/shaper/follow_joint_trajectory", "The FollowJointTrajectory action the learner's"
                            " ~/follow_joint_trajectory sends each goal on to, unchanged (the shaper node's proxy);"
                            " the goals' waypoints predict the factors' time cost.", read_only=True)
    action_timeout: float = param(30.0, "How long a goal waits for the next action server and its answer, s.",
                                  (0.1, 600.0), read_only=True)
    rate_hz: float = param(500.0, "The shaper node's command rate, Hz (the predicted shaped command's).",
                           (1.0, 10000.0), read_only=True)
    joint_tolerance: float = param(5e-5, "The settling band of the predicted command, rad (0.05 mm at 1 m of"
                                   " reach).", (1e-9, 1.0), read_only=True)
    servo_zeta: float = param(0.12, "Damping ratio from which an identified eigenvalue is the position loop's,"
                              " not a mode's.", (0.01, 0.99), read_only=True)
    settle_tolerance: float = param(5e-5, "With no schedule at a move's goal: the settled flange's band, m, that"
                                    " the move's measured move + settle time is taken to (on the accelerometer, at"
                                    " a x (2 pi f)^2, f the lowest mode identified in its first reference, 10 Hz if"
                                    " none).", (1e-7, 0.01), read_only=True)
    max_factors: int = param(1, "Most factors stacked per move: after a factor is kept, a new reference with it in"
                             " place chooses the next on what still rings (1: one factor per move).",
                             (1, MAX_FACTORS), read_only=True)
    pool_cycles: int = param(POOL_CYCLES, "A move over a schedule with no factor kept whose reference finds none"
                             " predicted to pay runs its reference again, up to this many cycles, the windows"
                             " pooled (aligned at the commanded end, averaged), the loop's pole searched in them;"
                             " a factor on it is judged by its amplitude at the pole in its own windows pooled (up"
                             " to this many). 0: the one-window rule only. On by default: with accelerometer noise"
                             " one window finds nothing for most moves, and a pooled reference runs the schedule"
                             " alone (nodes/learner_payback_pole.py).", (0, 10), read_only=True)


@dataclass(frozen=True)
class PaybackParams:
    """The payback rule's parameters (declared by the per-move LIST mode)."""

    payback: PaybackGroup = field(default_factory=PaybackGroup)


#: the payback rule's parameters (derived from PaybackParams)
PARAMETERS: tuple[Spec, ...] = table(PaybackParams)
