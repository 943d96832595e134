"""Shaper families (mzv, multi-hump EI, SI), their registry metadata, and the design CLI.

The assertions are the families' defining properties (the physics), checked on the sensitivity
curve computed independently of how each design was found.
"""

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from shaper_nodes.cli.shaper_design import main
from shaper_nodes.core.shaping.families import FAMILIES, design, family_info, family_properties
from shaper_nodes.core.shaping.types import Mode, ShaperError
from shaper_nodes.core.shaping.vibration import percentage_vibration

FAST = settings(max_examples=40, deadline=None)
TOLERANCE_FAMILIES = ("ei", "2hump_ei", "3hump_ei", "si")


def v_at(shaper, omega, zeta):
    return float(percentage_vibration(shaper.amplitudes, shaper.times, omega, zeta))


def band_max(shaper, lo, hi, zeta, points=20001):
    """Largest V over [lo, hi] rad/s: a dense grid, then each local maximum refined."""
    w = np.linspace(lo, hi, points)
    v = percentage_vibration(shaper.amplitudes, shaper.times, w, zeta)
    worst = float(max(v[0], v[-1]))
    for i in np.flatnonzero((v[1:-1] >= v[:-2]) & (v[1:-1] >= v[2:])) + 1:
        res = minimize_scalar(lambda x: -v_at(shaper, x, zeta), bounds=(w[i - 1], w[i + 1]), method="bounded",
                              options={"xatol": 1e-13 * hi})
        worst = max(worst, float(v[i]), -float(res.fun))
    return worst


# --- every family ------------------------------------------------------------------------------


@FAST
@given(st.floats(0.5, 200.0), st.floats(0.0, 0.3),
       st.sampled_from(["zv", "zvd", "zvdd", "zvdn", "mzv", "ei", "2hump_ei", "3hump_ei", "si"]),
       st.integers(0, 6))
def test_every_family_sums_to_one_and_meets_its_design_condition(hz, zeta, family, n):
    m = Mode.from_hz(hz, zeta)
    s = design(family, [m], derivative_order=n)
    assert math.isclose(float(s.amplitudes.sum()), 1.0, abs_tol=1e-12)
    assert np.all(s.amplitudes > 0.0) and s.times[0] == 0.0 and np.all(np.diff(s.times) > 0.0)
    v = v_at(s, m.omega, zeta)
    if family in TOLERANCE_FAMILIES:
        assert v <= 0.05 + 1e-9
    else:
        assert v < 1e-9


def test_parameters_are_recorded():
    m = Mode.from_hz(5.0, 0.05)
    assert design("zv", [m]).params == {}
    assert design("zvdn", [m], derivative_order=3).params == {"derivative_order": 3}
    for fam in ("ei", "2hump_ei", "3hump_ei"):
        assert design(fam, [m], vibration_tolerance=0.03).params == {"vibration_tolerance": 0.03}
    assert design("si", [m], vibration_tolerance=0.03, insensitivity=0.5).params == {
        "vibration_tolerance": 0.03, "insensitivity": 0.5}


@pytest.mark.parametrize("zeta", [0.0, 0.02, 0.05, 0.1, 0.2])
@pytest.mark.parametrize("hz", [1.0, 12.5])
def test_insensitivity_ranks_zv_zvd_ei_2hump_3hump(hz, zeta):
    """The 5 % insensitivity grows with each step of robustness (and with the duration)."""
    m = Mode.from_hz(hz, zeta)
    widths = [family_properties(f, m).insensitivity_5pct for f in ("zv", "zvd", "ei", "2hump_ei", "3hump_ei")]
    assert all(a < b for a, b in itertools.pairwise(widths)), widths
    # MZV sits between ZV and ZVD in duration and in robustness
    zv, mz, zvd = (family_properties(f, m) for f in ("zv", "mzv", "zvd"))
    assert zv.duration < mz.duration < zvd.duration
    assert zv.insensitivity_5pct < mz.insensitivity_5pct < zvd.insensitivity_5pct


# --- MZV -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("zeta", [0.0, 0.1, 0.3])
def test_mzv_impulses_a_third_of_a_period_apart(zeta):
    m = Mode(7.0, zeta)
    s = design("mzv", [m])
    np.testing.assert_allclose(s.times, np.arange(3) * m.damped_period / 3.0, rtol=1e-12)
    # each impulse's residual vector has the same length: amplitude ratio exp(-zeta omega T)
    ratio = math.exp(-zeta * m.omega * m.damped_period / 3.0)
    np.testing.assert_allclose(s.amplitudes[1:] / s.amplitudes[:-1], ratio, rtol=1e-12)
    if zeta == 0.0:
        np.testing.assert_allclose(s.amplitudes, 1.0 / 3.0, rtol=1e-12)


