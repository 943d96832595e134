"""Takagi-Sugeno interpolation (seed 004): membership functions, weights, models and modes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shaper_nodes.core.scheduling.fuzzy import (
    FuzzyError,
    Gaussian,
    Rule,
    RuleBase,
    Trapezoidal,
    Triangular,
    membership,
    modes_of,
    rule_base_from_dict,
    triangular_partition,
)

FAST = settings(max_examples=80, deadline=None)


def mck(m, c, k):
    """Base-fixed m-c-k: x' = A x + B u, state (x, x')."""
    return np.array([[0.0, 1.0], [-k / m, -c / m]]), np.array([[0.0], [1.0 / m]])


def test_membership_formulas():
    tri = Triangular(0.0, 1.0, 3.0)
    assert [tri(z) for z in (-1, 0, 0.5, 1, 2, 3, 4)] == [0, 0, 0.5, 1, 0.5, 0, 0]
    trap = Trapezoidal(0.0, 1.0, 2.0, 4.0)
    assert [trap(z) for z in (-1, 0.5, 1, 1.5, 2, 3, 4.5)] == [0, 0.5, 1, 1, 1, 0.5, 0]
    crisp = Trapezoidal(-1.0, -1.0, 0.35, 0.35)  # a crisp set: seed 004 eq. (9)
    assert crisp(0.35) == 1.0 and crisp(0.3500001) == 0.0 and crisp(-1.0) == 1.0
    g = Gaussian(1.0, 0.5)
    assert g(1.0) == 1.0 and g(1.5) == pytest.approx(math.exp(-0.5))
    assert membership("Gaussian", [1.0, 0.5]) == g
    for kind, params in [("triangular", [0, 2, 1]), ("trapezoidal", [0, 1]), ("gaussian", [0, 0]),
                         ("bell", [0, 1, 2]), ("triangular", [0, float("nan"), 1])]:
        with pytest.raises(FuzzyError):
            membership(kind, params)


@FAST
@given(st.floats(-5, 5), st.floats(0.1, 100), st.floats(0, 10), st.floats(-10, 10))
def test_one_rule_returns_that_rules_model(m_log, k, c, z):
    a, b = mck(10 ** (m_log / 5), c, k)
    base = RuleBase(("q",), (Rule((Gaussian(0.0, 1.0),), a, b),), ranges=[[-3.0, 3.0]])
    out = base.evaluate([z])
    np.testing.assert_array_equal(out.a, a)
    np.testing.assert_array_equal(out.b, b)
    assert out.weights.tolist() == [1.0]
    assert out.clamped == (abs(z) > 3.0,)


@st.composite
def partitions(draw):
    n = draw(st.integers(1, 7))
    steps = draw(st.lists(st.floats(0.01, 10.0), min_size=n, max_size=n))
    pts = np.cumsum(steps) - 5.0
    kind = draw(st.sampled_from(["triangular", "gaussian", "trapezoidal"]))
    if kind == "triangular":
        mfs = triangular_partition(pts)
    elif kind == "gaussian":
        # wide enough that no gap opens between neighbours (a gap is an error, tested below)
        mfs = [Gaussian(float(p), draw(st.floats(0.3, 3.0)) * max(steps)) for p in pts]
    else:  # overlapping trapezoids, cores around the points
        lo = np.concatenate([[pts[0] - 1], pts[:-1]])
        hi = np.concatenate([pts[1:], [pts[-1] + 1]])
        mfs = [Trapezoidal(float(a), float(a + 0.4 * (p - a)), float(p + 0.4 * (h - p)), float(h))
               for a, p, h in zip(lo, pts, hi, strict=True)]
    return pts, mfs


@FAST
@given(partitions(), partitions(), st.floats(0, 1), st.floats(0, 1))
def test_weights_sum_to_one_everywhere_in_range(p1, p2, s1, s2):
    (_, mf1), (_, mf2) = p1, p2
    a, b = mck(1.0, 0.1, 1.0)
    rules = [Rule((f, g), a, b) for f in mf1 for g in mf2]  # a grid over two premises
    base = RuleBase(("q1", "q2"), tuple(rules))
    z = base.ranges[:, 0] + np.array([s1, s2]) * (base.ranges[:, 1] - base.ranges[:, 0])
    w = base.weights(z)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(w >= 0)


def test_interpolated_model_is_the_weighted_mean_and_exact_at_operating_points():
    pts = [0.0, 1.0, 2.0]
    models = [mck(1.0 + p, 0.1, 4.0) for p in pts]
    base = RuleBase(("q",), tuple(Rule((mf,), a, b, name=str(p))
                                   for mf, p, (a, b) in zip(triangular_partition(pts), pts, models, strict=True)))
    for p, (a, b) in zip(pts, models, strict=True):
        out = base.evaluate([p])
        np.testing.assert_allclose(out.a, a, rtol=0, atol=1e-15)
        np.testing.assert_allclose(out.b, b, rtol=0, atol=1e-15)
    out = base.evaluate([0.25])
    np.testing.assert_allclose(out.weights, [0.75, 0.25, 0.0])
    np.testing.assert_allclose(out.a, 0.75 * models[0][0] + 0.25 * models[1][0])
    assert out.dominant == 0
    # outside the range: clamped to the end, reported, not extrapolated
    out = base.evaluate([7.0])
    assert out.clamped == (True,) and out.z.tolist() == [2.0] and out.z_in.tolist() == [7.0]
    np.testing.assert_allclose(out.a, models[2][0])


@FAST
@given(st.floats(0.1, 100.0), st.floats(0.0, 0.25), st.floats(0.1, 10.0))
def test_modes_of_a_known_system(omega, zeta, m):
    a, _ = mck(m, 2 * zeta * omega * m, omega**2 * m)
    (mode,) = modes_of(a)
    assert mode.omega == pytest.approx(omega, rel=1e-9)
    assert mode.zeta == pytest.approx(zeta, rel=1e-7, abs=1e-9)


def test_modes_keep_every_lightly_damped_pair_and_drop_the_rest():
    blocks = [mck(1.0, 2 * 0.02 * 3.0, 9.0)[0], mck(1.0, 2 * 0.1 * 10.0, 100.0)[0], mck(1.0, 2 * 0.6 * 5.0, 25.0)[0]]
    a = np.zeros((6, 6))
    for i, blk in enumerate(blocks):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blk
    modes = modes_of(a, max_damping=0.3)
    assert [round(m.omega, 9) for m in modes] == [3.0, 10.0]
    assert [round(m.zeta, 9) for m in modes] == [0.02, 0.1]
    assert len(modes_of(a, max_damping=0.7)) == 3


def test_direct_interpolation_of_mode_parameters():
    spec = {"premises": ["q"], "rules": {
        "low": {"membership": ["triangular"], "membership_params": [0, 0, 1], "natural_frequency": [2.0],
                "damping_ratio": [0.02]},
        "high": {"membership": ["triangular"], "membership_params": [0, 1, 1], "natural_frequency": [1.0],
                 "damping_ratio": [0.06]}}}
    base = rule_base_from_dict(spec)
    (mode,) = base.evaluate([0.25], method="modes").modes
    assert mode.omega == pytest.approx(1.75) and mode.zeta == pytest.approx(0.03)
    with pytest.raises(FuzzyError, match="needs rules with models"):
        base.evaluate([0.25], method="model")


def test_rule_base_from_dict_checks_everything():
    a, b = mck(1.0, 0.1, 1.0)
    good = {"premises": ["q"], "rules": {"r": {"membership": ["gaussian"], "membership_params": [0, 1],
                                               "a_matrix": a.ravel().tolist(), "b_matrix": b.ravel().tolist()}}}
    base = rule_base_from_dict(good)
    np.testing.assert_array_equal(base.evaluate([0.0]).a, a)

    def bad(match, **change):
        rule = {**good["rules"]["r"], **change}
        with pytest.raises(FuzzyError, match=match):
            rule_base_from_dict({**good, "rules": {"r": rule}})

    bad("n\\*n values", a_matrix=[1.0, 2.0, 3.0])
    bad("b_matrix needs", b_matrix=[1.0, 2.0, 3.0])
    bad("membership_params has 3", membership_params=[0, 1, 2])
    bad("finite", a_matrix=[0, 1, float("inf"), 0])
    bad(r"a_matrix\[2\] = -1e\+308 is beyond \+-1e\+12", a_matrix=[0, 1, -1e308, -1e308])
    bad(r"b_matrix\[1\] = 1e\+200 is beyond", b_matrix=[0, 1e200])
    big = (a * 1e9).ravel().tolist()  # a mode at 5 kHz still loads
    rule_base_from_dict({**good, "rules": {"r": {**good["rules"]["r"], "a_matrix": big}}})
    bad("unknown membership", membership=["sigmoid"])
    bad("1 natural frequencies but 0", natural_frequency=[1.0])
    bad("1 natural frequencies but 0", frequency_hz=[1.0])
    bad("not both", frequency_hz=[1.0], natural_frequency=[6.3], damping_ratio=[0.1])
    hz = rule_base_from_dict({**good, "rules": {"r": {**good["rules"]["r"], "frequency_hz": [2.0],
                                                      "damping_ratio": [0.1]}}})
    assert hz.rules[0].modes[0].omega == pytest.approx(4 * np.pi)  # Hz in, rad/s in the core
    with pytest.raises(FuzzyError, match="premise values"):
        base.evaluate([0.0, 1.0])
    with pytest.raises(FuzzyError, match="finite"):
        base.evaluate([float("nan")])
    with pytest.raises(FuzzyError, match="at least one rule"):
        rule_base_from_dict({"premises": ["q"], "rules": {}})


def test_a_gap_between_membership_functions_is_an_error_that_names_the_value():
    a, b = mck(1.0, 0.1, 1.0)
    base = RuleBase(("q",), (Rule((Triangular(0, 0, 1),), a, b), Rule((Triangular(2, 3, 3),), a, b)))
    with pytest.raises(FuzzyError, match=r"no rule fires at q = 1\.5"):
        base.evaluate([1.5])
