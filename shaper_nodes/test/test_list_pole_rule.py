"""The pooled-pole rule per move (core/learning/list/pole_rule.py) and the running pool it keeps (loop_pole.Pool):
the pool is the mean of the windows, bit for bit, and survives a save; the loop's pole found in pooled references
gives a factor and the reference's amplitude and response at it; a trial is kept, run again or withdrawn by its
response there (the whitened change, ``loop_pole.change_at_pole``; the amplitude's rule for a reference saved before
it); a best fit at the search grid's top is no pole."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from shaper_nodes.core.learning.list.loop_pole import HZ_RANGE, LOWER, Pool, change_at_pole, fixed_pole_fit, pooled
from shaper_nodes.core.learning.list.params import ListError, ListParams
from shaper_nodes.core.learning.list.payback import Component
from shaper_nodes.core.learning.list.pole_rule import POOL_CYCLES, PoleState, judge_pole, pole_pick

RATE = 1000.0  # Hz
T = np.arange(0.0, 1.0, 1.0 / RATE)
LOOP = Component(2.0 * math.pi * 50.0, 0.6, 0.0)
RING = Component(2.0 * math.pi * 12.0, 0.04, 0.0)


def _response(c: Component, amplitude: float, direction: tuple[float, float, float]) -> np.ndarray:
    p = c.pole
    d = np.asarray(direction, dtype=float)
    return amplitude * np.outer(np.exp(p.real * T) * np.cos(p.imag * T), d / np.linalg.norm(d))


def _signal(loop_amp: float, noise: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    clean = (_response(LOOP, loop_amp, (1.0, 0.5, -0.3)) + _response(RING, 0.01, (0.2, 1.0, 0.1))
             + np.array([0.1, -9.81, 0.05]))
    return clean + noise * rng.standard_normal(clean.shape)


def _windows(loop_amp: float, noise: float, seeds: range) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Windows of the same response at different starts (each cycle's own clock), the commanded end at 0.3 s."""
    pad = np.zeros((300, 3)) + np.array([0.1, -9.81, 0.05])
    return [(np.arange(T.size + 300) / RATE + 7.0 * k, np.vstack([pad, _signal(loop_amp, noise, k)]), 7.0 * k + 0.3)
            for k in seeds]


def test_the_running_pool_is_the_mean_of_the_windows_bit_for_bit_and_survives_a_save():
    windows = _windows(0.04, 0.01, range(3))
    cut = [(t[(t >= s) & (t <= s + 1.0)] - s, y[(t >= s) & (t <= s + 1.0)]) for t, y, s in windows]
    n = min(t.size for t, _ in cut)
    want = np.mean([y[:n] for _, y in cut], axis=0)  # the mean as pooled() took it before the running sum
    pool = Pool()
    for k, (t, y, s) in enumerate(windows):
        pool.add(t, y, s)
        pool = Pool.from_dict(json.loads(json.dumps(pool.to_dict())))  # saved and restored after every cycle
        assert pool.count == k + 1
    times, mean = pool.mean()
    assert np.array_equal(mean, want) and np.array_equal(times, cut[0][0][:n])
    assert np.array_equal(pooled(windows)[1], want)
    # bounded: one window's samples, whatever the count (4 numbers per sample of three axes)
    assert len(pool.to_dict()["times"]) == n and np.asarray(pool.to_dict()["sum"]).shape == (n, 3)


def test_a_shorter_window_cuts_the_pool_and_bad_saved_pools_are_refused():
    pool = Pool()
    pool.add(T, np.ones((T.size, 3)), 0.0)
    pool.add(T[:-10] + 2.0, 3.0 * np.ones((T.size - 10, 3)), 2.0)
    t, y = pool.mean()
    assert t.size == T.size - 10 and np.allclose(y, 2.0)
    with pytest.raises(ListError, match="axes"):
        pool.add(T, np.ones((T.size, 2)), 0.0)
    with pytest.raises(ListError, match="no window"):
        Pool().mean()
    good = pool.to_dict()
    for bad in ({**good, "count": -1}, {**good, "count": True}, {**good, "length": 0.0},
                {**good, "sum": good["sum"][:-1]}, {**good, "times": good["times"][::-1]},
                {**good, "sum": [[math.nan] * 3] * len(good["times"])}, {"count": 1}, [1, 2]):
        with pytest.raises(ListError):
            Pool.from_dict(bad)
    assert Pool.from_dict(Pool().to_dict()).count == 0


