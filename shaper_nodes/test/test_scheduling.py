"""Scheduling core: rate-limit measure, the learner's corrections per region, the shaper at a pose."""

import math

import numpy as np
import pytest

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.scheduling.fuzzy import Gaussian, Rule, RuleBase, Trapezoidal, Triangular, triangular_partition
from shaper_nodes.core.scheduling.scheduler import (
    GRADE_TOLERANCE,
    MAX_POSE_JOINTS,
    Scheduler,
    premise_values,
    relative_change,
)
from shaper_nodes.core.shaping.families import convolve, design
from shaper_nodes.core.shaping.types import Mode, Shaper, ShaperError


def base():
    pts = [0.0, 1.0, 2.0]
    rules = []
    for mf, p in zip(triangular_partition(pts), pts, strict=True):
        w, z = 2.0 - 0.5 * p, 0.05
        a = np.array([[0.0, 1.0], [-w * w, -2 * z * w]])
        rules.append(Rule((mf,), a, np.array([[0.0], [1.0]]), name=f"r{int(p)}"))
    return RuleBase(("q",), tuple(rules))


def same(a, b):
    return a.family == b.family and np.array_equal(a.times, b.times) and np.array_equal(a.amplitudes, b.amplitudes)


def test_relative_change():
    assert relative_change([Mode(1.0, 0.05)], [Mode(1.02, 0.05)]) == pytest.approx(0.02)
    assert relative_change([Mode(1.0, 0.0)], [Mode(1.0, 0.001)]) == pytest.approx(0.1)  # zeta floor 0.01
    assert relative_change([Mode(1.0, 0.05)], []) == math.inf


def test_corrections_are_exact_where_learned_and_kept_per_region():
    s = Scheduler(base())
    at = s.evaluate([0.3])
    sched = s.scheduled(at)
    assert same(s.shaper(at), sched)  # no correction yet: the scheduled ZV
    learned = Shaper(np.array([0.45, 0.55]), np.array([0.0, 1.1 * sched.times[1]]))
    region, _ = s.learn(at, learned)
    assert region == 0
    got = s.shaper(at)
    np.testing.assert_allclose(got.times, learned.times, rtol=1e-12)
    np.testing.assert_allclose(got.amplitudes, learned.amplitudes, rtol=1e-12)
    far = s.evaluate([2.0])  # a region with no correction: the scheduled ZV
    assert same(s.shaper(far), s.scheduled(far))
    again = s.shaper(s.evaluate([0.3]))
    np.testing.assert_allclose(again.times, learned.times, rtol=1e-12)
    with pytest.raises(ShaperError, match="two-impulse"):
        s.learn(at, design("zvd", [Mode(2.0, 0.05)]))


def test_mode_interpolation_and_family_checks():
    s = Scheduler(base(), method="modes")
    (m,) = s.evaluate([0.5]).modes
    assert m.omega == pytest.approx(0.5 * 2.0 + 0.5 * 1.5, rel=1e-9)
    with pytest.raises(ValueError, match="interpolation"):
        Scheduler(base(), method="cubic")
    with pytest.raises(ValueError):
        Scheduler(base(), family="nonsense")
    rb = RuleBase(("q",), (Rule((Triangular(0, 0, 1),), np.array([[-1.0]]), np.array([[1.0]])),))
    with pytest.raises(ValueError, match="no lightly damped mode"):
        Scheduler(rb).evaluate([0.5])


def test_premise_values_are_picked_by_name_in_linear_time_and_bad_poses_are_named():
    assert premise_values(("b", "a"), ["x", "a", "b"], [9.0, 1.0, 2.0]) == [2.0, 1.0]  # any order, extras ignored
    cases = [
        ((["a"], [1.0, 2.0]), "wrong_size", "2 positions for 1 names"),
        ((["a", "x"], [1.0, 2.0]), "missing_joint", r"missing premise joints \['b'\]"),
        ((["a", "b", "b"], [1.0, 2.0, 3.0]), "duplicate_joint", r"named more than once: \['b'\]"),
        ((["a", "b"], [1.0, math.nan]), "non_finite", "non-finite premise values: b = nan"),
        ((["j"] * (MAX_POSE_JOINTS + 1), [0.0]), "too_large", f"exceed the limit of {MAX_POSE_JOINTS}"),
    ]
    for (names, positions), kind, words in cases:
        with pytest.raises(InputError, match=words) as err:
            premise_values(("a", "b"), names, positions)
        assert err.value.kind == kind
    # a pose of the largest admitted size with the premises at its end: one pass, no quadratic search
    names = [f"j{k}" for k in range(MAX_POSE_JOINTS - 2)] + ["b", "a"]
    assert premise_values(("a", "b"), names, np.arange(MAX_POSE_JOINTS, dtype=float)) == \
        [MAX_POSE_JOINTS - 1.0, MAX_POSE_JOINTS - 2.0]


