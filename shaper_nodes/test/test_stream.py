"""The rules of the shaper node's streamed commands (core/shaping/stream.py), without ROS: input bounds,
joint limits, time order, the output check and the filters' restart after a refused output, blocks,
trajectory fields that appear or vanish, shaper switches."""

from __future__ import annotations

import array
import math
import subprocess
import sys

import numpy as np
import pytest

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.lockstep import block_rows
from shaper_nodes.core.shaping import Mode, RetimingShaper, StreamingShaper, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.stream import FIELDS, CommandStream, check_times, normal_stamp

RATE = 100.0
NAMES = ("a", "b")
ZV = discretize(design("zv", [Mode.from_hz(5.0, 0.0)]), RATE)  # half now, half 0.1 s (10 samples) later
NONE = discretize(design("none", []), RATE)


def stream(lower=(), upper=(), velocity=(), fir=ZV, **kwargs) -> CommandStream:
    return CommandStream(fir, JointLimits.from_lists(NAMES, lower, upper, velocity), max_abs=1e6, **kwargs)


class refused:  # a context manager, used as a function
    """pytest.raises(InputError) that also checks the error's ``kind``, and its message if ``words``."""

    def __init__(self, kind: str, words: str | None = None) -> None:
        self.kind, self.ctx = kind, pytest.raises(InputError, match=words or None)

    def __enter__(self):
        self.info = self.ctx.__enter__()
        return self.info

    def __exit__(self, *exc):
        out = self.ctx.__exit__(*exc)
        assert self.info.value.kind == self.kind, str(self.info.value)
        return out


def test_the_module_imports_no_rclpy():
    code = ("import sys; import shaper_nodes.core.shaping.stream; import shaper_nodes.core.shaping;"
            " assert 'rclpy' not in sys.modules, 'rclpy imported';"
            " assert not [m for m in sys.modules if m.endswith('_msgs') or '.msg' in m], 'messages imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_sample_is_shaped_as_the_filter_shapes_it():
    s = stream()
    ref = StreamingShaper(ZV, 2)
    for x in ([0.0, 0.0], [1.0, -1.0], [1.0, -1.0], [0.5, 2.0]):
        assert s.shape_array(x) == pytest.approx(ref.process(np.array(x)).tolist(), abs=1e-12)
    assert s.shape_array(array.array("d", [0.5, 2.0])) == pytest.approx(ref.process(np.array([0.5, 2.0])).tolist())


@pytest.mark.parametrize("data, kind, words", [
    ([], "empty", "data is empty"),
    ([1.0], "wrong_size", "data has 1 values, expected 2"),
    ([1.0, 2.0, 3.0], "wrong_size", "expected 2"),
    ([math.nan, 0.0], "non_finite", ""),
    ([0.0, math.inf], "non_finite", ""),
    ([0.0, 2e6], "too_large", ""),
])
def test_refused_inputs_name_their_reason_and_leave_the_filter_as_it_was(data, kind, words):
    s, ref = stream(), StreamingShaper(ZV, 2)
    s.shape_array([1.0, 1.0])
    ref.process(np.array([1.0, 1.0]))
    with refused(kind, words):
        s.shape_array(data)
    assert s.shape_array([0.0, 0.0]) == pytest.approx(ref.process(np.array([0.0, 0.0])).tolist())


def test_max_abs_may_change_at_any_time():
    s = stream()
    s.shape_array([5.0, 5.0])
    s.max_abs = 4.0
    with refused("too_large"):
        s.shape_array([5.0, 5.0])
    s.max_abs = 10.0
    s.shape_array([5.0, 5.0])


def test_inputs_beyond_the_joint_limits_are_refused_before_the_filter():
    s = stream(lower=[-1.0, -1.0], upper=[1.0, 1.0])
    s.shape_array([0.0, 0.0])
    with refused("beyond_limits", "position limit of joint 'b'"):
        s.shape_array([0.0, 1.5])
    with refused("beyond_limits", "joint 'a'"):
        s.shape_block([0.0, 0.0, -1.5, 0.0], 2)
    assert s.shape_array([0.0, 0.0]) == [0.0, 0.0]  # nothing of them stayed


def test_an_output_beyond_the_limits_restarts_the_filter_at_the_last_command_sent():
    """A custom shaper with a negative impulse overshoots its input: the overshoot is refused, nothing is
    passed on, and the next sample is shaped from rest at the last command sent."""
    over = discretize(design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.05], max_gain=3.0), RATE)
    s = stream(lower=[-1.0, -1.0], upper=[1.0, 1.0], fir=over)
    assert s.shape_array([0.0, 0.0]) == [0.0, 0.0]
    sent = s.shape_array([0.4, 0.0])  # 2 * 0.4 - 0 = 0.8: inside
    assert sent == pytest.approx([0.8, 0.0])
    with refused("beyond_limits", "the filters restart from the last command passed on"):
        s.shape_array([0.9, 0.0])  # 2 * 0.9 - 0 = 1.8: beyond 1
    # from rest at [0.8, 0]: a constant input there stays there
    assert s.shape_array([0.8, 0.0]) == pytest.approx([0.8, 0.0])
    assert s.shape_array([0.8, 0.0]) == pytest.approx([0.8, 0.0])


