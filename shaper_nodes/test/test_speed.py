"""The per-move speed learner: raise while good, lower at once, bisect, hold; its state round-trips."""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.learning.speed import (
    SpeedError,
    SpeedLearner,
    SpeedSettings,
    effort_check,
    limit_ceiling,
    limits_held,
)


def test_the_factor_rises_by_the_step_while_cycles_are_good_and_stops_at_the_ceiling():
    sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=1.25))
    assert sp.factor == 1.0
    assert [round(sp.update(True), 6) for _ in range(4)] == [1.1, 1.2, 1.25, 1.25]
    assert sp.holding


def test_a_violation_lowers_the_factor_at_once_to_the_last_good_one_and_later_raises_bisect():
    sp = SpeedLearner(SpeedSettings(step=0.2, ceiling=3.0, resolution=0.04))
    sp.update(True)  # 1.0 good -> 1.2
    sp.update(True)  # 1.2 good -> 1.4
    assert sp.update(False, "residual 0.07 mm") == pytest.approx(1.2)  # 1.4 failed: back at once
    assert sp.update(True) == pytest.approx(1.3)  # half way to the failed factor
    assert sp.update(False) == pytest.approx(1.2)
    assert sp.update(True) == pytest.approx(1.25)
    assert sp.update(True) == pytest.approx(1.275)
    assert sp.update(True) == pytest.approx(1.275)  # within the resolution: holds
    assert sp.holding
    assert sp.history[2]["reason"] == "residual 0.07 mm"


def test_a_failure_at_the_planned_speed_holds_the_floor():
    sp = SpeedLearner()
    assert sp.update(False) == 1.0
    assert sp.holding


def test_relearn_forgets_the_factors():
    sp = SpeedLearner()
    sp.update(True)
    sp.relearn()
    assert (sp.factor, sp.good, sp.failed) == (1.0, None, None)


def test_the_state_round_trips_and_bad_states_are_refused_with_the_entry_named():
    sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=1.5))
    sp.update(True)
    sp.update(False, "torque")
    back = SpeedLearner.from_dict(sp.to_dict())
    assert back.to_dict() == sp.to_dict()
    d = sp.to_dict()
    with pytest.raises(SpeedError, match="factor"):
        SpeedLearner.from_dict({**d, "factor": 9.0})
    with pytest.raises(SpeedError, match="unknown"):
        SpeedLearner.from_dict({**d, "extra": 1})
    with pytest.raises(SpeedError, match="version"):
        SpeedLearner.from_dict({**d, "version": 99})
    with pytest.raises(SpeedError, match="good"):
        SpeedLearner.from_dict({**d, "good": float("nan")})
    with pytest.raises(SpeedError, match="ceiling"):
        SpeedSettings(floor=2.0, ceiling=1.0)


def test_the_limit_ceiling_is_the_tightest_of_velocity_and_acceleration():
    v = np.array([[1.5, 0.5, 0.0]])
    a = np.array([[6.0, 2.0, 0.0]])
    # velocity: pi / 1.5 = 2.09; acceleration: sqrt(12 / 6) = 1.41 on joint 0
    assert limit_ceiling(v, a, [np.pi] * 3, [12.0] * 3) == pytest.approx(np.sqrt(2.0))
    assert limits_held(np.array([1.0, -3.0, 0.5]), [2.0, 2.0, 2.0]) == [1]
    with pytest.raises(SpeedError, match="> 0"):
        limit_ceiling(v, a, [0.0] * 3, [1.0] * 3)
    assert limit_ceiling(v, a, [np.pi] * 3, [np.inf] * 3) == pytest.approx(np.pi / 1.5)


def test_a_measured_effort_past_its_joints_limit_is_a_violation_that_lowers_the_factor_at_once():
    names = ["shoulder_pan_joint", "shoulder_lift_joint", "wrist_1_joint"]
    limits = [150.0, 150.0, 28.0]
    ratio, joint, breach = effort_check([30.0, -75.0, 13.0], limits, names)
    assert ratio == pytest.approx(0.5) and joint == 1 and breach is None  # within: the largest |effort| / limit
    ratio, joint, breach = effort_check([30.0, -75.0, -29.4], limits, names)
    assert ratio == pytest.approx(1.05) and joint == 2
    assert breach == "joint wrist_1_joint: measured |effort| 29.4 N m above its limit 28 N m"
    # at the limit is within; no limit (inf) counts 0; a nan effort is a violation
    assert effort_check([150.0, 0.0, 28.0], limits, names) == (1.0, 0, None)
    assert effort_check([1e6, 1.0, 1.0], [np.inf, 2.0, 2.0], names) == (0.5, 1, None)
    assert effort_check([np.nan, 1.0, 1.0], limits, names)[1:] == (0, "joint shoulder_pan_joint: measured |effort|"
                                                                    " nan N m above its limit 150 N m")
    # two joints past their limits: the one furthest past is named
    assert effort_check([160.0, 0.0, 56.0], limits, names)[1:] == (2, "joint wrist_1_joint: measured |effort| 56 N m"
                                                                    " above its limit 28 N m")
    with pytest.raises(SpeedError, match="2 efforts against 3 limits"):
        effort_check([1.0, 2.0], limits, names)
    # the learner's rule: a breach is a bad cycle, as a residual above the tolerance is
    sp = SpeedLearner(SpeedSettings(step=0.2, ceiling=2.0))
    sp.update(True)
    sp.update(True)
    assert sp.update(False, breach) == pytest.approx(1.2)
    assert sp.failed == pytest.approx(1.4) and sp.history[-1]["reason"] == breach
