"""The per-move LIST node's learner, started from the schedule's lowest mode, keeps its factor in its band.

``nodes/learner_moves.py`` builds a move's learner with :func:`schedule_config`: T2 bounded to
``start.t2_band(T2_BAND)``. Here the learner runs on a one-mode plant whose mode is 30 % below the
start (the schedule's estimate off by more than the band): without the band the factor walks to the
plant's mode; with it every factor sent stays within +-10 % of the start's frequency.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.signal import cont2discrete, dlsim

from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
from shaper_nodes.core.shaping import Mode
from shaper_nodes.nodes.learner_moves import T2_BAND, schedule_config

RATE = 500.0
OMEGA, ZETA = 2.0 * math.pi * 1.6, 0.05  # the plant's mode, rad/s
VMAX, AMAX, DISTANCE = 1.0, 2.0, 1.0
MOTION_END = DISTANCE / VMAX + VMAX / AMAX  # 1.5 s
END = 6.5
TIMES = np.arange(int(round(END * RATE)) + 1) / RATE
_A = np.array([[0.0, 1.0], [-OMEGA**2, -2.0 * ZETA * OMEGA]])
_B = np.array([[0.0], [OMEGA**2]])
PLANT = cont2discrete((_A, _B, -_A[1:], np.array([[OMEGA**2]])), 1.0 / RATE, method="foh")  # tip acceleration
#: the schedule's lowest mode: 30 % above the plant's
START = ListParams.from_mode(Mode(1.3 * OMEGA, ZETA))


def _trapezoid(t: np.ndarray) -> np.ndarray:
    ta, tc = VMAX / AMAX, MOTION_END - VMAX / AMAX
    return np.where(t <= 0.0, 0.0, np.where(
        t <= ta, 0.5 * AMAX * t**2, np.where(
            t <= tc, 0.5 * AMAX * ta**2 + VMAX * (t - ta), np.where(
                t < MOTION_END, DISTANCE - 0.5 * AMAX * (MOTION_END - t) ** 2, DISTANCE))))


def _cycle(params: ListParams | None) -> tuple[np.ndarray, np.ndarray]:
    if params is None:
        cmd = _trapezoid(TIMES)
    else:
        amps, times = params.impulses("zv2")
        cmd = sum(a * _trapezoid(TIMES - ti) for a, ti in zip(amps, times, strict=True))
    return TIMES.copy(), dlsim(PLANT, cmd, TIMES)[1][:, 0]


def _run(config: ListConfig, cycles: int = 12) -> list[ListParams]:
    """The factors the learner sends after its reference cycle, one per cycle."""
    learner = ListLearner(config, START)
    assert learner.update(*_cycle(None), MOTION_END, END, None).action == "reference"
    sent = []
    for _ in range(cycles):
        used = learner.params
        update = learner.update(*_cycle(used), MOTION_END, END, used)
        assert update.next is not None, update.reason
        sent.append(update.next)
    return sent


def test_a_move_from_the_schedule_keeps_its_factor_in_the_band():
    base = ListConfig(highpass_hz=0.5)
    lo, hi = START.t2_band(T2_BAND)
    config = schedule_config(base, START, None)
    assert config.t2_bounds == (lo, hi) and config.window_delay is None
    banded = _run(config)
    assert all(lo <= p.t2 <= hi for p in banded)
    # the factor's frequency 1 / (2 T2) within +-10 % of the start's: the mode it started on
    f0 = 1.0 / (2.0 * START.t2)
    assert all(abs(1.0 / (2.0 * p.t2) / f0 - 1.0) <= T2_BAND + 1e-12 for p in banded)
    # without the band (the learner's own bounds, 0.5-2 T2) the same run leaves it
    free = _run(base)
    assert max(p.t2 for p in free) > hi * 1.05


def test_the_window_starts_after_the_schedule_and_the_longest_factor():
    hi = START.t2_band(T2_BAND)[1]
    assert schedule_config(ListConfig(), START, 0.12).window_delay == pytest.approx(0.12 + hi)
    zvd = schedule_config(ListConfig(structure="zvd3"), START, 0.12)
    assert zvd.window_delay == pytest.approx(0.12 + 2.0 * hi)
    user = ListConfig(t2_bounds=(0.9 * START.t2, 1.05 * START.t2))  # list.t2_bounds set: kept
    assert schedule_config(user, START, None).t2_bounds == user.t2_bounds
    # the band only bounds T2: the rest of the configuration is the node's
    assert dataclasses.replace(schedule_config(base := ListConfig(rule="paper"), START, None),
                               t2_bounds=None) == base
