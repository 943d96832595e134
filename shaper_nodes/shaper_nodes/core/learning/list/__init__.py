"""The Learning Input Shaping Technique (LIST, seed 003), free of ROS.

Modules
-------
params
    The two-impulse parameters (:class:`ListParams`), their structures and residual factor,
    the update formulas, and the learner's settings (:class:`ListConfig`, :class:`ListError`).
measure
    The unshaped reference cycle (:class:`Reference`, :func:`make_reference`), the residual
    window, and M, phi and rho of a shaped cycle (:func:`.measure.measure`, :class:`Measurement`).
trials
    What the learner records of a cycle: :class:`ListUpdate` (the outcome it reports), its
    trials and steps, and the search of the minimum of M.
learner
    :class:`ListLearner`, the state machine that updates A1 and T2 cycle by cycle (with
    rollback, patience and hold): the update and what to apply next.
phases
    The learner's rules after a measured trial (:class:`.phases.PhaseRules`): ranking, rollback, patience,
    the phase's steps (phi's model, the sensitivity step, the search of M alone) within bounds and maximum step.
state
    The learner's fields, the bounds of its parameters and its state as a dictionary
    (:class:`.state.LearnerState`, with :meth:`~.state.LearnerState.to_dict` and ``from_dict``).
payback
    A factor over a move's base shaper chosen to pay before it is tried: the residual's components
    (:func:`.payback.components`), the time cost predicted from the shaped command
    (:func:`.payback.time_cost`), the least predicted residual within it (:func:`.payback.paying_factor`).
stack
    A move's stacked factors (:class:`.stack.FactorStack`: those kept, each because it paid, and the one on
    trial) and their convolution, the one impulse sequence the move's goals run with (:func:`.stack.stack_shaper`).
loop_pole
    The position loop's damped pole in a noisy residual: reference windows pooled
    (:class:`.loop_pole.Pool`), the pole searched with the ringing modes fixed (:func:`.loop_pole.loop_pole`),
    a trial's change at the pole in standard errors (:func:`.loop_pole.change_at_pole`).
pole_rule
    The pooled-pole rule per move (:func:`.pole_rule.pole_pick`, :func:`.pole_rule.judge_pole`,
    :class:`.pole_rule.PoleState`): one copy for the learner node and the reproduction.
settle
    A move's move + settle time from its accelerometer, measured and predicted, for a move with no schedule.
session
    The bookkeeping the learner node and the offline replay share: which shaper a cycle ran
    with, the accelerometer buffer (bounded: the cycle duration limit), the sensor's range,
    cycle events, and the learner node's state document.
"""

from .learner import ListLearner
from .measure import Measurement, Reference, make_reference
from .params import ListConfig, ListError, ListParams, lti_factor
from .session import ListSession, SessionResult, learner_from_state, list_config
from .trials import ListUpdate

__all__ = [
    "ListConfig",
    "ListError",
    "ListLearner",
    "ListParams",
    "ListSession",
    "ListUpdate",
    "Measurement",
    "Reference",
    "SessionResult",
    "learner_from_state",
    "list_config",
    "lti_factor",
    "make_reference",
]
