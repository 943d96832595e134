"""The loop's damped pole in a noisy residual: pooled windows, the pole searched beside the modes that ring, its
amplitude by least squares with the pole fixed, and the trial's judgement at it (core/learning/list/loop_pole.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.learning.list.loop_pole import (
    HZ_RANGE,
    ZETA_RANGE,
    fixed_pole_fit,
    loop_pole,
    lower_at_pole,
    pooled,
)
from shaper_nodes.core.learning.list.params import ListError
from shaper_nodes.core.learning.list.payback import Component

RATE = 1000.0  # Hz, the offline arm's accelerometer
T = np.arange(0.0, 1.0, 1.0 / RATE)
LOOP = Component(2.0 * math.pi * 50.0, 0.6, 0.0)
RING = Component(2.0 * math.pi * 12.0, 0.04, 0.0)


def _response(c: Component, amplitude: float, direction: tuple[float, float, float], phase: float = 0.0,
              t: np.ndarray = T) -> np.ndarray:
    """A pole's free response, ``amplitude`` (m/s^2, norm over the axes) at t = 0."""
    p = c.pole
    wave = np.exp(p.real * t) * np.cos(p.imag * t + phase) / math.cos(phase)
    d = np.asarray(direction, dtype=float)
    return amplitude * np.outer(wave, d / np.linalg.norm(d))


def _signal(loop_amp: float, noise: float, seed: int, ring_amp: float = 0.01) -> np.ndarray:
    rng = np.random.default_rng(seed)
    clean = (_response(LOOP, loop_amp, (1.0, 0.5, -0.3)) + _response(RING, ring_amp, (0.2, 1.0, 0.1), 0.4)
             + np.array([0.1, -9.81, 0.05]) + 0.002 * T[:, None])  # gravity's offset and a drift
    return clean + noise * rng.standard_normal(clean.shape)


def test_the_amplitude_with_the_poles_fixed_is_recovered_with_an_honest_standard_error():
    misses = []
    for seed in range(40):
        fit = fixed_pole_fit(T, _signal(0.04, 0.01, seed), 0.0, [RING.pole, LOOP.pole])
        amp, err = fit.amplitudes[1], fit.errors[1]
        assert fit.variance == pytest.approx(1e-4, rel=0.2)  # the noise's variance per sample and axis
        misses.append(abs(amp - 0.04) > 3.0 * math.sqrt(3.0) * err)
    assert sum(misses) <= 2  # the norm over three axes: within 3 sqrt(3) standard errors nearly always
    clean = fixed_pole_fit(T, _signal(0.04, 0.0, 0), 0.0, [RING.pole, LOOP.pole])
    assert clean.amplitudes[1] == pytest.approx(0.04, rel=1e-6)
    assert clean.amplitudes[0] == pytest.approx(0.01, rel=1e-6)


def test_the_standard_error_falls_as_the_square_root_of_the_pooled_windows():
    one = fixed_pole_fit(T, _signal(0.04, 0.01, 0), 0.0, [RING.pole, LOOP.pole]).errors[1]
    windows = [(T + 5.0 * k, _signal(0.04, 0.01, k), 5.0 * k) for k in range(4)]
    t, y = pooled(windows)
    assert t[0] == pytest.approx(0.0) and y.shape == (T.size, 3)
    four = fixed_pole_fit(t, y, 0.0, [RING.pole, LOOP.pole]).errors[1]
    assert four == pytest.approx(one / 2.0, rel=0.15)


def test_pooled_windows_are_cut_to_the_shortest_and_an_empty_pool_is_refused():
    a = (T, np.ones((T.size, 3)), 0.0)
    b = (T[:-10] + 2.0, 3.0 * np.ones((T.size - 10, 3)), 2.0)
    t, y = pooled([a, b])
    assert t.size == T.size - 10 and np.allclose(y, 2.0)
    with pytest.raises(ListError, match="no window"):
        pooled([])


def test_the_loop_pole_is_found_beside_a_mode_that_rings_and_none_in_noise_alone():
    found = loop_pole(T, _signal(0.04, 0.002, 1), 0.0, [RING])
    assert found is not None
    c, err = found
    assert ZETA_RANGE[0] <= c.zeta <= ZETA_RANGE[1] and HZ_RANGE[0] <= c.hz <= HZ_RANGE[1]
    assert c.amplitude > 3.0 * err
    # the heavily damped transient is what it fits: the same response within a few % over its first 30 ms
    head = T < 0.03
    got = _response(c, 1.0, (1.0, 0.0, 0.0), t=T[head])[:, 0]
    want = _response(LOOP, 1.0, (1.0, 0.0, 0.0), t=T[head])[:, 0]
    assert float(np.sqrt(np.mean((c.amplitude * got - 0.04 * want) ** 2))) < 0.15 * 0.04
    assert loop_pole(T, _signal(0.0, 0.01, 2), 0.0, [RING]) is None


def test_a_trial_is_lower_at_the_pole_only_by_more_than_the_combined_standard_errors():
    assert lower_at_pole((0.05, 0.005), (0.01, 0.005))  # 0.04 below, 2 x 0.0071 needed
    assert not lower_at_pole((0.05, 0.005), (0.04, 0.005))
    assert not lower_at_pole((0.05, 0.005), (0.06, 0.001))
    assert lower_at_pole((0.05, 0.005), (0.04, 0.005), significance=1.0)


def test_too_short_a_window_for_the_poles_is_refused():
    with pytest.raises(ListError, match="cannot fit"):
        fixed_pole_fit(T[:5], np.zeros((5, 3)), 0.0, [RING.pole, LOOP.pole])