def _cost(p: ListParams) -> float:
    return 0.0  # every factor within the time rule


def test_the_loop_pole_is_picked_in_pooled_references_where_one_window_cannot_resolve_it():
    # the loop's part at 0.03 m/s^2 (5 ms long) under 0.03 of noise: one window does not resolve it, three pooled do
    windows = _windows(0.03, 0.03, range(POOL_CYCLES))
    one = pole_pick(*pooled(windows[:1]), _cost, 0.002, 0.12, 0.1)
    pick = pole_pick(*pooled(windows), _cost, 0.002, 0.12, 0.1)
    assert one is None
    assert pick is not None
    assert pick.choice.component == pick.loop and pick.loop.zeta >= 0.12
    assert pick.poles[-1] == pick.loop.pole and pick.ringing == len(pick.poles) - 1
    assert pick.reference[0] > 3.0 * pick.reference[1] > 0.0
    # a factor on it that costs more than the time rule allows is not chosen
    assert pole_pick(*pooled(windows), lambda p: 1.0, 0.002, 0.12, 0.1) is None


def test_a_trial_is_kept_run_again_or_withdrawn_by_its_amplitude_at_the_pole():
    """The amplitude's rule: a reference saved before the response was (no ``response``)."""
    ref_windows = _windows(0.04, 0.01, range(2))
    pick = pole_pick(*pooled(ref_windows), _cost, 0.002, 0.12, 0.1)
    assert pick is not None
    gone = pooled(_windows(0.0, 0.01, range(10, 11)))
    assert judge_pole(*gone, pick.poles, pick.reference, 1)[0] == "learn"
    same = pooled(_windows(0.04, 0.01, range(20, 21)))
    assert judge_pole(*same, pick.poles, pick.reference, 1)[0] == "base"
    # lower but within the combined errors: again while fewer than POOL_CYCLES windows, then withdrawn
    ref = (pick.reference[0], 0.6 * pick.reference[0])
    decision, trial, change = judge_pole(*gone, pick.poles, ref, 1)
    assert decision == "again" and trial[0] < ref[0] and math.isnan(change)
    assert judge_pole(*gone, pick.poles, ref, POOL_CYCLES)[0] == "base"
    assert judge_pole(*gone, pick.poles, pick.reference, 1, in_time=False)[0] == "base"


def test_a_trial_is_kept_run_again_or_withdrawn_by_its_response_at_the_pole():
    ref_windows = _windows(0.04, 0.01, range(2))
    pick = pole_pick(*pooled(ref_windows), _cost, 0.002, 0.12, 0.1)
    assert pick is not None and pick.response is not None
    coef, cov = pick.response
    assert coef.shape == (2, 3) and cov.shape == (2, 2) and np.all(np.linalg.eigvalsh(cov) > 0)
    gone = pooled(_windows(0.0, 0.01, range(10, 11)))
    decision, _, change = judge_pole(*gone, pick.poles, pick.reference, 1, response=pick.response)
    assert decision == "learn" and change > LOWER
    same = pooled(_windows(0.04, 0.01, range(20, 21)))
    decision, _, change = judge_pole(*same, pick.poles, pick.reference, 1, response=pick.response)
    assert decision == "base" and change < 1.0
    # lower but not by LOWER standard errors of the change (the reference's covariance 8 times larger): again while
    # fewer than POOL_CYCLES windows, then withdrawn; out of time: withdrawn
    wide = (coef, 8.0 * cov)
    decision, _, change = judge_pole(*gone, pick.poles, pick.reference, 1, response=wide)
    assert decision == "again" and 0.0 < change <= LOWER
    assert judge_pole(*gone, pick.poles, pick.reference, POOL_CYCLES, response=wide)[0] == "base"
    assert judge_pole(*gone, pick.poles, pick.reference, 1, in_time=False, response=pick.response)[0] == "base"