def test_a_non_finite_output_is_refused_and_the_filter_restarts():
    s = stream()
    s.shape_array([0.0, 0.0])
    s.array_filter.process_values = lambda v: [math.nan, 0.0]  # type: ignore[method-assign]
    with refused("non_finite", "would not be finite"):
        s.shape_array([0.0, 0.0])
    del s.array_filter.process_values
    assert s.shape_array([0.0, 0.0]) == [0.0, 0.0]


def test_an_output_beyond_the_limits_across_a_switch_is_refused():
    """A positive shaper's output leaves the range of its input across a switch (core/shaping/limits.py)."""
    slow = discretize(design("zv", [Mode.from_hz(1.0, 0.0)]), RATE)
    s = stream(lower=[0.0, 0.0], upper=[1.0, 1.0], fir=slow)
    s.shape_array([0.0, 0.0])
    s.shape_array([1.0, 1.0])
    s.switch(NONE)
    with refused("beyond_limits", "beyond 0"):
        s.shape_array([0.0, 0.0])
    assert s.shape_array([1.0, 1.0]) == pytest.approx([1.0, 1.0])  # restarted at rest at the last sent, 1 - 0.5


def test_block_rows_from_the_layout():
    assert block_rows([2], 2, 2, 10) == 1
    assert block_rows([3, 2], 6, 2, 10) == 3
    with refused("wrong_size", r"layout \[3, 2\] does not describe samples x 2 joints in 5 values"):
        block_rows([3, 2], 5, 2, 10)
    with refused("wrong_size"):
        block_rows([3, 3], 9, 2, 10)
    with refused("wrong_size"):
        block_rows([0, 2], 0, 2, 10)
    with refused("wrong_size"):
        block_rows([1, 1, 2], 2, 2, 10)
    with refused("too_large", r"a block of 11 samples is more than limits.max_trajectory_samples \(10\)"):
        block_rows([11, 2], 22, 2, 10)


def test_a_block_is_shaped_as_its_samples_one_by_one():
    rows = np.array([[0.0, 0.0], [1.0, -1.0], [1.0, -1.0], [0.3, 0.2]] * 5)
    one, block = stream(), stream()
    expect = [one.shape_array(r.tolist()) for r in rows]
    got = block.shape_block(rows.ravel().tolist(), rows.shape[0])
    assert got == pytest.approx(np.array(expect).ravel().tolist(), abs=1e-12)
    assert block.shape_array([0.5, 0.5]) == pytest.approx(one.shape_array([0.5, 0.5]), abs=1e-12)


def test_a_block_with_one_bad_sample_is_refused_whole():
    s, ref = stream(), stream()
    s.shape_array([1.0, 1.0])
    ref.shape_array([1.0, 1.0])
    with refused("non_finite"):
        s.shape_block([0.0, 0.0, math.nan, 0.0], 2)
    with refused("too_large"):
        s.shape_block([0.0, 0.0, 1e7, 0.0], 2)
    with refused("wrong_size"):
        s.shape_block([0.0, 0.0, 0.0], 2)
    assert s.shape_block([0.0] * 4, 2) == pytest.approx(ref.shape_block([0.0] * 4, 2))


