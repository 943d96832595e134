"""Calibration core, free of ROS: the plan and its refusals, the pose map, the rule base, the outputs.

Expected values come from the formulas the modules document (the quintic's peaks, the grid
axes with home inserted, the follow rule, triangular partitions, linear interpolation, the
zero residual of a ZV shaper on its design modes), never from a run. Synthetic free decays are
sums of damped sinusoids with known natural frequencies and damping ratios on three axes,
sampled at 1 kHz from t = 0 with seeded white noise.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import pathlib
import re

import numpy as np
import pytest
import yaml

from shaper_nodes.analysis.calibration import (
    END,
    MOTION_END,
    START,
    PoseData,
    compute,
    setup_dict,
)
from shaper_nodes.analysis.calibration_outputs import DIGITS, report_dict, scheduler_yaml, shaper_yaml
from shaper_nodes.analysis.calibration_report import write_outputs
from shaper_nodes.core.calibration import Decay, IdentifySettings, PoseResult, identify_pose, rule_base_spec
from shaper_nodes.core.calibration.plan import (
    MAX_AMPLITUDE,
    MAX_POSES,
    MIN_MOVE_TIME,
    QUINTIC_ACCELERATION,
    QUINTIC_SPEED,
    PlanConfig,
    PlanError,
    config_from_dict,
    config_to_dict,
    excursion,
    make_limits,
    make_plan,
    plan_to_dict,
)
from shaper_nodes.core.identification import ModeFit
from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict, triangular_partition
from shaper_nodes.core.shaping.vibration import percentage_vibration

CONFIG = pathlib.Path(__file__).resolve().parents[1] / "config" / "calibrate.yaml"
RATE = 1000.0  # Hz, the synthetic accelerometer
TWO_PI = 2 * math.pi
#: largest relative error of a number the outputs round to DIGITS significant digits
ROUNDED = 0.5 * 10.0 ** (1 - DIGITS) * (1 + 1e-9)


# --------------------------------------------------------------------------- helpers
def default_config(**changes) -> PlanConfig:
    """config/calibrate.yaml's plan (its parameters mapped as the node maps them), with ``changes``."""
    p = yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"]
    k = len(p["grid"]["joints"])
    gains = p["follow"]["gains"]
    follow = {j: gains[i * k:(i + 1) * k] for i, j in enumerate(p["follow"]["joints"])}
    c = config_from_dict({"joint_names": p["joint_names"], "limits": p["limits"], "base_pose": p["base_pose"],
                          "home_pose": p["home_pose"], "grid": p["grid"], "poses": [], "follow": follow,
                          "excitation": p["excitation"], "approach": p["approach"]})
    return dataclasses.replace(c, **changes)


#: s(u) = 10 u^3 - 15 u^4 + 6 u^5, the quintic joint_trajectory_controller joins rest points with
QUINTIC = np.polynomial.Polynomial([0.0, 0.0, 0.0, 10.0, -15.0, 6.0])


def peak(p: np.polynomial.Polynomial) -> float:
    """max |p(u)| over [0, 1] (at an end or where p' = 0)."""
    crit = [r.real for r in p.deriv().roots() if abs(r.imag) < 1e-12 and 0.0 <= r.real <= 1.0]
    return max(abs(float(p(u))) for u in [0.0, 1.0, *crit])


PEAK_SPEED = peak(QUINTIC.deriv())  # of a unit move in unit time
PEAK_ACCELERATION = peak(QUINTIC.deriv(2))


def assert_least_time(distance: np.ndarray, duration: float, velocity: float, acceleration: float) -> str:
    """A quintic move over ``distance`` in ``duration`` stays within both bounds and one of them
    holds with equality (so no shorter move would); returns which binds."""
    d = float(np.max(np.abs(distance)))
    speed = PEAK_SPEED * d / duration
    acc = PEAK_ACCELERATION * d / duration**2
    assert speed <= velocity * (1 + 1e-12) and acc <= acceleration * (1 + 1e-12)
    if duration == MIN_MOVE_TIME:  # the shortest move admitted, whatever the bounds
        assert speed <= velocity and acc <= acceleration
        return "minimum"
    binding = max(speed / velocity, acc / acceleration)
    assert binding == pytest.approx(1.0, rel=1e-9)
    return "speed" if speed / velocity >= acc / acceleration else "acceleration"


def axis(lower: float, upper: float, count: int, home: float) -> list[float]:
    """A grid axis as documented: ``count`` values evenly from lower to upper, home's value added."""
    values = list(np.linspace(lower, upper, count))
    if lower <= home <= upper and all(abs(v - home) > 1e-6 for v in values):
        values.append(home)
    return sorted(values)


