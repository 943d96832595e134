"""The Learning Input Shaping Technique (LIST, seed 003), free of ROS.

Modules
-------
learner
    The two-impulse parameters, the measurement of M and phi, and :class:`ListLearner`, the
    state machine that updates A1 and T2 cycle by cycle (with rollback, patience and hold).
session
    The bookkeeping the learner node and the offline replay share: which shaper a cycle ran
    with, the accelerometer buffer, and cycle events.
"""

from .learner import ListConfig, ListError, ListLearner, ListParams, ListUpdate
from .session import ListSession, SessionResult, list_config

__all__ = [
    "ListConfig",
    "ListError",
    "ListLearner",
    "ListParams",
    "ListSession",
    "ListUpdate",
    "SessionResult",
    "list_config",
]
