"""The loop_design CLI: what it prints for the papers' cases, JSON, plots, and bad input (exit 2)."""

import json
import math

import pytest

from shaper_nodes.cli.loop_design import main
from shaper_nodes.core.closed_loop.time_delay import exact_step_response, growth_rate, step_response_with_horizon


def run(capsys, *argv):
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_tdf_interval(capsys):
    status, out, _ = run(capsys, "tdf-interval", "--omega-a", "3", "--delay", repr(math.pi / 9), "--json")
    assert status == 0
    doc = json.loads(out)
    assert doc["stable_interval"] == pytest.approx([3.0, 5.04551], abs=1e-5)
    assert doc["gains"] == pytest.approx([1.0, -1.0, 1.0])
    status, out, _ = run(capsys, "tdf-interval", "--omega-a", "3", "--delay", repr(math.pi / 9))
    assert "stable for 3 <= w_R <= 5.04551 rad/s" in out


def test_tdf_interval_with_an_overshoot_limit(capsys):
    """Seed 001's case with a 20 % overshoot spec: the interval shrinks from [3, 5.05] to [3, x] with the
    paper's w_R = 3.9 inside and its w_R = 4 outside; x is where the exact overshoot is 20 %."""
    t = repr(math.pi / 9)
    status, out, _ = run(capsys, "tdf-interval", "--omega-a", "3", "--delay", t, "--max-overshoot", "20", "--json")
    assert status == 0
    doc = json.loads(out)
    lim = doc["overshoot_limited"]
    assert lim["max_overshoot_percent"] == 20
    ((lo, hi),) = lim["intervals"]
    assert lo == 3.0 and 3.9 < hi < 4.0 and lim["edges"] == [["stability", "overshoot"]]
    assert exact_step_response(3.0, math.pi / 9, hi).overshoot == pytest.approx(0.20, abs=1e-8)
    assert all(p["class"] in ("meets", "violates") for p in lim["scan"])
    assert doc["stable_interval"] == pytest.approx([3.0, 5.04551], abs=1e-5)  # unchanged
    # the text of the same interval, scanned on 3 of the 41 points above (the default grid's first, middle and
    # last): 7 s of CPU instead of 40, and its edge, refined to 1e-9 rad/s all the same, prints the same 6 digits
    status, out, _ = run(capsys, "tdf-interval", "--omega-a", "3", "--delay", t, "--max-overshoot", "20", "--grid",
                         "3")
    assert f"overshoot <= 20 % (exact step response) for 3 <= w_R <= {hi:.6g} rad/s" in out
    assert "stable for 3 <= w_R <= 5.04551 rad/s" in out
    # without the option nothing is added
    status, out, _ = run(capsys, "tdf-interval", "--omega-a", "3", "--delay", t, "--json")
    assert "overshoot_limited" not in json.loads(out)


def test_tdf_step(capsys):
    t = repr(math.pi / 9)
    status, out, _ = run(capsys, "tdf-step", "--omega-a", "3", "--delay", t, "--omega-r", "4", "--json")
    assert status == 0
    doc = json.loads(out)
    ref = step_response_with_horizon(3.0, math.pi / 9, 4.0)
    assert doc["in_stable_interval"] and doc["sampled_stable"] and doc["growth_rate"] < 0
    assert doc["overshoot_percent"] == pytest.approx(100 * ref.overshoot, abs=1e-9)
    assert doc["overshoot_percent"] > 20.0  # the paper's "within 20 %" does not hold for the exact loop
    assert doc["peak_time"] == pytest.approx(ref.peak_time, abs=1e-9)
    assert doc["settling_time"] == pytest.approx(ref.settling_time, abs=1e-9)
    assert doc["peak_captured"] and doc["settled"] and doc["band"] == 0.02
    status, out, _ = run(capsys, "tdf-step", "--omega-a", "3", "--delay", t, "--omega-r", "4")
    assert "w_R = 4 rad/s: stable" in out
    assert f"overshoot {100 * ref.overshoot:.4f} % at t = {ref.peak_time:.5g} s" in out
    assert f"settling time (2 % band) {ref.settling_time:.5g} s" in out
    # a wider band settles earlier
    status, out, _ = run(capsys, "tdf-step", "--omega-a", "3", "--delay", t, "--omega-r", "4", "--band", "0.05",
                         "--json")
    assert json.loads(out)["settling_time"] < ref.settling_time
    # Fig. 9: below w_A the loop is unstable by both checks and the response does not settle
    status, out, _ = run(capsys, "tdf-step", "--omega-a", "3", "--delay", t, "--omega-r", "2.9")
    assert status == 0
    assert "w_R = 2.9 rad/s: UNSTABLE" in out and "OUTSIDE the stable interval" in out and "GROWS" in out
    assert "does NOT settle into the 2 % band" in out
    # the matched plant: the shaped step, no overshoot
    status, out, _ = run(capsys, "tdf-step", "--omega-a", "3", "--delay", t, "--omega-r", "3")
    assert "no overshoot" in out


