"""Bounded shapers: every change does bounded work, and no custom shaper amplifies unless allowed."""

import numpy as np
import pytest

from shaper_nodes.core.shaping import (
    MAX_DESIGN_MODES,
    MAX_GAIN,
    MAX_IMPULSES,
    Mode,
    Shaper,
    ShaperError,
    design,
    modes_from_hz,
)

MODE = Mode.from_hz(5.0, 0.05)


def modes(n):
    return [Mode.from_hz(5.0 + k, 0.05) for k in range(n)]


def test_too_many_design_modes_are_refused_before_any_work():
    with pytest.raises(ShaperError, match=f"25 design modes exceed the limit of {MAX_DESIGN_MODES}"):
        design("zvd", modes(25))  # 3^25 impulses if it were attempted


def test_a_convolution_beyond_the_impulse_limit_is_refused():
    ok = design("zvd", modes(6))  # 3^6 = 729 impulses
    assert len(ok) <= MAX_IMPULSES
    with pytest.raises(ShaperError, match=f"zvd for 7 modes needs more than {MAX_IMPULSES} impulses"):
        design("zvd", modes(7))  # 2187


def test_a_custom_shaper_that_amplifies_is_refused_naming_its_gain():
    with pytest.raises(ShaperError,
                       match=r"gain sum \|A\| = 1999 exceeds max_gain 1 \(a unit step would peak at 1000\)"):
        design("custom", amplitudes=[1000.0, -999.0], times=[0.0, 0.1])
    with pytest.raises(ShaperError, match="gain sum"):
        design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.1])


def test_negative_impulses_pass_when_allowed_and_the_bound_is_the_gain():
    s = design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.1], max_gain=3.0)
    assert s.gain == pytest.approx(3.0) and s.step_peak == pytest.approx(2.0)
    # the bound holds for any input: |y| <= gain * max |x|
    x = np.sign(np.sin(np.arange(400) * 0.37))
    y = x[10:] * 2.0 - x[:-10]
    assert np.max(np.abs(y)) <= s.gain * np.max(np.abs(x)) + 1e-12
    for bad in (0.5, MAX_GAIN * 2, float("nan")):
        with pytest.raises(ShaperError, match="max_gain must be in"):
            design("custom", amplitudes=[1.0], times=[0.0], max_gain=bad)


def test_too_many_custom_impulses_are_refused():
    n = MAX_IMPULSES + 1
    with pytest.raises(ShaperError, match=f"{n} impulses exceed the limit of {MAX_IMPULSES}"):
        design("custom", amplitudes=[1.0 / n] * n, times=np.linspace(0.0, 1.0, n).tolist())
    with pytest.raises(ShaperError, match="impulses exceed the limit"):
        Shaper(np.full(n, 1.0 / n), np.linspace(0.0, 1.0, n))


def test_designed_shapers_have_unit_gain():
    for family in ("zv", "zvd", "mzv", "ei", "2hump_ei", "si"):
        assert design(family, [MODE]).gain == pytest.approx(1.0), family


def test_many_duplicate_joint_names_are_refused_in_linear_time():
    from shaper_nodes.core.checks import InputError, joint_permutation

    names = ["j1"] * 1000
    with pytest.raises(InputError, match=r"duplicate joint names \['j1'\] \(1000 names\)") as err:
        joint_permutation(["j1", "j2"], names)
    assert err.value.kind == "duplicate_joint"
    unknown = [f"x{k}" for k in range(1000)]
    with pytest.raises(InputError, match="and 990 more"):
        joint_permutation(["j1"], unknown)
    # beyond the limit: refused before the names are looked at (40,000 once stalled the node 31 s)
    with pytest.raises(InputError, match="40000 joint names exceed the limit of 1000") as err:
        joint_permutation(["j1", "j2"], ["j1"] * 40_000)
    assert err.value.kind == "too_large"


