"""Seed 002: plant set, controller, model matching and QFT bounds."""

import math

import numpy as np
import pytest

from shaper_nodes.core.closed_loop.qft import (
    DELTA_M,
    GAIN_FB,
    GAIN_FFB,
    WORKING_FREQUENCIES,
    QftError,
    bounds,
    closed_loop,
    controller_tf,
    corners,
    loop_specs,
    matching_error,
    matching_table,
    nichols,
    nominal,
    plant_tf,
)


def test_nominal_plant_is_the_papers():
    p = nominal()
    assert p.omega_n == pytest.approx(40 * math.pi, rel=1e-4)
    assert p.zeta == pytest.approx(0.1, rel=1e-4)
    for q in corners():  # every corner is 35 % off the nominal in each parameter
        for x, x0 in zip((q.m, q.c, q.k), (p.m, p.c, p.k), strict=True):
            assert abs(x / x0 - 1) == pytest.approx(0.35, abs=2e-3)


def test_closed_form_matching_error_equals_the_transfer_function_algebra():
    w = np.array(WORKING_FREQUENCIES)
    p0 = plant_tf(nominal())
    for design in ("fb", "ffb"):
        for q in corners()[1:3]:
            direct = np.abs(p0(1j * w) - closed_loop(design, q)(1j * w))
            assert np.allclose(matching_error(design, q, w), direct, rtol=1e-3, atol=1e-5)


def test_feedforward_feedback_matches_the_model_except_at_120_and_150():
    """FFB (gain 166.7): |M - Y/R| <= 0.1 for every corner at every working frequency but 120 and
    150 rad/s, where the paper's feedback design violates its bounds on purpose."""
    failing = {w for row in matching_table("ffb") for w in row.violations}
    assert failing == {120.0, 150.0}
    # at the nominal plant the feedforward-feedback loop is the model exactly
    assert np.max(matching_error("ffb", nominal(), WORKING_FREQUENCIES)) < 1e-9


def test_feedforward_feedback_is_less_conservative():
    g = controller_tf(GAIN_FB)(1j * np.array(WORKING_FREQUENCIES))
    gr = controller_tf(GAIN_FFB)(1j * np.array(WORKING_FREQUENCIES))
    assert np.all(np.abs(gr) < np.abs(g))  # Fig. 7
    # at low frequency, where the plants agree, (9) is far below (7)
    fb = max(matching_error("fb", q, [10.0])[0] for q in corners())
    ffb = max(matching_error("ffb", q, [10.0])[0] for q in corners())
    assert ffb < 0.05 * fb


def test_bounds_agree_with_the_direct_check():
    """L0 above the upper bound (or below the lower one) at a frequency <=> every template plant meets the spec."""
    for design, gain in (("fb", GAIN_FB), ("ffb", GAIN_FFB)):
        l0 = controller_tf(gain) * plant_tf(nominal())
        for w in WORKING_FREQUENCIES:
            for scale in (0.5, 1.0, 2.0):
                ph, mag = nichols(np.array([scale * l0(1j * w)]))
                lo, up = bounds(design, w, ph, plants=corners())
                meets_bound = np.isnan(up[0]) or mag[0] >= up[0] or mag[0] <= lo[0]
                e = max(matching_error(design, q, [w], gain * scale)[0] for q in corners())
                assert meets_bound == (e <= DELTA_M + 1e-12), (design, w, scale, e)


def test_disturbance_and_noise_specs():
    w = np.array([10.0, 125.0])
    s = loop_specs("ffb", nominal(), w)
    assert s["output_disturbance"][0] < 0.1  # integral action rejects a slow output disturbance
    assert s["noise"][0] == pytest.approx(1.0, abs=0.05)  # below the bandwidth the output follows the noise
    open_ = loop_specs("open", nominal(), w)
    assert s["input_disturbance"][1] < 0.2 * open_["input_disturbance"][1]  # resonance damped by the loop


def test_bad_input_is_named():
    with pytest.raises(QftError, match="gain"):
        controller_tf(-1.0)
    with pytest.raises(QftError, match="frequencies"):
        matching_table("ffb", omega=[10.0, float("nan")])
    with pytest.raises(QftError, match="design"):
        matching_table("pid")