def test_a_block_whose_output_leaves_the_limits_restarts_the_filter():
    over = discretize(design("custom", amplitudes=[2.0, -1.0], times=[0.0, 0.05], max_gain=3.0), RATE)
    s = stream(lower=[-1.0, -1.0], upper=[1.0, 1.0], fir=over)
    s.shape_array([0.0, 0.0])
    s.shape_array([0.2, 0.0])  # sent 0.4
    with refused("beyond_limits"):
        s.shape_block([0.2, 0.0, 0.9, 0.0], 2)
    assert s.shape_array([0.4, 0.0]) == pytest.approx([0.4, 0.0])  # from rest at 0.4


@pytest.mark.parametrize("times, kind", [
    ([-0.1], "non_increasing_time"),
    ([0.0, 0.01, 0.01], "non_increasing_time"),
    ([0.02, 0.01], "non_increasing_time"),
    ([0.0, math.nan], "non_finite"),
    ([0.0, math.inf], "non_finite"),
])
def test_points_out_of_time_order_are_refused(times, kind):
    with refused(kind):
        check_times(np.array(times))
    s = stream()
    x = np.zeros((len(times), 2))
    with refused(kind):
        s.shape_points(np.array(times), {"positions": x})


def test_times_in_order_pass():
    check_times(np.array([0.0]))
    check_times(np.array([0.0, 0.01, 0.02]))
    check_times(np.array([0.5]), require_order=True)
    with refused("empty"):
        check_times(np.array([]), require_order=True)


def test_stream_points_are_shaped_per_field_and_fields_that_appear_start_at_their_first_value():
    s = stream()
    t = np.array([0.0, 0.01])
    pos = np.array([[0.0, 0.0], [1.0, 1.0]])
    out = s.shape_points(t, {"positions": pos})
    assert list(out) == ["positions"] and s.fields == ("positions",)
    assert out["positions"] == pytest.approx(StreamingShaper(ZV, 2).process(pos))
    vel = np.array([[2.0, 2.0], [2.0, 2.0]])
    out = s.shape_points(t, {"positions": pos, "velocities": vel})
    assert s.fields == ("positions", "velocities")
    assert out["velocities"] == pytest.approx(vel)  # at rest at its first value: no step from zero
    # velocities vanish: no longer output; when they come back they start afresh at their new value
    out = s.shape_points(t, {"positions": pos})
    assert list(out) == ["positions"] and s.fields == ("positions",)
    back = np.array([[-3.0, 1.0], [-3.0, 1.0]])
    out = s.shape_points(t, {"positions": pos, "velocities": back})
    assert out["velocities"] == pytest.approx(back)


@pytest.mark.parametrize(("stamp", "normal"), [
    ((5, 4_000_000_000), (9, 0)), ((0, 1_500_000_000), (1, 500_000_000)),
    ((-3, 4_294_967_295), (1, 294_967_295)), ((7, 999_999_999), (7, 999_999_999))])
def test_stamps_are_normalised(stamp, normal):
    assert normal_stamp(*stamp) == normal


def test_a_stamp_that_overflows_int32_seconds_is_refused():
    with refused("too_large", "does not fit"):
        normal_stamp(2**31 - 2, 4_000_000_000)


def test_header_stamps_may_not_go_back_zero_means_now():
    s = stream()
    t = np.array([0.0])
    pos = np.array([[0.1, 0.1]])
    s.shape_points(t, {"positions": pos}, (10, 0))
    s.shape_points(t, {"positions": pos}, (10, 0))  # the same stamp again: not going back
    s.shape_points(t, {"positions": pos}, (0, 0))  # "now": always taken, not ordered
    with refused("non_increasing_time", r"header stamp 9\.500000000 s is before the last accepted one, 10\.0"):
        s.shape_points(t, {"positions": np.array([[5.0, 5.0]])}, (9, 500_000_000))
    # the refused point left nothing in the filter: the next sample continues from 0.1
    out = s.shape_points(t, {"positions": pos}, (11, 0))
    assert out["positions"] == pytest.approx(pos)
    assert s.last_stamp_ns == 11 * 10**9