# --- multi-hump EI -------------------------------------------------------------------------------


def hump_structure(s, m, vtol):
    """Local maxima and minima of V inside the contiguous band where V <= V_tol around the mode."""
    w = np.linspace(0.2 * m.omega, 3.0 * m.omega, 56001)
    v = percentage_vibration(s.amplitudes, s.times, w, m.zeta)
    centre = int(np.argmin(np.abs(w - m.omega)))
    inside = v <= vtol * (1 + 1e-6)
    assert inside[centre]
    outside = np.flatnonzero(~inside)
    lo = int(outside[outside < centre].max(initial=0))
    hi = int(outside[outside > centre].min(initial=w.size - 1))  # damped: V may stay low above
    maxima, minima = [], []
    for i in range(lo + 1, hi - 1):
        if v[i] >= v[i - 1] and v[i] >= v[i + 1]:
            res = minimize_scalar(lambda x: -v_at(s, x, m.zeta), bounds=(w[i - 1], w[i + 1]), method="bounded",
                                  options={"xatol": 1e-12 * m.omega})
            maxima.append((float(res.x), -float(res.fun)))
        elif v[i] <= v[i - 1] and v[i] <= v[i + 1]:
            res = minimize_scalar(lambda x: v_at(s, x, m.zeta), bounds=(w[i - 1], w[i + 1]), method="bounded",
                                  options={"xatol": 1e-12 * m.omega})
            minima.append((float(res.x), float(res.fun)))
    return maxima, minima


@pytest.mark.parametrize("vtol", [0.02, 0.05, 0.1])
@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.1, 0.2])
@pytest.mark.parametrize("family, humps", [("ei", 1), ("2hump_ei", 2), ("3hump_ei", 3)])
def test_multi_hump_ei_has_its_humps_and_zeros(family, humps, zeta, vtol):
    """n humps at V = V_tol (local maxima), n + 1 zeros between and around them, alternating."""
    m = Mode.from_hz(4.0, zeta)
    s = design(family, [m], vibration_tolerance=vtol)
    assert len(s) == humps + 2
    maxima, minima = hump_structure(s, m, vtol)
    assert len(maxima) == humps and len(minima) == humps + 1
    for _, v in maxima:
        assert v == pytest.approx(vtol, abs=1e-8)
    for _, v in minima:
        assert v < 1e-6
    points = sorted([(w, "max") for w, _ in maxima] + [(w, "min") for w, _ in minima])
    assert [kind for _, kind in points] == ["min", "max"] * humps + ["min"]
    # the design frequency is the middle hump (odd n) or the middle zero (even n)
    middle = points[humps][0]
    assert middle == pytest.approx(m.omega, rel=1e-6)


@pytest.mark.parametrize("vtol", [0.01, 0.05, 0.15])
def test_undamped_multi_hump_ei_matches_the_closed_forms(vtol):
    """Undamped: impulses half a period apart with the literature's closed-form amplitudes."""
    m = Mode(2.0 * math.pi, 0.0)
    two = design("2hump_ei", [m], vibration_tolerance=vtol)
    x = (vtol**2 * (math.sqrt(1 - vtol**2) + 1)) ** (1 / 3)
    a1 = (3 * x * x + 2 * x + 3 * vtol**2) / (16 * x)
    np.testing.assert_allclose(two.amplitudes, [a1, 0.5 - a1, 0.5 - a1, a1], atol=1e-9)
    np.testing.assert_allclose(two.times, [0.0, 0.5, 1.0, 1.5], atol=1e-9)
    three = design("3hump_ei", [m], vibration_tolerance=vtol)
    b1 = (1 + 3 * vtol + 2 * math.sqrt(2 * vtol * (vtol + 1))) / 16
    b2 = (1 - vtol) / 4
    np.testing.assert_allclose(three.amplitudes, [b1, b2, 1 - 2 * (b1 + b2), b2, b1], atol=1e-9)
    np.testing.assert_allclose(three.times, [0.0, 0.5, 1.0, 1.5, 2.0], atol=1e-9)


def test_heavily_damped_multi_hump_ei_is_refused_with_a_reason():
    with pytest.raises(ShaperError, match="no 3-hump EI shaper"):
        design("3hump_ei", [Mode(3.0, 0.6)])


# --- SI ------------------------------------------------------------------------------------------


@settings(max_examples=15, deadline=None)
@given(st.floats(0.5, 200.0), st.floats(0.0, 0.3), st.sampled_from([0.01, 0.05, 0.1]),
       st.sampled_from([0.1, 0.3, 0.4, 0.8]))
