"""Joint limits of the shaper's output (core/shaping/limits.py) and the rate watch of streamed inputs
(core/rate.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.rate import RateWatch
from shaper_nodes.core.shaping import Mode, StreamingShaper, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits, urdf_limits

NAMES = ("a", "b")


def test_unset_limits_pass_everything_finite():
    lim = JointLimits.from_lists(NAMES)
    lim.check_trajectory(np.arange(3.0), np.full((3, 2), 1e300), np.full((3, 2), -1e300), np.zeros((3, 2)))


@pytest.mark.parametrize("kwargs, words", [
    ({"lower": [0.0]}, "limits.position_lower has 1 entries, one per joint (2) or none expected"),
    ({"lower": [1.0, 0.0], "upper": [0.5, 1.0]}, "limits.position_lower 1 is above limits.position_upper 0.5"
                                                 " for joint 'a'"),
    ({"velocity": [1.0, 0.0]}, "limits.velocity must be > 0"),
    ({"acceleration": [math.nan, 1.0]}, "limits.acceleration has NaN entries"),
])
def test_bad_limit_lists_are_refused_by_name(kwargs, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        JointLimits.from_lists(NAMES, **kwargs)


def test_each_limit_is_named_with_joint_sample_time_and_value():
    lim = JointLimits.from_lists(NAMES, [-1, -2], [1, 2], [3, math.inf], [10, 20])
    t = np.array([0.0, 0.1, 0.2])
    ok = np.zeros((3, 2))
    pos = ok.copy()
    pos[2, 1] = -2.5
    with pytest.raises(InputError, match=r"position limit of joint 'b' at sample 2 \(t = 0.2000 s\): -2.5 beyond -2"):
        lim.check_trajectory(t, pos, ok, ok)
    vel = ok.copy()
    vel[1, 0] = -3.5
    with pytest.raises(InputError, match=r"velocity limit of joint 'a' at sample 1 .*-3.5 beyond -3") as err:
        lim.check_trajectory(t, ok, vel, ok)
    assert err.value.kind == "beyond_limits"
    vel[1, 0] = 0.0
    vel[:, 1] = 1e9  # no velocity limit on b
    acc = ok.copy()
    acc[0, 1] = 21.0
    with pytest.raises(InputError, match="acceleration limit of joint 'b'"):
        lim.check_trajectory(t, ok, vel, acc)


def test_a_positive_shaper_can_leave_the_range_of_its_input_across_a_switch():
    """Why the output is checked, not the input: a step shaped by a slow filter, then a step back
    shaped by a fast one, takes the output below both input values for a while."""
    slow = discretize(design("zv", [Mode.from_hz(1.0, 0.0)]), 100.0)  # half now, half after 0.5 s
    fast = discretize(design("none", []), 100.0)
    f = StreamingShaper(slow, 1)
    f.process(np.array([0.0]))
    f.process(np.array([1.0]))
    f.switch(fast)
    y = f.process(np.array([0.0]))
    assert y[0] < 0.0  # input only ever in [0, 1]
    lim = JointLimits.from_lists(("j",), [0.0], [1.0])
    with pytest.raises(InputError, match="beyond 0"):
        lim.check_positions("the shaped command", y)


URDF = """<robot name="r">
  <joint name="a" type="revolute"><limit lower="-1.5" upper="1.5" velocity="2.0" effort="1"/></joint>
  <joint name="b" type="continuous"><limit velocity="1e308" effort="1"/></joint>
  <joint name="c" type="fixed"/>
</robot>"""


def test_urdf_limits_per_joint_type():
    lim = urdf_limits(URDF, ["b", "a"])
    np.testing.assert_array_equal(lim.lower, [-np.inf, -1.5])
    np.testing.assert_array_equal(lim.upper, [np.inf, 1.5])
    np.testing.assert_array_equal(lim.velocity, [np.inf, 2.0])  # 1e308: a sentinel for none
    np.testing.assert_array_equal(lim.acceleration, [np.inf, np.inf])  # URDF has none
    with pytest.raises(ValueError, match="joint 'c' is 'fixed' in the URDF"):
        urdf_limits(URDF, ["a", "c"])
    with pytest.raises(ValueError, match="not well-formed XML"):
        urdf_limits("<robot>", ["a"])
    with pytest.raises(ValueError, match="is not a number"):
        urdf_limits(URDF.replace('lower="-1.5"', 'lower="low"'), ["a"])
    tight = lim.tighter(JointLimits.from_lists(("b", "a"), [], [0.5, 2.0], [1.0, 3.0]))
    np.testing.assert_array_equal(tight.upper, [0.5, 1.5])
    np.testing.assert_array_equal(tight.velocity, [1.0, 2.0])
    with pytest.raises(ValueError, match="do not overlap"):
        lim.tighter(JointLimits.from_lists(("b", "a"), [0.0, 2.0], [1.0, 3.0]))


def test_rate_watch_counts_rate_gaps_bursts_drops_and_lag():
    w = RateWatch(1000.0)
    ms = 1_000_000
    t = 0
    for k in range(1, 101):  # 100 messages at 1 kHz, one lost (seq 50), one pause of 5 ms, two bunched
        if k == 50:
            t += ms
            continue
        t += 5 * ms if k == 70 else ms
        received = t + 100_000 if k != 80 else t + 900_000  # 81 arrives 0.1 ms after 80's late arrival
        w.arrival(t, received, received + (3 * ms if k == 90 else 10_000), k)
    win = w.window()
    assert win.messages == 99 and win.drops == 1 and win.drops_counted
    assert win.gaps == 2  # the lost message's 2 ms and the 5 ms pause
    assert win.largest_gap_s == pytest.approx(5e-3)
    assert win.bursts == 1 and win.largest_lag_s == pytest.approx(3e-3)
    assert win.rate_hz == pytest.approx(98 / ((t - 1 * ms) * 1e-9))
    assert win.trouble
    empty = w.window()
    assert empty.messages == 0 and math.isnan(empty.rate_hz) and not empty.trouble
    w.arrival(t + ms, t + ms, t + ms, 7, publishers=2)  # several publishers: their numbers interleave
    win = w.window()
    assert win.drops == 0 and not win.drops_counted and w.total_drops == 1


def test_a_cycle_without_end_is_abandoned_at_the_sample_bound():
    from shaper_nodes.core.cycles import END, START, CycleMonitor

    m = CycleMonitor(max_samples=100)
    m.event(START, 1, 0.0)
    for k in range(250):
        m.add_accel(0.001 * k, [0.0, 0.0, 0.0])
    assert not m.in_cycle and m.abandoned == 1 and not m._acc_t
    assert m.event(END, 1, 1.0) is None  # its END, if it comes, finds no cycle
    m.event(START, 2, 2.0)
    m.add_accel(2.1, [1.0, 0.0, 0.0])
    assert m.in_cycle and m.abandoned == 1
