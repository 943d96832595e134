"""What the cases that add two-impulse factors share: the residual's components, the bands, the impulse
sequences' products."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from reproductions.arm_learning.runs import Run
from reproductions.residual_split import SERVO_ZETA  # more damped than this: the position loop's transient

#: the flange's settling band over the arm's reach (1 m), rad: the joint-space band in which the shaped command's own
#: settling predicts a factor's time cost (:func:`~shaper_nodes.core.learning.list.payback.time_cost`)
JOINT_TOLERANCE = 0.05e-3 / 1.0


#: ``scheduled_list_factor`` fits the residual from the commanded end with up to this many more modes than the modes
#: that ring fill (:func:`~shaper_nodes.core.learning.list.payback.components`' ``extra_damped``;
#: :data:`~shaper_nodes.core.learning.list.payback.EXTRA_DAMPED`)
SERVO_EXTRA = 2


def _components(run: Run, extra_damped: int = 0) -> list[Any]:
    """The components of a run's residual (:func:`~shaper_nodes.core.learning.list.payback.components`)."""
    from shaper_nodes.core.learning.list.payback import components

    return components(run.times, run.imu, run.planned_end + run.measures.delay_s, SERVO_ZETA,
                      extra_damped=extra_damped)


#: the ``list`` case's factor stays within this fraction of the frequency it started from (the identified mode;
#: :meth:`~shaper_nodes.core.learning.list.ListParams.t2_band`)
LIST_BAND = 0.1


def _shaper(impulses: tuple[Any, Any] | None) -> Any:
    """A ``custom`` shaper of (amplitudes, times)."""
    from shaper_nodes.core.shaping import Shaper

    assert impulses is not None
    return Shaper(np.asarray(impulses[0]), np.asarray(impulses[1]), "custom")


def _times(a: tuple[Any, Any] | None, b: tuple[Any, Any] | None) -> tuple[Any, Any] | None:
    """The convolution of two impulse sequences (amplitudes, times); None is the identity."""
    from shaper_nodes.core.shaping.families import convolve

    return b if a is None else a if b is None else convolve(a, b)


def _factor_count(impulses: tuple[np.ndarray, np.ndarray]) -> int:
    """How many two-impulse factors a frozen product holds (2^n impulses)."""
    return int(round(math.log2(len(impulses[0]))))