def test_stream_points_beyond_a_velocity_limit_restart_every_field_filter():
    s = stream(velocity=[1.0, 1.0])
    t = np.array([0.0])
    s.shape_points(t, {"positions": np.zeros((1, 2)), "velocities": np.full((1, 2), 0.5)})
    with refused("beyond_limits", "velocity limit"):
        s.shape_points(t, {"positions": np.ones((1, 2)), "velocities": np.full((1, 2), 1.5)})
    out = s.shape_points(t, {"positions": np.zeros((1, 2)), "velocities": np.full((1, 2), 0.5)})
    assert out["positions"] == pytest.approx(np.zeros((1, 2)))
    assert out["velocities"] == pytest.approx(np.full((1, 2), 0.5))


def test_unknown_fields_are_refused():
    with refused("unsupported"):
        stream().shape_points(np.array([0.0]), {"positions": np.zeros((1, 2)), "effort": np.zeros((1, 2))})


def test_a_switch_is_bumpless_and_applies_to_every_filter():
    s = stream()
    for _ in range(20):
        s.shape_array([1.0, 1.0])
    s.switch(NONE)
    assert s.stages() == [2] + [0] * len(FIELDS)  # the array filter's old one runs out its tail; the others never ran
    assert s.shape_array([1.0, 1.0]) == pytest.approx([1.0, 1.0])  # no jump
    y = s.shape_array([0.0, 0.0])
    assert y == pytest.approx([0.0, 0.0])  # the new filter passes the step at once
    for f in (s.array_filter, *s.field_filters.values()):
        assert f.fir is NONE


def test_retime_needs_retiming_filters():
    s = stream(retiming=True)
    assert isinstance(s.array_filter, RetimingShaper)
    s.shape_array([1.0, 1.0])
    s.switch(NONE, retime=True)
    assert s.shape_array([1.0, 1.0]) == pytest.approx([1.0, 1.0])
    with pytest.raises(ValueError, match="retiming=True"):
        stream().switch(NONE, retime=True)


def test_the_lock_is_held_by_every_call_on_the_filters():
    s = stream()
    seen = []
    s.array_filter.process_values = lambda v: (seen.append(s.lock.locked()), v)[1]  # type: ignore[method-assign]
    s.shape_array([0.0, 0.0])
    switch = s.array_filter.switch
    s.array_filter.switch = lambda fir: (seen.append(s.lock.locked()), switch(fir))[1]  # type: ignore[method-assign]
    s.switch(NONE)
    assert seen == [True, True]
    assert not s.lock.locked()


def test_the_written_out_bounds_check_is_the_comparisons_of_each_value():
    """The streamed sample's check (limits.bounds_check): one value per joint, lo <= v <= hi for each, a NaN or an
    infinity beyond a finite bound fails; the same truth as the comparisons through map(), on values at, inside and
    beyond the bounds, in a tuple or a list."""
    from operator import le

    from shaper_nodes.core.shaping.limits import bounds_check

    big = sys.float_info.max
    lo, hi = (-1.0, -big, 0.0, -math.inf), (1.0, big, 0.0, math.inf)
    within = bounds_check(lo, hi)
    assert bounds_check(lo, hi) is within  # cached per bounds
    rng = np.random.default_rng(7)
    picks = [-math.inf, -big, -1.5, -1.0, -0.0, 0.0, 0.5, 1.0, 1.5, big, math.inf, math.nan]
    for _ in range(2000):
        v = [float(x) for x in rng.choice(picks, size=4)]
        want = all(map(le, lo, v)) and all(map(le, v, hi))
        assert within(v) is want and within(tuple(v)) is want
    assert not within([0.0, 0.0, 0.0]) and not within([0.0] * 5)  # one value per joint
    with pytest.raises(ValueError, match="one \\(lowest, highest\\) pair per joint"):
        bounds_check((0.0,), (1.0, 2.0))
