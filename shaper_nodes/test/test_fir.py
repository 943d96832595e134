"""Streaming FIR: equals offline convolution; bumpless, exact switching; re-timing."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from shaper_nodes.core.shaping.families import design
from shaper_nodes.core.shaping.fir import MAX_STAGES, RetimingShaper, StreamingShaper, discretize
from shaper_nodes.core.shaping.types import Mode

SETTINGS = settings(max_examples=40, deadline=None)
shaper_st = st.builds(
    lambda fam, hz, z: design(fam, [Mode.from_hz(hz, z)]),
    st.sampled_from(["zv", "zvd", "zvdd", "ei"]), st.floats(1.0, 40.0), st.floats(0.0, 0.2))


def offline(x, taps):
    """Convolution of x (at rest at x[0] before the start) with the dense taps."""
    pad = np.repeat(x[:1], taps.size - 1, axis=0)
    xe = np.vstack([pad, x])
    return np.column_stack([np.convolve(xe[:, j], taps, mode="valid") for j in range(x.shape[1])])


@SETTINGS
@given(shaper_st, st.sampled_from([250.0, 500.0, 1000.0]), st.sampled_from(["split", "round"]),
       arrays(float, (200, 3), elements=st.floats(-10, 10)))
def test_streaming_equals_offline_convolution(shaper, rate, method, x):
    fir = discretize(shaper, rate, method)
    assert fir.dense().sum() == pytest.approx(1.0, abs=1e-12)
    s = StreamingShaper(fir, 3)
    y = np.vstack([s.process(x[k]) for k in range(x.shape[0])])
    np.testing.assert_allclose(y, offline(x, fir.dense()), atol=1e-9)
    # blocks of any size give the same as sample by sample
    s2 = StreamingShaper(fir, 3)
    y2 = np.vstack([s2.process(x[:37]), s2.process(x[37:38]), s2.process(x[38:])])
    np.testing.assert_allclose(y2, y, atol=1e-12)


def ramp_and_hold(n_move=300, n_hold=1200, goal=1.0):
    return np.concatenate([np.linspace(0, goal, n_move), np.full(n_hold, goal)])[:, None]


@SETTINGS
@given(shaper_st, shaper_st, st.integers(1, 299))
def test_switching_mid_motion_is_bumpless(a, b, k_switch):
    """Output stays continuous and settles to the same final value when the shaper changes."""
    rate = 500.0
    fa, fb = discretize(a, rate), discretize(b, rate)
    x = ramp_and_hold()
    s = StreamingShaper(fa, 1)
    y = np.vstack([s.process(x[:k_switch]), s.switch(fb) or s.process(x[k_switch:])])
    dx = np.max(np.abs(np.diff(x[:, 0])))
    # every output increment is a convex mix of input increments of the two filters: at most 2 of them
    assert np.max(np.abs(np.diff(y[:, 0]))) <= 2 * dx + 1e-12
    assert y[-1, 0] == pytest.approx(1.0, abs=1e-12)
    assert s.stages == 1  # the retired filter was folded once its tail had passed


@SETTINGS
@given(shaper_st, st.integers(1, 1400))
def test_switching_to_the_same_filter_changes_nothing(a, k_switch):
    fir = discretize(a, 500.0)
    x = ramp_and_hold()
    ref = StreamingShaper(fir, 1).process(x)
    s = StreamingShaper(fir, 1)
    y = np.vstack([s.process(x[:k_switch]), s.switch(fir) or s.process(x[k_switch:])])
    np.testing.assert_allclose(y, ref, atol=1e-12)


def test_motion_before_a_switch_keeps_its_own_shaping():
    """Increments commanded before the switch are shaped by the old filter only."""
    m = Mode.from_hz(5.0, 0.0)
    fa = discretize(design("zvd", [m]), 500.0)
    fb = discretize(design("none"), 500.0)
    x = ramp_and_hold(100, 400)
    ref = StreamingShaper(fa, 1).process(x)
    s = StreamingShaper(fa, 1)
    y = np.vstack([s.process(x[:150]), s.switch(fb) or s.process(x[150:])])  # switch after the motion
    np.testing.assert_allclose(y, ref, atol=1e-12)


def test_starts_at_rest_at_the_first_sample():
    s = StreamingShaper(discretize(design("zvd", [Mode(20.0, 0.05)]), 500.0), 2)
    y = s.process(np.array([[3.0, -1.0]] * 5))
    np.testing.assert_allclose(y, [[3.0, -1.0]] * 5)


def test_too_many_pending_switches_is_refused_and_leaves_the_filter():
    fa = discretize(design("zvd", [Mode(2.0, 0.0)]), 500.0)
    fb = discretize(design("zv", [Mode(2.0, 0.0)]), 500.0)
    s = StreamingShaper(fa, 1)
    s.process(np.zeros((1, 1)))
    for k in range(MAX_STAGES - 1):
        s.switch(fb if k % 2 == 0 else fa)
        s.process(np.full((1, 1), float(k)))
    before = s.fir
    with pytest.raises(RuntimeError, match="still settling"):
        s.switch(fb)
    assert s.fir is before


@SETTINGS
@given(shaper_st, shaper_st, st.integers(0, 150), arrays(float, (150, 2), elements=st.floats(-10, 10)))
def test_retiming_shaper_without_retime_is_the_bumpless_streaming_shaper(a, b, k_switch, x):
    rate = 250.0
    fa, fb = discretize(a, rate), discretize(b, rate)
    ref, sh = StreamingShaper(fa, 2), RetimingShaper(fa, 2)
    before_ref = ref.process(x[:k_switch])
    ref.switch(fb)
    y_ref = np.vstack([before_ref, ref.process(x[k_switch:])])
    before = sh.process(x[:k_switch])
    sh.switch(fb)
    y = np.vstack([before, sh.process(x[k_switch:])])
    np.testing.assert_allclose(y, y_ref, atol=1e-9)


def test_retime_moves_a_pending_impulse_and_never_takes_back_what_was_emitted():
    rate = 100.0
    slow = discretize(design("zv", [Mode(math.pi / 2.0, 0.0)]), rate)  # second impulse at 2 s
    fast = discretize(design("zv", [Mode(math.pi, 0.0)]), rate)        # at 1 s
    sh = RetimingShaper(slow, 1)
    x = np.concatenate([np.zeros(10), np.ones(400)])[:, None]
    y1 = sh.process(x[:60])                 # the step at 0.1 s; half emitted
    assert y1[-1, 0] == pytest.approx(0.5)
    sh.retime(fast)                         # 0.5 s after the step: the rest now comes at 1 s
    y2 = sh.process(x[60:])
    t_full = (60 + int(np.argmax(y2[:, 0] >= 1.0 - 1e-12))) / rate
    assert t_full == pytest.approx(1.1, abs=0.011)
    sh.retime(slow)                         # after everything was emitted: nothing goes back
    y3 = sh.process(np.ones((300, 1)))
    np.testing.assert_allclose(y3, 1.0)
    # re-timing to a later time while the second impulse is pending delays it; emitted stays
    sh2 = RetimingShaper(fast, 1)
    y = sh2.process(x[:60])
    sh2.retime(slow)
    y = np.vstack([y, sh2.process(x[60:])])
    assert np.all(np.diff(y[:, 0]) >= -1e-12)
    assert (np.argmax(y[:, 0] >= 1.0 - 1e-12)) / rate == pytest.approx(2.1, abs=0.011)


@SETTINGS
@given(shaper_st, shaper_st, st.sampled_from([250.0, 1000.0]), st.data(),
       arrays(float, (300, 7), elements=st.floats(-2, 2)))
def test_single_sample_path_equals_block_path_and_offline(shaper, other, rate, data, x):
    """The fast one-sample paths (ring buffer: numpy, and Python floats with process_values) give what the
    block path gives, through filter changes and any mix of one-sample calls of either kind and blocks,
    and all equal offline convolution."""
    fa, fb = discretize(shaper, rate), discretize(other, rate)
    # offline: one filter throughout
    one = StreamingShaper(fa, 7)
    ys = np.vstack([one.process(x[k]) for k in range(x.shape[0])])
    np.testing.assert_allclose(ys, offline(x, fa.dense()), rtol=0, atol=1e-12)
    lists = StreamingShaper(fa, 7)
    yl = np.array([lists.process_values(x[k].tolist()) for k in range(x.shape[0])])
    np.testing.assert_allclose(yl, offline(x, fa.dense()), rtol=0, atol=1e-12)
    # switches at drawn samples, sample by sample against one block between switches, against a
    # random mix of one-sample calls and blocks
    cuts = sorted(set(data.draw(st.lists(st.integers(1, x.shape[0] - 1), max_size=4))))
    bounds = [0, *cuts, x.shape[0]]
    by_sample, by_block, mixed = StreamingShaper(fa, 7), StreamingShaper(fa, 7), StreamingShaper(fa, 7)
    by_values = StreamingShaper(fa, 7)
    y1, y2, y3, y4 = [], [], [], []
    for i, (lo, hi) in enumerate(itertools.pairwise(bounds)):
        if i:
            f = fb if i % 2 else fa
            for s in (by_sample, by_block, mixed, by_values):
                s.switch(f)
        y1 += [by_sample.process(x[k]) for k in range(lo, hi)]
        y2.append(by_block.process(x[lo:hi]))
        y4 += [by_values.process_values(x[k].tolist()) for k in range(lo, hi)]
        k = lo
        while k < hi:
            n = data.draw(st.integers(-1, 40))  # -1: one sample as a list, 0 or 1: as an array, more: a block
            if n == -1:
                y3.append(np.array(mixed.process_values(x[k].tolist())))
            elif n <= 1:
                y3.append(mixed.process(x[k]))
            else:
                y3.append(mixed.process(x[k : min(hi, k + n)]))
            k = min(hi, k + n) if n > 1 else k + 1
    y1a, y2a, y3a, y4a = np.vstack(y1), np.vstack(y2), np.vstack(y3), np.array(y4)
    np.testing.assert_allclose(y1a, y2a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(y3a, y2a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(y4a, y2a, rtol=0, atol=1e-12)
    assert by_sample.stages == by_block.stages == mixed.stages == by_values.stages


def by_definition(x, firs_at):
    """y(k) = x(0) + sum_j s_f(j)(k - j) (x(j) - x(j - 1)) (the module docstring), with s_f the step response of
    the filter active when increment j arrived: ``firs_at[j]``."""
    steps = [np.concatenate([np.cumsum(f.dense()), [1.0]]) for f in firs_at]
    y = np.repeat(x[:1], x.shape[0], axis=0).astype(float)
    for j in range(1, x.shape[0]):
        s = steps[j]
        age = np.arange(x.shape[0] - j)
        y[j:] += s[np.minimum(age, s.size - 1)][:, None] * (x[j] - x[j - 1])
    return y


@SETTINGS
@given(st.lists(shaper_st, min_size=1, max_size=4), st.lists(st.integers(1, 399), min_size=0, max_size=3),
       arrays(float, (400, 2), elements=st.floats(-5, 5)))
def test_sample_by_sample_with_switches_is_the_definition_and_shares_no_state_with_its_caller(shapers, at, x):
    """The single-sample path (the node's: one setpoint a message), with switches between any two samples,
    equals the sum over increments by definition; neither the input nor the returned array is the filter's
    state (the caller reuses or keeps them: the node keeps the last output it sent)."""
    rate = 250.0
    firs = [discretize(s, rate) for s in shapers]
    at = sorted(set(at))[: len(firs) - 1]
    s = StreamingShaper(firs[0], 2)
    active, firs_at, out = 0, [], []
    row = np.empty(2)
    for k in range(x.shape[0]):
        if active + 1 < len(firs) and active < len(at) and k == at[active]:
            active += 1
            s.switch(firs[active])
        firs_at.append(firs[active])
        row[:] = x[k]  # one buffer for every input, as a caller reusing its array
        y = s.process(row)
        out.append(y.copy())
        row[:] = np.nan  # ... and into its input after the call
        y[:] = 1e9  # ... and into what it got
    np.testing.assert_allclose(np.vstack(out), by_definition(x, firs_at), rtol=0, atol=1e-9)
    # the same with one list per sample (process_values), which the caller changes after each call
    s, active, out = StreamingShaper(firs[0], 2), 0, []
    for k in range(x.shape[0]):
        if active + 1 < len(firs) and active < len(at) and k == at[active]:
            active += 1
            s.switch(firs[active])
        values = x[k].tolist()
        got = s.process_values(values)
        out.append(list(got))
        values[:] = [math.nan] * 2
        got[:] = [1e9] * 2
    np.testing.assert_allclose(np.array(out), by_definition(x, firs_at), rtol=0, atol=1e-9)


@pytest.mark.parametrize("cls", [StreamingShaper, RetimingShaper])
def test_process_values_takes_one_sample_of_the_filters_channels(cls):
    fir = discretize(design("zv", [Mode.from_hz(5.0, 0.05)]), 100.0)
    s = cls(fir, 3)
    with pytest.raises(ValueError, match="expected 3 values, got 2"):
        s.process_values([1.0, 2.0])
    assert s.process_values([1.0, 2.0, 3.0]) == [1.0, 2.0, 3.0]  # at rest at its first sample
    s.reset([0.5, 0.5, 0.5])  # a list, as the node's last sent command
    assert s.process_values([0.5, 0.5, 0.5]) == pytest.approx([0.5, 0.5, 0.5], abs=1e-15)


@pytest.mark.parametrize("k", [1, 2, 5, 18, 32, 33, 60])
def test_tap_steps_written_out_are_the_loop_over_the_taps_exactly(k):
    """The one-sample path's written-out step (up to UNROLLED_TAPS taps) writes the deviation to the ring's row and
    adds in the loop's order: equal bit for bit, the ring alike."""
    from shaper_nodes.core.shaping.fir_stage import UNROLLED_TAPS, _tap_step, _tap_step_loop

    rng = np.random.default_rng(k)
    size = k + 3
    gains, offset = rng.normal(size=k).tolist(), rng.normal(size=7).tolist()
    values, origin = rng.normal(size=7).tolist(), rng.normal(size=7).tolist()
    taps = [int(t) for t in rng.permutation(size)[:k]]
    p = taps[0]  # the row written is tapped too (delay 0), as in a FIR
    rows_a, rows_b = rng.normal(size=(size, 7)).tolist(), None
    rows_b = [list(r) for r in rows_a]
    out_a = _tap_step(k)(values, origin, rows_a, taps, p, gains, offset)
    out_b = _tap_step_loop(values, origin, rows_b, taps, p, gains, offset)
    assert out_a == out_b and rows_a == rows_b
    assert rows_a[p] == [v - o for v, o in zip(values, origin, strict=True)]
    assert (_tap_step(k) is _tap_step_loop) == (k > UNROLLED_TAPS)


@pytest.mark.parametrize(("k", "channels"), [(1, 1), (1, 7), (2, 3), (5, 7), (18, 7), (36, 7), (37, 7), (5, 60)])
def test_tap_steps_written_out_product_by_product_are_the_loop_over_the_taps_exactly(k, channels):
    """The one-sample path's step written out product by product (up to UNROLLED_TERMS products; beyond, the
    comprehension's or the loop's form) writes the deviation to the ring's row and adds in the loop's order: equal
    bit for bit, the ring alike, for a tuple of values as for a list."""
    from shaper_nodes.core.shaping.fir_stage import UNROLLED_TAPS, UNROLLED_TERMS, _tap_step, _tap_step_loop

    rng = np.random.default_rng(100 * k + channels)
    size = k + 3
    gains, offset = rng.normal(size=k).tolist(), rng.normal(size=channels).tolist()
    values, origin = tuple(rng.normal(size=channels).tolist()), rng.normal(size=channels).tolist()
    taps = [int(t) for t in rng.permutation(size)[:k]]
    p = taps[-1]
    rows_a = rng.normal(size=(size, channels)).tolist()
    rows_b = [list(r) for r in rows_a]
    step = _tap_step(k, channels)
    out_a = step(values, origin, rows_a, taps, p, gains, offset)
    out_b = _tap_step_loop(values, origin, rows_b, taps, p, gains, offset)
    assert out_a == out_b and rows_a == rows_b and isinstance(out_a, list) and isinstance(rows_a[p], list)
    by_product = step is not _tap_step_loop and step.__code__.co_filename.endswith(f"x {channels} channels>")
    assert by_product == (k * channels <= UNROLLED_TERMS)  # beyond: the comprehension's form, or the loop
    assert (step is _tap_step_loop) == (k * channels > UNROLLED_TERMS and k > UNROLLED_TAPS)