def test_the_scheduler_remembers_where_the_premises_are_and_still_checks_every_pose():
    """The premise joints' places are looked up once per name layout; every pose is still checked,
    and a pose after a refused one or in another layout gives what the plain function gives."""
    sched = Scheduler(base())
    poses = [
        (["x", "q"], [5.0, 0.5]), (["x", "q"], [5.0, 0.7]),        # the same layout twice
        (["x", "q"], [5.0]),                                       # same names, wrong size
        (["x", "q"], [5.0, math.inf]),                             # same names, non-finite
        (["q", "x"], [0.9, 5.0]),                                  # another layout
        (["x", "y"], [1.0, 2.0]), (["q", "q"], [1.0, 2.0]),        # missing, duplicate
        (["q", "x"], [1.1, 5.0]), (["x", "q"], [5.0, 1.2]),        # back to known layouts
        (("x", "q"), np.array([5.0, 1.3])),                        # tuple and array as given
    ]
    for names, positions in poses:
        try:
            want: object = premise_values(("q",), names, positions)
        except InputError as err:
            want = (err.kind, str(err))
        try:
            got: object = sched.premise_values(names, positions)
        except InputError as err:
            got = (err.kind, str(err))
        assert got == want, (names, positions)

def test_the_shaper_at_a_pose_is_the_schedules_with_the_regions_correction_and_clamping_is_said():
    s = Scheduler(base())
    at = s.evaluate([0.3])
    learned = Shaper(np.array([0.45, 0.55]), np.array([0.0, 1.1 * s.scheduled(at).times[1]]))
    s.learn(at, learned)
    for z in ([0.3], [1.4], [2.0]):
        interp, shaper = s.at(z)
        assert same(shaper, s.shaper(s.evaluate(z))) and interp.modes == s.evaluate(z).modes
    np.testing.assert_allclose(s.at([0.3])[1].times, learned.times, rtol=1e-12)  # the correction applies
    assert s.clamping(s.evaluate([1.0])) == ""
    interp, shaper = s.at([2.5])  # beyond the last operating point: clamped to it
    assert s.clamping(interp) == "premise q = 2.5 outside [0, 2]: clamped, not extrapolated"
    assert same(shaper, s.shaper(s.evaluate([2.0])))
    with pytest.raises(ValueError, match="must be finite"):
        s.at([math.nan])


def test_on_several_modes_the_learner_shaper_is_a_factor_of_its_region_and_on_one_the_ratio_policy_stays():
    pts = [0.0, 1.0, 2.0]
    rules = [Rule((mf,), modes=(Mode(10.0 - p, 0.02), Mode(40.0 + 5.0 * p, 0.03)), name=f"r{int(p)}")
             for mf, p in zip(triangular_partition(pts), pts, strict=True)]
    s = Scheduler(RuleBase(("q",), tuple(rules)), "modes", "zv")
    at = s.evaluate([0.3])
    assert at.dominant == 0 and len(s.scheduled(at).modes) == 2
    assert same(s.shaper(at), s.scheduled(at))  # nothing learned yet
    learned = Shaper(np.array([0.45, 0.55]), np.array([0.0, 0.4]))
    region, (t2, a1) = s.learn(at, learned)
    assert (region, t2, a1) == (0, 0.4, 0.45)
    assert s.factors[0] is learned and s.factors[1:] == [None, None]
    np.testing.assert_array_equal(s.corrections, np.ones((3, 2)))  # no ratio on several modes
    for z in (0.3, 0.45, 0.0):  # region 0 dominates: the scheduled shaper there, convolved with the factor
        interp = s.evaluate([z])
        assert interp.dominant == 0
        base_shaper = s.scheduled(interp)
        amps, times = convolve((base_shaper.amplitudes, base_shaper.times), (learned.amplitudes, learned.times))
        got = s.shaper(interp)
        assert len(got) == len(base_shaper) * len(learned) == 8
        np.testing.assert_allclose(got.amplitudes, amps, rtol=1e-12)
        np.testing.assert_allclose(got.times, times, rtol=1e-12)
        assert got.modes == base_shaper.modes and got.amplitudes.sum() == pytest.approx(1.0)
        assert same(s.at([z])[1], got)
    for z in (0.6, 1.0, 1.7):  # dominated by regions 1 and 2: the plain scheduled shaper
        interp = s.evaluate([z])
        assert interp.dominant != 0 and same(s.shaper(interp), s.scheduled(interp))

    # one mode: the ratio (r_T, r_A) of the learner's shaper to the scheduled ZV, kept per rule and
    # interpolated with the weights; no factor
    one = Scheduler(base(), "modes")
    at = one.evaluate([0.3])  # weights 0.7, 0.3
    sched = one.scheduled(at)
    learned = Shaper(np.array([0.45, 0.55]), np.array([0.0, 1.1 * sched.times[1]]))
    region, _ = one.learn(at, learned)
    assert region == 0 and one.factors == [None, None, None]
    wanted = np.array([1.1, 0.45 / sched.amplitudes[0]])
    np.testing.assert_allclose(one.corrections[0], 1.0 + (wanted - 1.0) / 0.7, rtol=1e-12)
    np.testing.assert_array_equal(one.corrections[1:], np.ones((2, 2)))
    mid = one.evaluate([0.6])  # weights 0.4, 0.6
    r_t, r_a = 0.4 * one.corrections[0] + 0.6 * np.ones(2)
    got, plain = one.shaper(mid), one.scheduled(mid)
    np.testing.assert_allclose(got.times, [0.0, r_t * plain.times[1]], rtol=1e-12)
    np.testing.assert_allclose(got.amplitudes, [r_a * plain.amplitudes[0], 1.0 - r_a * plain.amplitudes[0]],
                               rtol=1e-12)