def free_decay(modes, seed: int, t: np.ndarray | None = None, *, noise: float = 0.01, gains=None):
    """(t, y): a free decay of ``modes`` ((Hz, damping ratio) pairs) at times ``t`` (s from the
    motion's end; default 2 s at 1 kHz from 0) on three axes, random phases and axis shares, white
    noise of standard deviation ``noise`` (the modes' amplitudes are 0.3 to 1)."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(2.0 * RATE)) / RATE if t is None else t
    y = noise * rng.standard_normal((t.size, 3))
    for (hz, zeta), g in zip(modes, gains or [1.0] * len(modes), strict=True):
        w = TWO_PI * hz
        shares = g * rng.uniform(0.3, 1.0, 3)
        phases = rng.uniform(0.0, TWO_PI, 3)
        y += shares * np.exp(-zeta * w * t)[:, None] * np.cos(w * math.sqrt(1 - zeta**2) * t[:, None] + phases)
    return t, y


def assert_modes(found, truth, *, freq=0.005, damping=0.10) -> None:
    """``found`` (ModeFit, by frequency) are ``truth`` ((Hz, ratio)) within the relative tolerances."""
    assert [m.hz for m in found] == sorted(m.hz for m in found)
    assert len(found) == len(truth), [(m.hz, m.zeta) for m in found]
    for m, (hz, zeta) in zip(found, sorted(truth), strict=True):
        assert m.hz == pytest.approx(hz, rel=freq) and m.zeta == pytest.approx(zeta, rel=damping), (m, hz, zeta)


def fit(hz: float, zeta: float, amplitude: float = 1.0) -> ModeFit:
    return ModeFit(TWO_PI * hz, zeta, 0.001 * TWO_PI * hz, 0.05 * zeta, amplitude, "fit")


# --------------------------------------------------------------------------- the plan
def test_the_quintic_peaks_are_those_of_the_documented_polynomial():
    assert [float(QUINTIC(u)) for u in (0.0, 1.0)] == [0.0, 1.0]
    for p in (QUINTIC.deriv(), QUINTIC.deriv(2)):  # rest to rest: no speed, no acceleration at the ends
        assert [float(p(u)) for u in (0.0, 1.0)] == pytest.approx([0.0, 0.0], abs=1e-12)
    assert pytest.approx(1.875, rel=1e-12) == PEAK_SPEED == QUINTIC_SPEED
    assert pytest.approx(10 / math.sqrt(3), rel=1e-12) == PEAK_ACCELERATION
    assert pytest.approx(PEAK_ACCELERATION, rel=1e-12) == QUINTIC_ACCELERATION
    assert pytest.approx(5.7735, abs=5e-5) == QUINTIC_ACCELERATION


def test_the_default_plan_starts_at_home_on_a_3x3_grid_in_serpentine_order_and_wrist_1_follows():
    c = default_config()
    plan = make_plan(c)
    names = list(c.joint_names)
    base, home = np.asarray(c.base_pose), np.asarray(c.home_pose)
    gi = [names.index(j) for j in c.grid_joints]
    axes = [axis(lo, hi, n, home[i]) for lo, hi, n, i in zip(c.grid_lower, c.grid_upper, c.grid_counts, gi,
                                                                 strict=True)]
    assert list(c.grid_counts) == [2, 2] and [len(a) for a in axes] == [3, 3]  # home's value inserted
    home_index = tuple(a.index(home[i]) for a, i in zip(axes, gi, strict=True))
    assert home_index == (1, 1)

    assert len(plan.steps) == 9
    first = plan.steps[0]
    assert first.home and first.name == "home" and first.grid_index == home_index
    np.testing.assert_array_equal(first.pose, home)
    assert not any(s.home for s in plan.steps[1:])
    assert [s.index for s in plan.steps] == list(range(9))
    assert sorted(s.grid_index for s in plan.steps) == list(itertools.product(range(3), range(3)))

    # serpentine: neighbours on the grid, except across the place home was taken out of
    jumps = 0
    for a, b in itertools.pairwise(s.grid_index for s in plan.steps[1:]):
        if np.sum(np.abs(np.subtract(a, b))) != 1:
            jumps += 1
            assert np.sum(np.abs(np.subtract(a, home_index))) == 1 == np.sum(np.abs(np.subtract(home_index, b)))
    assert jumps <= 1

    follow = {names.index(j): np.asarray(g) for j, g in c.follow.items()}
    assert list(c.follow) == ["wrist_1_joint"] and list(c.follow["wrist_1_joint"]) == [-1.0, -1.0]
    for s in plan.steps:
        expected = base.copy()
        for a, i in enumerate(gi):
            expected[i] = axes[a][s.grid_index[a]]
        for f, g in follow.items():
            expected[f] = base[f] + sum(gj * (s.pose[j] - base[j]) for gj, j in zip(g, gi, strict=True))
        np.testing.assert_allclose(s.pose, expected, rtol=0, atol=1e-12, err_msg=s.name)
    np.testing.assert_array_equal(plan.start, home)  # default start: home


@pytest.mark.parametrize(("velocity", "repeats", "binding"), [(None, None, "acceleration"), (0.1, 7, "speed")])
def test_excitations_go_out_and_back_in_the_least_quintic_time_then_hold_and_the_parts_add_up(
        velocity, repeats, binding):
    changes = {k: v for k, v in (("excitation_velocity", velocity), ("repeats", repeats)) if v is not None}
    c = default_config(**changes)
    plan = make_plan(c)
    names = list(c.joint_names)
    ei = [names.index(j) for j in c.excitation_joints]
    delta = np.zeros(len(names))
    delta[ei] = c.amplitude
    half = plan.steps[0].excitations[0][0].time
    assert assert_least_time(delta, half, c.excitation_velocity, c.excitation_acceleration) == binding
    total = 0.0
    prev = plan.start
    for s in plan.steps:
        assert s.repeats == c.repeats == len(s.excitations)
        for r, trajectory in enumerate(s.excitations):
            d = delta.copy()
            if r >= 1:  # repeat r halves excitation joint r - 1, cyclically
                d[ei[(r - 1) % len(ei)]] *= 0.5
            assert [w.time for w in trajectory] == pytest.approx([half, 2 * half, 2 * half + c.decay], rel=1e-12)
            np.testing.assert_allclose(trajectory[0].positions, s.pose + d, rtol=0, atol=1e-12)
            for w in trajectory[1:]:
                np.testing.assert_array_equal(w.positions, s.pose)
        assert s.excitation_time == pytest.approx(2 * half)
        # the approach: the least quintic time within the approach bounds, then at rest for settle
        move = s.approach[0].time
        assert_least_time(s.pose - prev, move, c.approach_velocity, c.approach_acceleration)
        assert [w.time for w in s.approach] == pytest.approx([move, move + c.settle])
        for w in s.approach:
            np.testing.assert_array_equal(w.positions, s.pose)
        total += move + c.settle + c.repeats * (2 * half + c.decay)
        prev = s.pose
    (back,) = plan.back_home
    np.testing.assert_array_equal(back.positions, c.home_pose)
    assert_least_time(np.asarray(c.home_pose) - prev, back.time, c.approach_velocity, c.approach_acceleration)
    assert plan.duration == pytest.approx(total + back.time, rel=1e-12)
    assert plan_to_dict(plan)["duration"] == plan.duration


def test_excursion_halves_one_excitation_joint_per_repeat_cyclically():
    delta = np.array([0.02, -0.02, 0.0, 0.02])
    joints = [0, 1, 3]
    np.testing.assert_array_equal(excursion(delta, joints, 0), delta)
    for r in range(1, 8):
        want = delta.copy()
        want[joints[(r - 1) % 3]] /= 2
        np.testing.assert_array_equal(excursion(delta, joints, r), want)
    assert delta.tolist() == [0.02, -0.02, 0.0, 0.02]  # not modified


def test_explicit_poses_are_visited_by_nearest_neighbour_from_home():
    c0 = default_config()
    home = np.asarray(c0.home_pose)
    el = list(c0.joint_names).index("elbow_joint")
    offsets = [0.6, 0.1, -0.3, 0.3]  # along the elbow: from home 0.1, 0.3, 0.6, then -0.3
    poses = []
    for o in offsets:
        p = home.copy()
        p[el] += o
        poses.append(tuple(p))
    c = default_config(grid_joints=(), grid_lower=(), grid_upper=(), grid_counts=(), follow={}, poses=tuple(poses))
    plan = make_plan(c)
    assert plan.steps[0].home and plan.steps[0].grid_index is None  # off the grid: an extra pose
    assert [s.name for s in plan.steps[1:]] == ["pose 1", "pose 3", "pose 0", "pose 2"]
    assert all(s.grid_index is None for s in plan.steps)
    # greedy: each pose is the nearest (largest joint displacement) of those not yet visited
    left = [np.asarray(p) for p in poses]
    here = home
    for s in plan.steps[1:]:
        nearest = min(left, key=lambda p: float(np.max(np.abs(p - here))))
        np.testing.assert_array_equal(s.pose, nearest)
        left = [p for p in left if p is not nearest]
        here = s.pose


def test_a_grid_value_micro_radians_from_home_is_still_a_pose_of_its_own():
    home_el = default_config().home_pose[2]
    c = default_config(grid_lower=(-1.9, home_el - 4e-6))  # elbow axis: home - 4 urad, home, 2.4
    plan = make_plan(c)
    assert sorted(s.grid_index for s in plan.steps) == list(itertools.product(range(3), range(3)))
    assert plan.steps[0].home and plan.steps[0].grid_index == (1, 1)


def test_the_configuration_round_trips_through_plain_data_to_the_same_plan():
    for c in (default_config(), default_config(**NO_GRID, poses=HUNDRED_AND_ONE[:5], repeats=2)):
        d = json.loads(json.dumps(config_to_dict(c)))
        again = config_from_dict(d)
        a, b = make_plan(c), make_plan(again)
        assert plan_to_dict(a) == plan_to_dict(b)
        assert a.describe() == b.describe()
        for sa, sb in zip(a.steps, b.steps, strict=True):
            for wa, wb in zip(sa.approach + sum(sa.excitations, ()), sb.approach + sum(sb.excitations, ()),
                              strict=True):
                assert wa.time == wb.time and np.array_equal(wa.positions, wb.positions)
        assert config_to_dict(again) == d
    with pytest.raises(PlanError, match="not a calibration plan"):
        config_from_dict({"joint_names": ["a"]})


# --------------------------------------------------------------------------- refusals
def limits(**per_joint):
    """The default limits with some joints' values changed: name=(lower, upper, velocity, acceleration)."""
    c = default_config()
    lim = c.limits
    vals = [lim.lower.copy(), lim.upper.copy(), lim.velocity.copy(), lim.acceleration.copy()]
    for name, new in per_joint.items():
        j = list(c.joint_names).index(name)
        for v, x in zip(vals, new, strict=True):
            if x is not None:
                v[j] = x
    return make_limits(len(c.joint_names), *vals)


