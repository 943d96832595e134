"""The speed learner's hold before a raise: the peaks predicted at the next factor from those measured, the factor
they allow, and the learner holding (or raising only part of its step) with the joint named; its state round-trips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.learning.speed import SpeedError, SpeedLearner, SpeedSettings, peak_check
from shaper_nodes.core.learning.speed_peaks import PeakLimits, allowed_factor, fit, predict

NAMES = ("shoulder_pan_joint", "wrist_1_joint")
LIMITS = PeakLimits(NAMES, {"effort": np.array([150.0, 28.0]), "velocity": np.array([math.pi, math.pi])}, 0.05)


def test_one_measured_factor_scales_all_of_the_peak_by_s_squared_and_a_speed_by_s():
    rows = [(1.5, [90.0, 7.0])]
    assert predict(rows, 1.8, 2) == pytest.approx([90.0 * 1.44, 7.0 * 1.44])
    assert predict(rows, 1.8, 1) == pytest.approx([90.0 * 1.2, 7.0 * 1.2])
    # the factor the rule allows: 95 % of 150 N m reached at 1.5 sqrt(142.5 / 90)
    f, why = allowed_factor({"effort": rows}, LIMITS, 1.5, 2.0)
    assert f == pytest.approx(1.5 * math.sqrt(142.5 / 90.0))
    assert why == ("joint shoulder_pan_joint: predicted |effort| 160 N m at x2.000 above 142.5 N m (95 % of its limit"
                   " 150 N m)")
    assert allowed_factor({"effort": rows}, LIMITS, 1.5, 1.6) == (1.6, "")  # within: the target itself


def test_two_or_more_factors_fit_a_plus_b_s_squared_and_the_conservative_of_fit_and_rule_is_taken():
    a, b = 40.0, 30.0  # N m: gravity's part, the dynamic part at s = 1
    s = np.array([1.0, 1.2, 1.4])
    rows = [(f, [a + b * f * f, 1.0]) for f in s]
    fa, fb = fit(s, np.asarray([r[1] for r in rows]), 2)
    assert fa[0] == pytest.approx(a) and fb[0] == pytest.approx(b)
    # a >= 0 on the model: the rule from the largest factor (all of the peak x s^2) is the larger above it
    at = predict(rows, 1.8, 2)[0]
    assert at == pytest.approx((a + b * 1.96) * (1.8 / 1.4) ** 2) and at > a + b * 1.8 ** 2
    # peaks growing faster than s^2 (the fit's a < 0): a = 0 with its own slope, above the rule from the top
    steep = [(1.0, [10.0, 1.0]), (1.2, [30.0, 1.0]), (1.4, [50.0, 1.0])]
    fa, fb = fit(np.array([1.0, 1.2, 1.4]), np.asarray([r[1] for r in steep]), 2)
    assert fa[0] == 0.0 and fb[0] == pytest.approx((10 + 30 * 1.44 + 50 * 1.96) / (1 + 1.44 ** 2 + 1.96 ** 2))
    assert predict(steep, 1.6, 2)[0] == pytest.approx(max(50 * (1.6 / 1.4) ** 2, fb[0] * 2.56))
    # the allowed factor is where the larger prediction reaches 95 % of the limit
    f, _ = allowed_factor({"effort": rows}, LIMITS, 1.4, 3.0)
    assert predict(rows, f, 2)[0] == pytest.approx(142.5)


def test_between_measured_factors_the_rule_scales_from_the_one_below_not_the_top():
    # measured at 1.0, 1.1 and 1.2 (1.2 bad on its residual: the learner is back at 1.0, bisecting towards 1.1)
    rows = [(1.0, [100.0, 1.0]), (1.1, [106.0, 1.0]), (1.2, [113.0, 1.0])]
    assert predict(rows, 1.05, 2)[0] == pytest.approx(max(100.0 * 1.05 ** 2, float(
        np.polyval(np.polyfit([1.0, 1.21, 1.44], [100.0, 106.0, 113.0], 1), 1.05 ** 2))))
    level = 102.0  # N m: 95 % of the limit, 2 % above what x1.0 measured
    tight = PeakLimits(NAMES, {"effort": np.array([level / 0.95, 28.0])}, 0.05)
    f, why = allowed_factor({"effort": rows}, tight, 1.0, 1.05)
    assert f == pytest.approx(math.sqrt(level / 100.0)) and "at x1.050" in why  # the rule from x1.0 bounds it
    # (from the top, x1.2, the rule would allow 1.2 sqrt(102 / 113) = 1.14 and the fit 1.035: both above it)
    # the learner there holds (the raise would be below the resolution), not raised by the fit through x1.2
    sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=2.0))
    for peaks in rows:
        sp.record(peaks[0], {"effort": peaks[1]})
    sp.factor, sp.good, sp.failed = 1.0, 1.0, 1.1
    assert sp.update(True, "", {"effort": [100.0, 1.0]}, tight) == 1.0 and "held at x1.000" in sp.held


def test_a_joint_without_a_limit_or_without_peaks_bounds_nothing_and_speeds_bound_by_s():
    free = PeakLimits(NAMES, {"effort": np.array([np.inf, np.inf]), "velocity": np.array([math.pi, np.inf])}, 0.0)
    assert allowed_factor({"effort": [(1.0, [1e4, 1e4])]}, free, 1.0, 1.5) == (1.5, "")
    f, why = allowed_factor({"velocity": [(1.0, [2.0, 50.0])]}, free, 1.0, 2.0)
    assert f == pytest.approx(math.pi / 2.0) and why.startswith("joint shoulder_pan_joint: predicted |velocity| 4")
    assert allowed_factor({}, LIMITS, 1.5, 1.7) == (1.7, "")


def test_the_learner_raises_only_as_far_as_the_prediction_allows_then_holds_naming_the_joint():
    def truth(s: float) -> list[float]:  # session 10's base rotation: 0.59 of 150 N m at x1.0, 103 % at x1.7
        return [150.0 * (0.346 + 0.2456 * s * s), 10.0]

    sp = SpeedLearner(SpeedSettings(step=0.1, ceiling=2.0))
    seen = []
    for _ in range(10):
        used = sp.factor
        peaks = truth(used)
        assert peaks[0] < 150.0  # no cycle at or above the limit
        seen.append((used, sp.update(True, "", {"effort": peaks, "velocity": [1.5 * used, 0.1]}, LIMITS)))
    assert [round(u, 1) for u, _ in seen[:6]] == [1.0, 1.1, 1.2, 1.3, 1.4, 1.5]  # far from the limit: the step
    assert 1.5 < seen[6][0] < 1.6  # at x1.5 (0.899 of the limit) the step to 1.6 is cut: 153 N m predicted
    assert seen[-1][0] == seen[-1][1] and sp.holding  # then it holds: the next raise would be below the resolution
    assert sp.held.startswith("joint shoulder_pan_joint: predicted |effort|") and "held at x1.54" in sp.held
    assert sp.history[-1]["held"] == sp.held and sp.history[5]["held"].endswith("raised only to x1.542")
    assert sp.cap is not None and sp.cap - sp.factor < sp.settings.resolution
    # a bad cycle still lowers at once (at the good factor itself: that no longer holds, to the floor); the peaks
    # stay, the relearn forgets them
    sp.update(False, "settled residual")
    assert sp.factor == 1.0 and sp.good is None and sp.peaks["effort"]
    sp.relearn()
    assert sp.peaks == {} and sp.cap is None and sp.factor == 1.0 and not sp.holding


def test_without_limits_or_peaks_the_learner_is_unchanged_and_the_peaks_kept_are_the_largest_per_factor():
    a, b = SpeedLearner(SpeedSettings(step=0.2)), SpeedLearner(SpeedSettings(step=0.2))
    for _ in range(4):
        a.update(True)
        b.update(True, "", {"effort": [100.0, 1.0]})  # peaks but no limits: kept, no prediction
    assert a.factor == b.factor == pytest.approx(1.8) and b.cap is None and b.held == ""
    b.record(1.8, {"effort": [120.0, 0.5], "velocity": None})
    b.record(1.8, {"effort": [110.0, 2.0]})
    b.record(1.9, {"effort": [np.nan, 1.0]})  # (a non-finite peak is not kept: it is a violation, not a measure)
    assert b.peaks["effort"][-1] == (1.8, [120.0, 2.0]) and "velocity" not in b.peaks
    with pytest.raises(SpeedError, match="3 effort peaks for a move measured on 2 joints"):
        b.record(1.0, {"effort": [1.0, 2.0, 3.0]})


def test_the_state_with_its_peaks_round_trips_a_version_1_state_is_read_and_bad_peaks_refused():
    sp = SpeedLearner()
    sp.update(True, "", {"effort": [90.0, 7.0], "velocity": [1.0, 0.5]}, LIMITS)
    d = sp.to_dict()
    assert d["version"] == 2 and d["peaks"]["effort"] == [[1.0, [90.0, 7.0]]]
    assert SpeedLearner.from_dict(d).to_dict() == d
    old = {k: v for k, v in d.items() if k not in ("peaks", "cap")} | {"version": 1}
    back = SpeedLearner.from_dict(old)
    assert back.peaks == {} and back.cap is None and back.factor == sp.factor
    with pytest.raises(SpeedError, match="entries differ"):
        SpeedLearner.from_dict({**old, "cap": 1.2})  # (version 1 has no cap)
    with pytest.raises(SpeedError, match="finite peak per joint"):
        SpeedLearner.from_dict({**d, "peaks": {"effort": [[1.0, [np.nan, 1.0]]]}})
    with pytest.raises(SpeedError, match="finite peak per joint"):
        SpeedLearner.from_dict({**d, "peaks": {"effort": [[1.0]]}})
    with pytest.raises(SpeedError, match="must be a dictionary of"):
        SpeedLearner.from_dict({**d, "peaks": {"current": []}})
    with pytest.raises(SpeedError, match="cap"):
        SpeedLearner.from_dict({**d, "cap": -1.0})


def test_a_measured_speed_past_its_limit_is_named_as_an_effort_is():
    ratio, joint, breach = peak_check([3.3, 1.0], [math.pi, math.pi], NAMES, "velocity", "rad/s")
    assert joint == 0 and ratio == pytest.approx(3.3 / math.pi)
    assert breach == "joint shoulder_pan_joint: measured |velocity| 3.3 rad/s above its limit 3.142 rad/s"
    with pytest.raises(SpeedError, match="1 velocities against 2 limits"):
        peak_check([1.0], [1.0, 1.0], NAMES, "velocity", "rad/s")