def test_membership_slopes_bound_the_grade_change_and_see_vertical_edges_inside_the_range():
    tri, trap, gauss = Triangular(0.0, 0.5, 2.0), Trapezoidal(0.0, 0.2, 0.3, 1.3), Gaussian(1.0, 0.25)
    for mf in (tri, trap, gauss):
        z = np.linspace(-1.0, 3.0, 40_001)
        grades = np.array([mf(float(v)) for v in z])
        steepest = np.max(np.abs(np.diff(grades)) / np.diff(z))
        assert steepest <= mf.slope(-1.0, 3.0) * (1 + 1e-9)
        assert steepest >= 0.99 * mf.slope(-1.0, 3.0)  # and it is the steepest, not just a bound
    shoulder = Triangular(0.0, 0.0, 1.0)  # 1 from z = 0 on, 0 below: a jump at 0
    assert shoulder.slope(0.0, 1.0) == 1.0  # the jump is not inside [0, 1] (clamped premises never go below 0)
    assert shoulder.slope(-1.0, 1.0) == math.inf
    assert Triangular(0.0, 1.0, 1.0).slope(0.0, 1.0) == 1.0 and Triangular(0.0, 1.0, 1.0).slope(0.0, 2.0) == math.inf
    assert Trapezoidal(0.0, 0.0, 1.0, 1.0).slope(0.2, 0.8) == 0.0  # crisp set, edges outside: flat
    assert Trapezoidal(0.0, 0.0, 1.0, 1.0).slope(-0.5, 0.8) == math.inf


def test_premises_that_move_no_grade_by_more_than_the_tolerance_reuse_the_evaluation():
    """Scheduler.moved: within GRADE_TOLERANCE of every grade the last evaluation stands; beyond it,
    or across the range's edge, the rule base is evaluated again; the comparison is with the last
    evaluation's premises, so small moves do not add up unseen."""
    core = Scheduler(base(), "model", "zv")  # triangular partition of [0, 2] with peaks 1 apart: slope 1
    tol = core.rule_base.premise_tolerance(GRADE_TOLERANCE)
    assert tol == pytest.approx([GRADE_TOLERANCE])
    last = core.evaluate([0.7])
    assert not core.moved([0.7 + 0.9 * GRADE_TOLERANCE], last)
    assert core.moved([0.7 + 1.1 * GRADE_TOLERANCE], last)
    # what a reuse can miss: the weights move by at most 2 R p GRADE_TOLERANCE (module docstring), the mode less
    near = core.evaluate([0.7 + 0.9 * GRADE_TOLERANCE])
    assert np.abs(near.weights - last.weights).sum() <= 2 * 3 * GRADE_TOLERANCE
    assert relative_change(last.modes, near.modes) < 1e-5
    # clamped: going into (or out of) the range evaluates again
    far = core.evaluate([5.0])
    assert not core.moved([5.0 + 0.5 * GRADE_TOLERANCE], far)
    assert core.moved([7.0], far)  # (the same evaluation, but the clamping report names the value)
    assert core.moved([2.0 - 0.1 * GRADE_TOLERANCE], far)
    # a vertical edge inside the range: every change evaluates again
    crisp = RuleBase(("q",), (Rule((Trapezoidal(0.0, 0.0, 1.0, 1.0),), modes=(Mode(10.0, 0.05),)),
                              Rule((Trapezoidal(1.0, 1.0, 2.0, 2.0),), modes=(Mode(20.0, 0.05),))))
    sharp = Scheduler(crisp, "modes", "zv")
    assert sharp.rule_base.premise_tolerance(GRADE_TOLERANCE) == pytest.approx([0.0])
    assert sharp.moved([0.5 + 1e-15], sharp.evaluate([0.5]))