def test_a_trajectory_too_long_to_shape_is_refused_before_resampling():
    from shaper_nodes.core.checks import InputError
    from shaper_nodes.core.shaping import discretize
    from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_SAMPLES, shape_trajectory

    fir = discretize(design("zv", [MODE]), 500.0)
    for span in (1e5, 3600.0):  # the node once died (1.1 GiB) or stalled 46 s on these
        with pytest.raises(InputError, match=f"exceed the limit of {MAX_TRAJECTORY_SAMPLES}") as err:
            shape_trajectory(np.array([0.0, span]), np.array([[0.0], [1.0]]), fir, 500.0)
        assert err.value.kind == "too_large"
    out = shape_trajectory(np.array([0.0, 2.0]), np.array([[0.0], [1.0]]), fir, 500.0)
    assert out.positions[-1, 0] == pytest.approx(1.0)
    with pytest.raises(InputError, match="time_from_start of point 0 is negative"):
        shape_trajectory(np.array([-1.0, 2.0]), np.array([[0.0], [1.0]]), fir, 500.0)


def test_a_message_with_too_many_points_or_negative_times_is_refused():
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from shaper_nodes.core.checks import InputError
    from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
    from shaper_nodes.ros.conversions import trajectory_arrays

    many = [JointTrajectoryPoint(positions=[0.0])] * (MAX_TRAJECTORY_POINTS + 1)
    msg = JointTrajectory(joint_names=["j1"], points=many)
    with pytest.raises(InputError, match="points exceed the limit"):
        trajectory_arrays(msg, ["j1"], require_times=True)
    msg = JointTrajectory(joint_names=["j1"], points=[
        JointTrajectoryPoint(positions=[0.0], time_from_start=Duration(sec=-1)),
        JointTrajectoryPoint(positions=[1.0], time_from_start=Duration(sec=1))])
    with pytest.raises(InputError, match="time_from_start of point 0 is negative"):
        trajectory_arrays(msg, ["j1"], require_times=True)


def test_finite_input_that_would_overflow_the_output_is_refused():
    from shaper_nodes.core.checks import InputError, finite_array
    from shaper_nodes.core.shaping import discretize
    from shaper_nodes.core.shaping.trajectory import shape_trajectory

    fir = discretize(design("zv", [MODE]), 500.0)
    with pytest.raises(InputError, match="accelerations are not finite") as err:  # 0 to 1e308 in 1 s
        shape_trajectory(np.array([0.0, 1.0]), np.array([[0.0], [1e308]]), fir, 500.0)
    assert err.value.kind == "non_finite"
    with pytest.raises(InputError, match=r"data has -1.7e\+308 at index 1, beyond the limit of 1e\+06") as err:
        finite_array("data", [0.0, -1.7e308], limit=1e6)
    assert err.value.kind == "too_large"
    assert finite_array("data", [1e6, -1e6], limit=1e6).tolist() == [1e6, -1e6]


def test_modes_from_lists_of_frequencies_and_damping_ratios():
    got = modes_from_hz([2.0, 7.5], [0.0, 0.05])
    assert got == (Mode.from_hz(2.0, 0.0), Mode.from_hz(7.5, 0.05))
    # the design on them is the convolution of the single-mode designs
    both = design("zv", got)
    assert len(both) == 4 and both.modes == got
    assert both.duration == pytest.approx(got[0].damped_period / 2 + got[1].damped_period / 2)
    assert modes_from_hz([], []) == ()


@pytest.mark.parametrize("freqs, zetas, words", [
    ([2.0, 7.5], [0.05], "2 frequencies but 1 damping ratios: give one damping ratio per frequency"),
    ([2.0, -1.0], [0.05, 0.05], r"mode 1 \(-1.0 Hz, damping ratio 0.05\): natural frequency must be finite and > 0"),
    ([2.0, 3.0], [0.05, float("nan")], r"mode 1 \(3.0 Hz, damping ratio nan\): damping ratio must be in \[0, 0.95\]"),
    ([2.0], [0.99], r"mode 0 .*damping ratio must be in \[0, 0.95\]"),
    ([2.0], ["x"], "damping ratio 0 must be a number"),
    ([1.0] * (MAX_DESIGN_MODES + 1), [0.05] * (MAX_DESIGN_MODES + 1),
     f"{MAX_DESIGN_MODES + 1} modes exceed the limit of {MAX_DESIGN_MODES}"),
    ([1.0] * 10**6, [0.05], f"1000000 modes exceed the limit of {MAX_DESIGN_MODES}"),  # before any other work
])
def test_invalid_mode_lists_are_refused_naming_the_mode(freqs, zetas, words):
    with pytest.raises(ShaperError, match=words):
        modes_from_hz(freqs, zetas)