def test_si_keeps_v_below_the_tolerance_over_the_band(hz, zeta, vtol, ins):
    m = Mode.from_hz(hz, zeta)
    s = design("si", [m], vibration_tolerance=vtol, insensitivity=ins)
    assert band_max(s, m.omega * (1 - ins / 2), m.omega * (1 + ins / 2), zeta) <= vtol + 1e-9


def symmetric_half_width(shaper, m, level, points=40001):
    """Largest h (grid-conservative) with V <= level on [omega (1 - h), omega (1 + h)]."""
    r = np.linspace(0.0, 1.0, points)
    below = percentage_vibration(shaper.amplitudes, shaper.times, m.omega * (1 - r), m.zeta) <= level
    above = percentage_vibration(shaper.amplitudes, shaper.times, m.omega * (1 + r), m.zeta) <= level
    ok = below & above
    return float(r[int(np.argmin(ok)) - 1])


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.15])
@pytest.mark.parametrize("n", [1, 2, 3])
def test_si_is_no_longer_than_zvdn_of_the_same_insensitivity(n, zeta):
    """ZV-D^n is one feasible sequence for the band it covers, so the shortest is no longer."""
    m = Mode.from_hz(10.0, zeta)
    zvdn = design("zvdn", [m], derivative_order=n)
    half = symmetric_half_width(zvdn, m, 0.05)
    si = design("si", [m], vibration_tolerance=0.05, insensitivity=2 * half)
    assert si.duration <= zvdn.duration * (1 + 1e-9)
    assert band_max(si, m.omega * (1 - half), m.omega * (1 + half), zeta) <= 0.05 + 1e-9


def test_multi_mode_si_covers_both_bands_and_beats_the_convolution():
    m1, m2 = Mode.from_hz(4.0, 0.02), Mode.from_hz(10.8, 0.05)
    s = design("si", [m1, m2], vibration_tolerance=0.05, insensitivity=0.3)
    for m in (m1, m2):
        assert band_max(s, m.omega * 0.85, m.omega * 1.15, m.zeta) <= 0.05 + 1e-9
    # the convolution of the single-mode designs is feasible for the joint problem (V multiplies)
    conv_duration = sum(design("si", [m], vibration_tolerance=0.05, insensitivity=0.3).duration for m in (m1, m2))
    assert s.duration <= conv_duration
    assert s.params == {"vibration_tolerance": 0.05, "insensitivity": 0.3}


def test_si_does_not_depend_on_the_order_of_the_modes():
    m1, m2 = Mode.from_hz(3.0, 0.0), Mode.from_hz(7.0, 0.1)
    a, b = design("si", [m1, m2]), design("si", [m2, m1])
    np.testing.assert_allclose(a.amplitudes, b.amplitudes)
    np.testing.assert_allclose(a.times, b.times)


@pytest.mark.parametrize("family", ["zv", "zvd", "zvdd", "mzv", "ei", "2hump_ei", "3hump_ei"])
def test_multi_mode_convolution_cancels_every_mode(family):
    modes = [Mode.from_hz(2.0, 0.01), Mode.from_hz(6.5, 0.05), Mode.from_hz(17.0, 0.1)]
    s = design(family, modes)
    single = len(design(family, modes[:1]))
    assert len(s) <= single**3
    for m in modes:
        v = v_at(s, m.omega, m.zeta)
        # V of a convolution is the product of the V's: zero where any factor is zero
        assert v <= (0.05 + 1e-9 if family in ("ei", "3hump_ei") else 1e-9)


# --- validation ------------------------------------------------------------------------------------


M = [Mode(10.0, 0.05)]


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(family="ei", vibration_tolerance=float("nan")), "vibration_tolerance must be finite"),
        (dict(family="2hump_ei", vibration_tolerance=0.0), "vibration_tolerance must be in"),
        (dict(family="3hump_ei", vibration_tolerance=0.5), "vibration_tolerance must be in"),
        (dict(family="si", vibration_tolerance=-0.1), "vibration_tolerance must be in"),
        (dict(family="si", vibration_tolerance="abc"), "vibration_tolerance must be a number"),
        (dict(family="si", insensitivity=0.0), "insensitivity must be in"),
        (dict(family="si", insensitivity=2.0), "insensitivity must be in"),
        (dict(family="si", insensitivity=float("inf")), "insensitivity must be finite"),
        (dict(family="zvdn", derivative_order=1.5), "derivative_order must be an integer"),
        (dict(family="zvdn", derivative_order=-1), "derivative_order must be an integer"),
        (dict(family="zvdn", derivative_order=True), "derivative_order must be an integer"),
        (dict(family="mzv", modes=[(10.0, 0.1)]), "modes must be Mode objects"),
        (dict(family="quintic"), "unknown shaper family"),
        (dict(family="si", modes=[]), "needs at least one mode"),
    ],
)
def test_invalid_parameters_name_the_problem(kwargs, words):
    kwargs = {"modes": M, **kwargs}
    with pytest.raises(ShaperError, match=words):
        design(**kwargs)