HUNDRED_AND_ONE = tuple((0.0, -1.57, 1.57, -1.57, -1.57, 0.01 * (k + 1)) for k in range(MAX_POSES + 1))  # none at home
NO_GRID = {"grid_joints": (), "grid_lower": (), "grid_upper": (), "grid_counts": (), "follow": {}}


@pytest.mark.parametrize(("changes", "words"), [
    ({"limits": limits(elbow_joint=(None, 2.3, None, None))},
     r"the pose leaves the joint limits: elbow_joint \+2\.4000 > \+2\.3000"),
    ({"limits": limits(shoulder_lift_joint=(-1.85, None, None, None))},
     r"the pose leaves the joint limits: shoulder_lift_joint -1\.9000 < -1\.8500"),
    ({"limits": limits(elbow_joint=(None, 2.41, None, None))},  # 2.4 + 0.02
     r"the excited pose leaves the joint limits: elbow_joint \+2\.4200 > \+2\.4100"),
    ({"limits": limits(shoulder_lift_joint=(-1.91, None, None, None))},  # -1.9 - 0.02
     r"the excited pose leaves the joint limits: shoulder_lift_joint -1\.9200 < -1\.9100"),
    ({"excitation_velocity": 4.0}, r"excitation\.max_velocity 4 exceeds the limit of joint\(s\) shoulder_pan_joint"),
    ({"limits": limits(wrist_3_joint=(None, None, 0.4, None))},
     r"excitation\.max_velocity 0\.5 exceeds the limit of joint\(s\) wrist_3_joint \(0\.4\)$"),
    ({"limits": limits(wrist_2_joint=(None, None, None, 5.0))},
     r"excitation\.max_acceleration 10 exceeds the limit of joint\(s\) wrist_2_joint \(5\)$"),
    ({"approach_velocity": 3.5}, r"approach\.max_velocity 3\.5 exceeds the limit of joint\(s\) shoulder_pan_joint"),
    ({"approach_acceleration": 16.0}, r"approach\.max_acceleration 16 exceeds the limit of joint\(s\)"),
    ({"amplitude": (0.02, 0.0, 0.02)}, r"excitation\.amplitude must be non-zero and within \+-0\.2 rad .*0\.0"),
    ({"amplitude": (0.02, -0.25, 0.02)}, r"excitation\.amplitude must be non-zero and within \+-0\.2 rad .*-0\.25"),
    ({"amplitude": (0.02, 0.02)}, r"excitation\.amplitude needs one value per excitation joint \(3\), got 2"),
    ({"excitation_joints": ("shoulder_pan_joint", "wrist_9_joint", "elbow_joint")},
     r"excitation\.joints names joints that are not in joint_names: \['wrist_9_joint'\]"),
    ({"grid_joints": ("shoulder_lift_joint", "elbo")}, r"grid\.joints names joints that are not in joint_names"),
    ({"follow": {"wrist_one": (-1.0, -1.0)}}, r"follow names joints that are not in joint_names: \['wrist_one'\]"),
    ({"poses": ((0.0, -1.57, 1.57, -1.57, -1.57, 0.0),)}, "either a grid .* or an explicit list of poses, not both"),
    (NO_GRID, "nothing to calibrate"),
    ({**NO_GRID, "poses": HUNDRED_AND_ONE}, rf"{MAX_POSES + 1} poses given; at most {MAX_POSES} are planned"),
    ({"grid_joints": ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"), "grid_lower": (-1.0, -1.9, 0.5),
      "grid_upper": (1.0, -1.0, 2.4), "grid_counts": (5, 5, 5), "follow": {}},
     rf"the grid has \d+ poses; at most {MAX_POSES} are planned"),
    ({"grid_lower": (-1.9,)}, r"need one value per grid joint \(2\), got 1, 2 and 2"),
    ({"grid_counts": (2, 2, 2)}, r"need one value per grid joint \(2\), got 2, 2 and 3"),
    ({"follow": {"wrist_1_joint": (-1.0,)}}, r"follow\.wrist_1_joint needs one gain per grid joint \(2\), got 1"),
])
def test_a_plan_that_must_not_run_is_refused_with_the_problem_named(changes, words):
    with pytest.raises(PlanError, match=words):
        make_plan(default_config(**changes))


