"""The loop_design CLI: what it prints for the papers' cases, JSON, plots, and bad input (exit 2)."""

import json
import math

import pytest

from shaper_nodes.core.time_delay import growth_rate
from shaper_nodes.loop_design_cli import main


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
    (("qft-table", "--design", "pid"), "--design"),
    (("qft-table", "--frequencies", "10", "inf"), "--frequencies"),
    (("qft-plot", "--figure", "6", "--out", "/nonexistent/dir/x.png"), "cannot write"),
])
def test_bad_input_exits_2_naming_the_problem(capsys, argv, words):
    status, _, err = run(capsys, *argv)
    assert status == 2
    assert words in err
