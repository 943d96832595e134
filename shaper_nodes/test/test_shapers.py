"""Shaper designs: the papers' formulas and the defining properties of each family."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shaper_nodes.core.shaping.families import FAMILIES, design, zvdn
from shaper_nodes.core.shaping.types import Mode, ShaperError
from shaper_nodes.core.shaping.vibration import percentage_vibration, sensitivity_curve

freqs = st.floats(min_value=0.2, max_value=80.0)
dampings = st.floats(min_value=0.0, max_value=0.3)
FAST = settings(max_examples=60, deadline=None)


def v_at(shaper, omega, zeta):
    return float(percentage_vibration(shaper.amplitudes, shaper.times, omega, zeta))


@FAST
@given(freqs, dampings, st.sampled_from(["zv", "zvd", "zvdd", "zvdn", "ei"]), st.integers(0, 5))
def test_amplitudes_sum_to_one_and_times_start_at_zero(hz, zeta, family, n):
    s = design(family, [Mode.from_hz(hz, zeta)], derivative_order=n)
    assert math.isclose(s.amplitudes.sum(), 1.0, abs_tol=1e-12)
    assert s.times[0] == 0.0 and np.all(np.diff(s.times) >= 0)
    assert np.all(s.amplitudes > 0)


@FAST
@given(freqs, dampings, st.sampled_from(["zv", "zvd", "zvdd"]))
def test_zero_vibration_at_the_design_mode(hz, zeta, family):
    m = Mode.from_hz(hz, zeta)
    assert v_at(design(family, [m]), m.omega, zeta) < 1e-12


@FAST
@given(freqs, dampings, st.integers(0, 6))
def test_zvdn_derivatives_vanish(hz, zeta, n):
    """ZV-D^n: V and its first n derivatives in omega are zero at the mode (seed 000 eq. (2))."""
    m = Mode.from_hz(hz, zeta)
    s = design("zvdn", [m], derivative_order=n)
    h = 1e-3 * m.omega
    # V ~ c |d omega|^(n+1) near the mode: a relative step of 1e-3 leaves V below ~1e-3^(n+1)
    v = v_at(s, m.omega + h, zeta)
    assert v < 10 * (1e-3) ** (n + 1) * (math.pi * 2) ** (n + 1)


def test_zv_and_zvd_match_the_papers_closed_forms():
    """Seed 002 eqs. (5)-(6) with K = exp(-zeta pi / sqrt(1 - zeta^2))."""
    m = Mode(10.0, 0.3)
    k = math.exp(-0.3 * math.pi / math.sqrt(1 - 0.09))
    td2 = math.pi / (10.0 * math.sqrt(1 - 0.09))
    zv = design("zv", [m])
    np.testing.assert_allclose(zv.amplitudes, [1 / (1 + k), k / (1 + k)], rtol=1e-12)
    np.testing.assert_allclose(zv.times, [0, td2], rtol=1e-12)
    zvd = design("zvd", [m])
    d = 1 + 2 * k + k * k
    np.testing.assert_allclose(zvd.amplitudes, [1 / d, 2 * k / d, k * k / d], rtol=1e-12)
    np.testing.assert_allclose(zvd.times, [0, td2, 2 * td2], rtol=1e-12)


@FAST
@given(freqs, st.floats(min_value=0.0, max_value=0.2), st.floats(min_value=0.01, max_value=0.2))
def test_ei_meets_its_specification(hz, zeta, vtol):
    """EI: V = V_tol at the mode, a local maximum, and V <= V_tol between its two zeros."""
    m = Mode.from_hz(hz, zeta)
    s = design("ei", [m], vibration_tolerance=vtol)
    assert abs(v_at(s, m.omega, zeta) - vtol) < 1e-7
    ratios, v = sensitivity_curve(s.amplitudes, s.times, m.omega, zeta, (0.5, 1.5), 2001)
    centre = int(np.argmin(np.abs(ratios - 1.0)))
    lo = centre - int(np.argmax(v[centre::-1] < 1e-3))  # nearest near-zero below the mode
    hi = centre + int(np.argmax(v[centre:] < 1e-3))
    assert lo < centre < hi
    assert v[lo:hi + 1].max() <= vtol + 1e-7
    # insensitivity: EI keeps V <= 5 % over a wider band than ZVD of about the same duration
    zvd = design("zvd", [m])
    _, vz = sensitivity_curve(zvd.amplitudes, zvd.times, m.omega, zeta, (0.5, 1.5), 2001)
    assert np.sum(v <= max(vtol, 0.05) + 1e-9) >= np.sum(vz <= max(vtol, 0.05))


def test_multi_mode_design_cancels_both_modes():
    m1, m2 = Mode.from_hz(3.0, 0.02), Mode.from_hz(11.0, 0.05)
    s = design("zv", [m1, m2])
    assert len(s) == 4
    assert v_at(s, m1.omega, m1.zeta) < 1e-12 and v_at(s, m2.omega, m2.zeta) < 1e-12


def test_none_passes_the_command():
    s = design("none")
    assert s.amplitudes.tolist() == [1.0] and s.times.tolist() == [0.0]
    assert v_at(s, 7.0, 0.1) == pytest.approx(1.0)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(family="zvd", modes=[]), "needs at least one mode"),
        (dict(family="cubic", modes=[Mode(1, 0)]), "unknown shaper family"),
        (dict(family="custom", amplitudes=[0.5, 0.6], times=[0, 1]), "sum to 1"),
        (dict(family="custom", amplitudes=[0.5, 0.5], times=[0, -1]), "non-decreasing"),
        (dict(family="custom", amplitudes=[0.5, 0.5], times=[0.1, 1]), "t = 0"),
        (dict(family="custom", amplitudes=[0.5, float("nan")], times=[0, 1]), "finite"),
        (dict(family="custom", amplitudes=[0.5, 0.5], times=[0]), "2 amplitudes but 1 times"),
        (dict(family="ei", modes=[Mode(1, 0)], vibration_tolerance=0.9), "vibration_tolerance"),
        (dict(family="zvdn", modes=[Mode(1, 0)], derivative_order=20), "derivative_order"),
    ],
)
def test_invalid_requests_name_the_problem(kwargs, words):
    with pytest.raises(ShaperError, match=words):
        design(**kwargs)


@pytest.mark.parametrize("omega, zeta", [(0.0, 0.1), (-1.0, 0.1), (float("inf"), 0.1), (1.0, 1.0), (1.0, -0.1),
                                         (1.0, float("nan"))])
def test_invalid_modes(omega, zeta):
    with pytest.raises(ShaperError):
        Mode(omega, zeta)


def test_registry_lists_every_family():
    assert {"none", "zv", "zvd", "zvdd", "zvdn", "mzv", "ei", "2hump_ei", "3hump_ei", "si", "custom"} <= set(FAMILIES)


def test_zvdn_order_zero_is_zv():
    m = Mode(5.0, 0.1)
    a, t = zvdn(m, 0)
    zv = design("zv", [m])
    np.testing.assert_allclose(a, zv.amplitudes)
    np.testing.assert_allclose(t, zv.times)