def test_the_bounds_themselves_are_admitted():
    c = default_config(amplitude=(MAX_AMPLITUDE, -MAX_AMPLITUDE, MAX_AMPLITUDE), excitation_velocity=math.pi,
                       excitation_acceleration=15.0, approach_velocity=math.pi, approach_acceleration=15.0)
    assert len(make_plan(c).steps) == 9
    exact = limits(elbow_joint=(None, 2.42, None, None))  # the excited elbow reaches its limit exactly
    assert len(make_plan(default_config(limits=exact)).steps) == 9
    poses = HUNDRED_AND_ONE[:MAX_POSES]
    assert len(make_plan(default_config(**NO_GRID, poses=poses)).steps) == MAX_POSES + 1  # and home


# --------------------------------------------------------------------------- the pose map
MODES = ((6.0, 0.02), (13.0, 0.03), (27.0, 0.015))  # Hz, damping ratio
#: the middle mode strongest, so identification's order (strongest first) is not the frequency order
GAINS = (0.5, 1.0, 0.3)


def pose_decays(modes_per_repeat, seed: int = 0) -> list[Decay]:
    out = []
    for r, modes in enumerate(modes_per_repeat):
        gains = list(GAINS)
        if r >= 1:  # the repeats vary the mix as the plan's do
            gains[(r - 1) % len(gains)] *= 0.5
        if modes is None:  # a repeat with nothing in it but noise
            t = np.arange(round(2.0 * RATE)) / RATE
            y = 0.01 * np.random.default_rng(seed + 100 + r).standard_normal((t.size, 3))
        else:
            t, y = free_decay(modes, seed + r, gains=gains)
        out.append(Decay(0, r, t, y))
    return out