def test_the_change_at_a_pole_of_an_unchanged_response_is_about_one_standard_error_and_a_removed_one_resolves():
    """change_at_pole on the loop's pole fixed (no search: its own bias only), 400 draws each, the transient's
    amplitude about 3.4 standard errors in one window (a pole found near the margin): an unchanged response (the
    same transient in reference and trial, independent noise) reads about N(0, 1) (centred; its spread somewhat
    wider, about 1.1: the direction is measured in the reference's noise) and is judged lower by LOWER in under
    5 %; a removed response is resolved far more often than by the norm-based amplitude's rule (about 60 % against
    35 %)."""
    poles = (RING.pole, LOOP.pole)
    unchanged, removed, by_amplitude = [], [], 0
    for k in range(400):
        ref = fixed_pole_fit(T, _signal(0.08, 0.03, 1000 + k), 0.0, poles)
        same = fixed_pole_fit(T, _signal(0.08, 0.03, 5000 + k), 0.0, poles)
        gone = fixed_pole_fit(T, _signal(0.0, 0.03, 9000 + k), 0.0, poles)
        assert ref.response is not None and same.response is not None and gone.response is not None
        unchanged.append(change_at_pole(ref.response, same.response))
        removed.append(change_at_pole(ref.response, gone.response))
        e_ref, e_gone = ref.errors[-1], gone.errors[-1]
        by_amplitude += gone.amplitudes[-1] + LOWER * math.hypot(e_ref, e_gone) < ref.amplitudes[-1]
    u = np.asarray(unchanged)
    assert abs(float(u.mean())) < 0.2 and 0.8 < float(u.std()) < 1.3
    assert float(np.mean(u > LOWER)) < 0.05  # kept without a change: about 2 %
    assert float(np.mean(np.asarray(removed) > LOWER)) > by_amplitude / 400 + 0.15


def test_a_best_fit_at_the_search_grids_top_frequency_is_no_pole():
    top = Component(2.0 * math.pi * (HZ_RANGE[1] + 30.0), 0.3, 0.0)  # above the grid: its best fit sits at the top
    rng = np.random.default_rng(3)
    clean = _response(top, 0.2, (1.0, 0.2, 0.1)) + np.array([0.1, -9.81, 0.05])
    assert pole_pick(T, clean + 0.001 * rng.standard_normal(clean.shape), _cost, 0.002, 0.12, 0.1) is None
    inside = _response(LOOP, 0.2, (1.0, 0.2, 0.1)) + np.array([0.1, -9.81, 0.05])
    assert pole_pick(T, inside + 0.001 * rng.standard_normal(clean.shape), _cost, 0.002, 0.12, 0.1) is not None


def test_a_moves_pole_state_survives_a_save_and_bad_ones_are_refused():
    st = PoleState()
    for t, y, s in _windows(0.04, 0.01, range(2)):
        st.pool.add(t, y, s)
    restored = PoleState.from_dict(json.loads(json.dumps(st.to_dict())))
    assert restored.pool.count == 2 and not restored.judging
    pick = pole_pick(*st.pool.mean(), _cost, 0.002, 0.12, 0.1)
    assert pick is not None
    st.chosen(pick)
    assert st.judging and st.pool.count == 0  # the references' pool gave way to the trial's
    restored = PoleState.from_dict(json.loads(json.dumps(st.to_dict())))
    assert restored.poles == pytest.approx(pick.poles) and restored.reference == pytest.approx(pick.reference)
    assert restored.response is not None and pick.response is not None
    assert np.array_equal(restored.response[0], pick.response[0]) and np.array_equal(restored.response[1],
                                                                                     pick.response[1])
    old = st.to_dict()
    del old["response"]  # a state saved before the response was: judged by the amplitude's rule
    assert PoleState.from_dict(old).judging and PoleState.from_dict(old).response is None
    for bad in ({**st.to_dict(), "response": {"coefficients": [[1.0, 2.0]], "covariance": [[1.0, 0.0], [0.0, 1.0]]}},
                {**st.to_dict(), "response": {"coefficients": [[1.0], [2.0]], "covariance": [[1.0, 2.0], [2.0, 1.0]]}},
                {**st.to_dict(), "response": {"coefficients": [[1.0], [math.nan]],
                                              "covariance": [[1.0, 0.0], [0.0, 1.0]]}},
                {**st.to_dict(), "response": [1.0]}, {**st.to_dict(), "extra": 1}):
        with pytest.raises(ListError):
            PoleState.from_dict(bad)
    st.reset()
    assert not st.judging and st.pool.count == 0 and st.response is None
    good = PoleState(pooled_only=True).to_dict()
    assert PoleState.from_dict(good).pooled_only
    for bad in ({**good, "pooled_only": 1}, {**good, "poles": [[-1.0, 2.0]]}, {**good, "reference": [0.1, 0.01]},
                {**good, "poles": [[-1.0]], "reference": [0.1, 0.01]},
                {**good, "poles": [[-1.0, 2.0]], "reference": [-0.1, 0.01]}, {"pool": good["pool"]}):
        with pytest.raises(ListError):
            PoleState.from_dict(bad)