def test_parameters_a_family_does_not_use_are_ignored():
    s = design("zv", M, vibration_tolerance=float("nan"), insensitivity=-1.0, derivative_order=99)
    assert len(s) == 2 and s.params == {}


# --- registry and properties ---------------------------------------------------------------------


def test_registry_describes_every_family():
    assert list(FAMILIES) == ["none", "zv", "zvd", "zvdd", "zvdn", "mzv", "ei", "2hump_ei", "3hump_ei", "si",
                              "custom"]
    for name, description in FAMILIES.items():
        info = family_info(name)
        assert info.description == description and info.impulses and info.damping
        if name not in ("none", "custom"):
            assert "damping ratio" in info.damping
    assert family_info("si").joint and not family_info("zvd").joint
    m = Mode(5.0, 0.1)
    for name in ("zv", "zvd", "zvdd", "mzv", "ei", "2hump_ei", "3hump_ei"):
        assert str(len(design(name, [m]))) == family_info(name).impulses


def test_family_properties():
    m = Mode.from_hz(10.0, 0.0)
    p = family_properties("zv", m)
    assert p.family == "zv" and p.impulses == 2
    assert p.duration == pytest.approx(0.05)
    assert p.v_at_design < 1e-12
    assert p.insensitivity_5pct == pytest.approx(4 * math.asin(0.05) / math.pi, abs=1e-9)
    assert "damping ratio" in p.damping_assumed
    e = family_properties("ei", m, vibration_tolerance=0.05)
    assert e.v_at_design == pytest.approx(0.05, abs=1e-9) and e.insensitivity_5pct > p.insensitivity_5pct
    n = family_properties("none", m)
    assert n.impulses == 1 and n.v_at_design == pytest.approx(1.0) and n.insensitivity_5pct == 0.0


# --- conversions -----------------------------------------------------------------------------------


def test_message_round_trip_carries_tolerance_and_insensitivity():
    msgs = pytest.importorskip("shaper_msgs.msg")
    if not hasattr(msgs, "Shaper") or not hasattr(msgs.Shaper(), "insensitivity"):
        pytest.skip("shaper_msgs with Shaper.insensitivity is not built")
    from shaper_nodes.ros.conversions import shaper_from_msg, shaper_to_msg

    s = design("si", [Mode(20.0, 0.05)], vibration_tolerance=0.03, insensitivity=0.5)
    msg = shaper_to_msg(s, "test", 1)
    assert msg.vibration_tolerance == 0.03 and msg.insensitivity == 0.5
    request = msgs.Shaper(family="si", design_modes=msg.design_modes, vibration_tolerance=0.03, insensitivity=0.5)
    back = shaper_from_msg(request)
    np.testing.assert_allclose(back.amplitudes, s.amplitudes)
    default = shaper_from_msg(msgs.Shaper(family="si", design_modes=msg.design_modes))
    assert default.params == {"vibration_tolerance": 0.05, "insensitivity": 0.4}
    zv = shaper_to_msg(design("zv", [Mode(20.0, 0.05)]), "test", 2)
    assert zv.vibration_tolerance == 0.0 and zv.insensitivity == 0.0
    with pytest.raises(ShaperError, match="insensitivity"):
        shaper_from_msg(msgs.Shaper(family="si", design_modes=msg.design_modes, insensitivity=-0.2))


# --- CLI -------------------------------------------------------------------------------------------


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


def test_cli_list(capsys):
    code, out, _ = run(capsys, "list")
    assert code == 0
    for name in FAMILIES:
        assert name in out
    code, out, _ = run(capsys, "list", "--json")
    doc = json.loads(out)
    assert code == 0 and [f["family"] for f in doc["families"]] == list(FAMILIES)
    assert {"description", "impulses", "damping_assumed"} <= set(doc["families"][0])