def identify(modes_per_repeat) -> PoseResult:
    return identify_pose(0, "home", np.zeros(6), (1, 1), pose_decays(modes_per_repeat), IdentifySettings())


def test_identify_pose_recovers_the_modes_of_agreeing_repeats_sorted_by_frequency():
    res = identify([MODES] * 3)
    assert res.flags == [] and res.ok
    assert_modes(res.modes, MODES)
    assert len(res.repeats) == 3
    for rep in res.repeats:
        assert sorted(round(m.hz) for m in rep) == [6, 13, 27]
    assert res.spectrum is not None
    f, p = res.spectrum
    assert f[np.argmax(p)] == pytest.approx(13.0, abs=0.5)  # the strongest mode's peak


def test_a_repeat_with_a_shifted_frequency_is_flagged_as_disagreeing():
    shifted = ((6.0, 0.02), (13.0 * 1.05, 0.03), (27.0, 0.015))
    spread = (2 * 0.05 / 3) / (1 + 0.05 / 3)  # largest deviation from the mean of 13, 13, 13.65 Hz: 3.3 %
    assert IdentifySettings().agreement < spread
    res = identify([MODES, MODES, shifted])
    disagree = [f for f in res.flags if f.startswith("repeats_disagree")]
    assert len(disagree) == 1 and not res.ok, res.flags
    (hz,) = re.findall(r"repeats_disagree: ([\d.]+) Hz", disagree[0])
    assert float(hz) == pytest.approx(13.0 * (1 + 0.05 / 3), rel=2e-3)  # the mean over the repeats
    assert not any(f.startswith(("identification_failed", "mode_not_in_every_repeat")) for f in res.flags)