def test_tdf_select(capsys):
    status, out, _ = run(capsys, "tdf-select", "--omega-r", "3", "--delay", "0.5", "--json")
    assert status == 0
    (r,) = json.loads(out)["ranges"]
    assert (r["k"], r["omega_a_low"], r["omega_a_high"]) == (1, 0.0, 3.0)
    # the suggested w_A keeps the plant inside its stable interval, by the independent check too
    wa = r["best_omega_a"]
    assert r["stable_omega_a"][0] <= wa <= r["stable_omega_a"][1] <= 3.0
    assert wa < 3.0 < r["best_upper_bound"]
    assert growth_rate(wa, 0.5, 3.0, 100) < 0
    assert growth_rate(0.95 * r["stable_omega_a"][0], 0.5, 3.0, 100) > 0  # below the range: unstable


def test_qft_table_names_where_the_spec_fails(capsys):
    status, out, _ = run(capsys, "qft-table", "--json")
    assert status == 0
    doc = json.loads(out)
    assert doc["design"] == "ffb" and doc["gain"] == 166.7
    assert doc["failing_frequencies"] == [120.0, 150.0]
    assert all(m["stable"] for m in doc["margins"])
    status, out, _ = run(capsys, "qft-table", "--design", "fb")
    assert "FAILS at 120, 150, 200, 500 rad/s" in out
    status, out, _ = run(capsys, "qft-table", "--delta", "0.3")
    assert "meets |M - Y/R| <= 0.3 for every corner plant" in out


@pytest.mark.parametrize("argv", [("tdf-plot", "--figure", "4"), ("tdf-plot", "--figure", "6"),
                                  ("qft-plot", "--figure", "6"), ("qft-plot", "--figure", "8")])
def test_plots_are_written(capsys, tmp_path, argv):
    out = tmp_path / "fig.png"
    status, _, _ = run(capsys, *argv, "--out", str(out))
    assert status == 0 and out.stat().st_size > 10000


@pytest.mark.parametrize("argv, words", [
    (("tdf-interval", "--omega-a", "nan", "--delay", "1"), "--omega-a"),
    (("tdf-interval", "--omega-a", "3", "--delay", repr(2 * math.pi / 3)), "multiple of 2 pi"),
    (("tdf-select", "--omega-r", "-3", "--delay", "1"), "--omega-r"),
    (("tdf-interval", "--omega-a", "3", "--delay", "0.3", "--max-overshoot", "-20"), "--max-overshoot"),
    (("tdf-interval", "--omega-a", "3", "--delay", "0.3", "--max-overshoot", "20", "--grid", "1"), "grid"),
    (("tdf-step", "--omega-a", "3", "--delay", "0.3", "--omega-r", "inf"), "--omega-r"),
    (("tdf-step", "--omega-a", "3", "--delay", "0.3", "--omega-r", "4", "--band", "1.5"), "settling band"),
    (("tdf-step", "--omega-a", "3", "--delay", "0.3"), "--omega-r"),
    (("qft-table", "--design", "pid"), "--design"),
    (("qft-table", "--frequencies", "10", "inf"), "--frequencies"),
    (("qft-plot", "--figure", "6", "--out", "/nonexistent/dir/x.png"), "cannot write"),
])
def test_bad_input_exits_2_naming_the_problem(capsys, argv, words):
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert words in err