def test_cli_show_with_fir(capsys):
    code, out, _ = run(capsys, "show", "zvd", "--frequency", "8", "--damping", "0.05", "--rate", "500")
    assert code == 0 and "duration" in out and "FIR at 500 Hz" in out
    code, out, _ = run(capsys, "show", "zvd", "-f", "8", "-z", "0.05", "--rate", "500", "--json")
    doc = json.loads(out)
    m = Mode.from_hz(8.0, 0.05)
    s = design("zvd", [m])
    np.testing.assert_allclose([i["amplitude"] for i in doc["impulses"]], s.amplitudes)
    assert doc["duration_s"] == pytest.approx(s.duration)
    assert doc["modes"][0]["v_at_design"] < 1e-9
    taps = doc["fir"]["taps"]
    assert sum(t["weight"] for t in taps) == pytest.approx(1.0)
    assert all(t["time_s"] == pytest.approx(t["index"] / 500.0) for t in taps)
    assert doc["fir"]["v_at_design"][0] < (m.omega / 500.0) ** 2  # split: second order in omega Ts
    assert doc["fir"]["v_at_design"][0] > 1e-6
    code, out, _ = run(capsys, "show", "zvd", "-f", "8", "-z", "0.05", "--rate", "500", "--discretization", "exact",
                       "--json")
    doc = json.loads(out)
    assert code == 0 and doc["fir"]["discretization"] == "exact" and doc["fir"]["v_at_design"][0] < 1e-12


def test_cli_show_multi_mode_si_and_custom(capsys):
    code, out, _ = run(capsys, "show", "si", "-f", "5", "-f", "13", "-z", "0.02", "-z", "0.1",
                       "--tolerance", "0.04", "--insensitivity", "0.3", "--json")
    doc = json.loads(out)
    assert code == 0 and len(doc["modes"]) == 2 and doc["params"]["insensitivity"] == 0.3
    assert all(mm["v_at_design"] <= 0.04 + 1e-9 for mm in doc["modes"])
    code, out, _ = run(capsys, "show", "custom", "-f", "5", "-z", "0", "--amplitudes", "0.5", "0.5",
                       "--times", "0", "0.1", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["modes"][0]["v_at_design"] < 1e-12  # ZV at 5 Hz by hand


def test_cli_compare(capsys):
    code, out, _ = run(capsys, "compare", "-f", "10", "-z", "0.02")
    assert code == 0 and "insensitivity" in out and "3hump_ei" in out
    code, out, _ = run(capsys, "compare", "-f", "10", "-z", "0.02", "--families", "zv", "zvd", "ei", "--json")
    doc = json.loads(out)
    rows = {r["family"]: r for r in doc["families"]}
    assert set(rows) == {"zv", "zvd", "ei"}
    assert rows["zvd"]["duration_periods"] == pytest.approx(1.0)
    assert rows["zv"]["insensitivity_5pct"] < rows["zvd"]["insensitivity_5pct"] < rows["ei"]["insensitivity_5pct"]


def test_cli_plot_writes_a_png(capsys, tmp_path):
    out_file = tmp_path / "sens.png"
    code, out, _ = run(capsys, "plot", "-f", "10", "-z", "0.02", "--families", "zv", "ei", "si", "--out",
                       str(out_file))
    assert code == 0 and str(out_file) in out
    data = out_file.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


@pytest.mark.parametrize(
    "argv, words",
    [
        (["show", "cubic", "-f", "10", "-z", "0"], "unknown shaper family 'cubic'"),
        (["show", "zv", "-f", "nan", "-z", "0"], "--frequency (Hz) must be finite and > 0"),
        (["show", "zv", "-f", "-3", "-z", "0"], "--frequency (Hz) must be finite and > 0"),
        (["show", "zv", "-f", "3", "-z", "1.5"], "damping ratio must be in"),
        (["show", "zv", "-f", "3", "-z", "nan"], "--damping must be finite"),
        (["show", "zv", "-f", "3", "-f", "4", "-z", "0", "-z", "0.1", "-z", "0.2"], "one --damping for all modes"),
        (["show", "custom", "-f", "3", "-z", "0"], "needs --amplitudes and --times"),
        (["show", "ei", "-f", "3", "-z", "0", "--tolerance", "0.9"], "vibration_tolerance must be in"),
        (["show", "zv", "-f", "3", "-z", "0", "--rate", "0"], "--rate (Hz) must be finite and > 0"),
        (["compare", "-f", "3", "-z", "0", "--insensitivity", "-1"], "insensitivity must be in"),
        (["compare", "-f", "3", "-z", "0", "--families", "zv", "bogus"], "unknown shaper family 'bogus'"),
        (["plot", "-f", "3", "-z", "0"], "--out"),
        ([], "required"),
    ],
)
def test_cli_bad_input_exits_2_with_a_clear_message(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    assert words in err and err.startswith("shaper_design")