def test_a_repeat_of_pure_noise_is_flagged_as_failed_and_the_others_still_give_the_modes():
    res = identify([MODES, None, MODES])
    assert res.repeats[1] == [] and not res.ok
    assert any(f.startswith("identification_failed: repeat 1:") for f in res.flags), res.flags
    assert sum(f.startswith("mode_not_in_every_repeat") for f in res.flags) == 3
    assert_modes(res.modes, MODES)


# --------------------------------------------------------------------------- the rule base
def grid_modes(gi: tuple[int, int], a: float, b: float) -> list[tuple[float, float]]:
    """Two modes (Hz, ratio) at grid index gi: frequencies change by a factor 1 + a per step along
    shoulder_lift and 1 + b per step along the elbow (so by 2a and 2b over the axes)."""
    i, j = gi
    s = (1 + a * i) * (1 + b * j)
    return [(5.0 * s, 0.02 + 0.002 * i), (17.0 * s, 0.03 - 0.001 * j)]


def pose_results(plan, a: float, b: float, drop=None) -> list[PoseResult]:
    """One PoseResult per step; at grid index ``drop`` only the lower mode was found."""
    out = []
    for s in plan.steps:
        modes = [fit(hz, z, 1.0 + k) for k, (hz, z) in enumerate(grid_modes(s.grid_index, a, b))]
        if s.grid_index == drop:
            modes = modes[:1]
        out.append(PoseResult(s.index, s.name, s.pose, s.grid_index, modes, [modes]))
    return out


def default_axes(c: PlanConfig) -> list[list[float]]:
    names = list(c.joint_names)
    return [axis(lo, hi, n, c.home_pose[names.index(j)])
            for j, lo, hi, n in zip(c.grid_joints, c.grid_lower, c.grid_upper, c.grid_counts, strict=True)]


def test_the_rule_base_has_a_rule_per_grid_pose_and_interpolates_the_measured_modes():
    c = default_config()
    plan = make_plan(c)
    axes = default_axes(c)
    spec, notes = rule_base_spec(plan, pose_results(plan, 0.1, 0.05), "zv", 0.02)
    assert spec["premises"] == ["shoulder_lift_joint", "elbow_joint"]
    assert all("a premise" in n for n in notes) and len(notes) == 2
    assert spec["range"] == [axes[0][0], axes[0][-1], axes[1][0], axes[1][-1]]
    assert spec["family"] == "zv" and spec["interpolation"] == "modes"
    assert len(spec["rules"]) == 9
    tri = [triangular_partition(a) for a in axes]
    for i, j in itertools.product(range(3), range(3)):
        rule = spec["rules"][f"r_{i}_{j}"]
        assert rule["membership"] == ["triangular", "triangular"]
        want = [tri[0][i].a, tri[0][i].b, tri[0][i].c, tri[1][j].a, tri[1][j].b, tri[1][j].c]
        assert rule["membership_params"] == pytest.approx(want, rel=0, abs=1e-12)
        assert rule["membership_params"][1] == axes[0][i] and rule["membership_params"][4] == axes[1][j]

    sched = Scheduler(rule_base_from_dict(spec), "modes", "zv")

    def modes_at(z):
        return np.array([(m.omega / TWO_PI, m.zeta) for m in sched.evaluate(z).modes])

    for i, j in itertools.product(range(3), range(3)):  # at a grid pose: exactly its modes
        assert modes_at([axes[0][i], axes[1][j]]) == pytest.approx(np.array(grid_modes((i, j), 0.1, 0.05)),
                                                                   rel=1e-12)
    for s in (0.25, 0.5, 0.8):  # between two grid poses: the linear interpolation of their modes
        for i, j in itertools.product(range(2), range(3)):
            z = [(1 - s) * axes[0][i] + s * axes[0][i + 1], axes[1][j]]
            lo, hi = np.array(grid_modes((i, j), 0.1, 0.05)), np.array(grid_modes((i + 1, j), 0.1, 0.05))
            assert modes_at(z) == pytest.approx((1 - s) * lo + s * hi, rel=1e-12)
        for i, j in itertools.product(range(3), range(2)):
            z = [axes[0][i], (1 - s) * axes[1][j] + s * axes[1][j + 1]]
            lo, hi = np.array(grid_modes((i, j), 0.1, 0.05)), np.array(grid_modes((i, j + 1), 0.1, 0.05))
            assert modes_at(z) == pytest.approx((1 - s) * lo + s * hi, rel=1e-12)


@pytest.mark.parametrize("b", [0.0, 0.004])  # the elbow changes nothing, or 0.8 % (< the 2 % threshold)
def test_a_grid_joint_the_modes_hardly_change_along_is_averaged_out_and_named(b):
    c = default_config()
    plan = make_plan(c)
    axes = default_axes(c)
    spec, notes = rule_base_spec(plan, pose_results(plan, 0.1, b), "zv", 0.02)
    assert spec["premises"] == ["shoulder_lift_joint"]
    assert spec["range"] == [axes[0][0], axes[0][-1]]
    assert [n for n in notes if n.startswith("elbow_joint")] == [
        f"elbow_joint: modes change by {100 * 2 * b:.2f} % (<= 2 %): averaged out, not a premise"]
    assert list(spec["rules"]) == ["r_0", "r_1", "r_2"]
    sched = Scheduler(rule_base_from_dict(spec), "modes", "zv")
    for i in range(3):
        mean = np.mean([grid_modes((i, j), 0.1, b) for j in range(3)], axis=0)
        got = np.array([(m.omega / TWO_PI, m.zeta) for m in sched.evaluate([axes[0][i]]).modes])
        assert got == pytest.approx(mean, rel=1e-12)


def test_a_pose_missing_a_mode_takes_it_from_its_nearest_neighbour_and_says_so():
    c = default_config()
    plan = make_plan(c)
    results = pose_results(plan, 0.1, 0.05, drop=(0, 1))
    missing = next(r for r in results if r.grid_index == (0, 1))
    grid = [r for r in results if r.grid_index != (0, 1)]
    # home (shoulder_lift 0.33 rad away, wrist_1 with it) is the nearest, by any norm
    for norm in (np.inf, 2):
        nearest = min(grid, key=lambda r: float(np.linalg.norm(r.positions - missing.positions, norm)))
        assert nearest.name == "home"
    spec, notes = rule_base_spec(plan, results, "zv", 0.02)
    upper_home = grid_modes((1, 1), 0.1, 0.05)[1]
    assert f"grid 0,1: mode(s) {upper_home[0]:.3f} Hz taken from home" in notes
    rule = spec["rules"]["r_0_1"]
    own = grid_modes((0, 1), 0.1, 0.05)[0]
    assert rule["natural_frequency"] == pytest.approx([TWO_PI * own[0], TWO_PI * upper_home[0]], rel=1e-12)
    assert rule["damping_ratio"] == pytest.approx([own[1], upper_home[1]], rel=1e-12)
    assert all(len(r["natural_frequency"]) == 2 for r in spec["rules"].values())


# --------------------------------------------------------------------------- from the recording to the files
#: a small plan: the elbow at 1.0, home's 1.57 and 2.0; two excitations of 1 s free decay each
SMALL = {"grid_joints": ("elbow_joint",), "grid_lower": (1.0,), "grid_upper": (2.0,), "grid_counts": (2,),
         "follow": {"wrist_1_joint": (-1.0,)}, "repeats": 2, "decay": 1.0, "settle": 0.5}


def truth(elbow: float) -> list[tuple[float, float]]:
    """The synthetic arm's modes (Hz, ratio) at an elbow angle: 10 %/rad up and 8 %/rad down."""
    return [(8.0 * (1 + 0.1 * (elbow - 1.57)), 0.02), (21.0 * (1 - 0.08 * (elbow - 1.57)), 0.03)]


def recorded(plan) -> list[PoseData]:
    """What the node records per pose: START, MOTION_END, END per repeat (kind, repeat, stamp) and the
    accelerometer throughout (the commanded motion shakes it too; only the free decays count)."""
    el = list(plan.config.joint_names).index("elbow_joint")
    poses = []
    for s in plan.steps:
        data = PoseData(s.index)
        t0 = 100.0 + 50.0 * s.index
        for r, trajectory in enumerate(s.excitations):
            motion, hold = trajectory[1].time, trajectory[2].time
            data.events += [(START, r, t0), (MOTION_END, r, t0 + motion), (END, r, t0 + hold)]
            tm = t0 + np.arange(round(hold * RATE) + 1) / RATE
            after = tm > t0 + motion
            y = np.empty((tm.size, 3))
            y[~after] = 5.0 * np.sin(TWO_PI * 3.0 * (tm[~after] - t0))[:, None]  # the motion's own shaking
            y[after] = free_decay(truth(s.pose[el]), 10 * s.index + r, tm[after] - (t0 + motion))[1]
            data.imu_t += tm.tolist()
            data.imu += [tuple(v) for v in y]
            t0 += hold + 0.5
        poses.append(data)
    return poses


@pytest.fixture(scope="module")
def calibration():
    plan = make_plan(default_config(**SMALL))
    assert [s.name for s in plan.steps] == ["home", "grid 0", "grid 2"]
    setup = json.loads(json.dumps(setup_dict(plan, IdentifySettings(max_modes=2), "zv", 0.02)))
    return plan, compute(setup, recorded(plan), workers=1)


def test_compute_maps_the_modes_and_builds_rule_base_and_fallback(calibration):
    plan, cal = calibration
    el = list(plan.config.joint_names).index("elbow_joint")
    assert [r.name for r in cal.results] == [s.name for s in plan.steps]
    for r in cal.results:
        assert r.flags == [] and r.ok, (r.name, r.flags)
        assert_modes(r.modes, truth(r.positions[el]))
    assert cal.rule_base is not None and cal.rule_base["premises"] == ["elbow_joint"]
    assert len(cal.rule_base["rules"]) == 3
    home = cal.results[0]
    assert cal.fallback is not None and cal.fallback.family == "zv"
    assert cal.fallback.modes == tuple(m.mode for m in home.modes)
    # a ZV shaper leaves no vibration on the modes it was designed for: the scheduled one at every
    # grid pose, the fixed one at home only
    for r, row in zip(cal.results, cal.residuals, strict=True):
        assert row["scheduled"] == pytest.approx(0.0, abs=1e-9)
        if r.name == "home":
            assert row["fixed"] == pytest.approx(0.0, abs=1e-9)
        else:
            expected = [float(percentage_vibration(cal.fallback.amplitudes, cal.fallback.times, m.omega, m.zeta))
                        for m in r.modes]
            assert row["fixed"] > 0.01 and min(expected) <= row["fixed"] <= max(expected)
        assert row["scheduled_worst_2sigma"] >= row["scheduled"]


def test_the_report_is_plain_json_and_the_parameter_files_load_as_the_nodes_read_them(calibration):
    _, cal = calibration
    report = report_dict(cal)
    text = json.dumps(report, allow_nan=False)  # plain JSON: no NaN, no numpy types
    assert json.dumps(json.loads(text), allow_nan=False) == text
    assert report["complete"] and report["flagged_poses"] == []
    for pose, r in zip(report["poses"], cal.results, strict=True):
        assert [m["frequency_hz"] for m in pose["modes"]] == pytest.approx([m.hz for m in r.modes], rel=ROUNDED)

    doc = yaml.safe_load(scheduler_yaml(cal))
    assert list(doc) == ["/**"] and list(doc["/**"]) == ["ros__parameters"]  # any node name
    params = doc["/**"]["ros__parameters"]
    assert params["family"] == "zv" and params["interpolation"] == "modes"
    assert params["rule_names"] == list(params["rules"]) == list(cal.rule_base["rules"])
    numbers = list(params["range"])
    for rule in params["rules"].values():
        assert rule["membership"] == ["triangular"]
        numbers += rule["membership_params"] + rule["frequency_hz"] + rule["damping_ratio"]
    assert all(type(x) is float for x in numbers)  # DOUBLE_ARRAY parameters: no integer, no string
    got = rule_base_from_dict(params)
    want = rule_base_from_dict(cal.rule_base)
    assert got.premises == want.premises == ("elbow_joint",)
    np.testing.assert_allclose(got.ranges, want.ranges, rtol=ROUNDED)
    for a, b in zip(got.rules, want.rules, strict=True):
        assert a.name == b.name
        np.testing.assert_allclose([(m.a, m.b, m.c) for m in a.memberships],
                                   [(m.a, m.b, m.c) for m in b.memberships], rtol=ROUNDED)
        np.testing.assert_allclose([(m.omega, m.zeta) for m in a.modes], [(m.omega, m.zeta) for m in b.modes],
                                   rtol=ROUNDED)

    doc = yaml.safe_load(shaper_yaml(cal))
    shaper = doc["/**"]["ros__parameters"]["shaper"]
    home = cal.results[0]
    assert shaper["family"] == "zv"
    assert shaper["frequencies_hz"] == pytest.approx([m.hz for m in home.modes], rel=ROUNDED)
    assert shaper["damping_ratios"] == pytest.approx([m.zeta for m in home.modes], rel=ROUNDED)
    assert all(type(x) is float for x in shaper["frequencies_hz"] + shaper["damping_ratios"])


def test_write_outputs_writes_every_file_whole(calibration, tmp_path):
    _, cal = calibration
    out = tmp_path / "cal"
    written = write_outputs(out, cal)
    names = {p.name for p in written}
    assert {"report.json", "report.md", "scheduler.yaml", "shaper.yaml"} <= names
    assert any(n.endswith(".png") for n in names)
    assert all(p.is_file() and p.stat().st_size > 0 for p in written)
    assert sorted(p.name for p in out.iterdir()) == sorted(names)  # nothing else, no *.tmp left
    assert not list(out.glob("*.tmp*"))
    assert json.loads((out / "report.json").read_text()) == json.loads(json.dumps(report_dict(cal)))
    assert yaml.safe_load((out / "scheduler.yaml").read_text()) == yaml.safe_load(scheduler_yaml(cal))
    assert (out / "shaper.yaml").read_text() == shaper_yaml(cal)
