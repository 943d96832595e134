"""What a calibration writes for the nodes (shaper.yaml, scheduler.yaml: everything they need to start and
work, as wired during the calibration) and what its figures show (series present and visible, legends and
labels matching the data, units), from the matplotlib objects themselves.

The calibration here is built from modes given per pose (no fit): two modes that cross along the elbow, so
that the k-th mode by frequency is not the same physical mode at every pose.
"""

from __future__ import annotations

import math
import pathlib

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
import yaml
from matplotlib.colors import to_rgba

from shaper_nodes.analysis.calibration import (
    WIRING,
    assemble,
    setup_dict,
    wiring_of,
)
from shaper_nodes.analysis.calibration_outputs import scheduler_yaml, shaper_yaml
from shaper_nodes.analysis.calibration_report import (
    RESIDUAL_SERIES,
    modes_figure,
    residual_figure,
    write_outputs,
)
from shaper_nodes.analysis.text import plus_minus_fixed as plus_minus
from shaper_nodes.core.calibration import IdentifySettings, PoseResult
from shaper_nodes.core.calibration.plan import config_from_dict, make_plan
from shaper_nodes.core.identification import ModeFit

CONFIG = pathlib.Path(__file__).resolve().parents[1] / "config" / "calibrate.yaml"
TWO_PI = 2 * math.pi


def default_plan():
    """config/calibrate.yaml's plan (3 x 3 grid over shoulder_lift and elbow)."""
    p = yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"]
    k = len(p["grid"]["joints"])
    gains = p["follow"]["gains"]
    follow = {j: gains[i * k:(i + 1) * k] for i, j in enumerate(p["follow"]["joints"])}
    return make_plan(config_from_dict({"joint_names": p["joint_names"], "limits": p["limits"],
                                       "base_pose": p["base_pose"], "home_pose": p["home_pose"], "grid": p["grid"],
                                       "poses": [], "follow": follow, "excitation": p["excitation"],
                                       "approach": p["approach"]}))


def crossing_modes(shoulder: float, elbow: float) -> list[tuple[float, float]]:
    """A mode rising with the elbow from 8 to 16 Hz and one falling from 14 to 10 Hz: they cross."""
    u = (elbow - 0.5) / 1.9
    s = 1 + 0.05 * (shoulder + 1.57)
    return sorted([(s * (8.0 + 8.0 * u), 0.02), (s * (14.0 - 4.0 * u), 0.04)])


def mode(hz: float, zeta: float) -> ModeFit:
    return ModeFit(TWO_PI * hz, zeta, 0.002 * TWO_PI * hz, 0.05 * zeta, 1.0, "fit")


@pytest.fixture(scope="module")
def calibration():
    plan = default_plan()
    names = list(plan.config.joint_names)
    sl, el = names.index("shoulder_lift_joint"), names.index("elbow_joint")
    results = []
    for s in plan.steps:
        modes = [mode(f, z) for f, z in crossing_modes(s.pose[sl], s.pose[el])]
        results.append(PoseResult(s.index, s.name, s.pose, s.grid_index, modes, [modes]))
    wiring = {"action": "/arm_controller/follow_joint_trajectory", "joint_states": "/robot/joint_states"}
    return assemble(plan, IdentifySettings(), "zv", 0.02, results, wiring)


# --------------------------------------------------------------------------- the parameter files
def test_the_setup_records_the_wiring_and_an_old_setup_without_it_takes_the_defaults():
    plan = default_plan()
    setup = setup_dict(plan, IdentifySettings(), "zv", 0.02, {"action": "/a/follow_joint_trajectory"})
    assert wiring_of(setup) == {**WIRING, "action": "/a/follow_joint_trajectory"}
    del setup["wiring"]
    assert wiring_of(setup) == WIRING
    with pytest.raises(ValueError, match="unknown wiring keys"):
        setup_dict(plan, IdentifySettings(), "zv", 0.02, {"controller": "/x"})


def test_shaper_yaml_names_the_joints_the_controller_the_scheduler_and_the_fallback(calibration):
    cal = calibration
    params = yaml.safe_load(shaper_yaml(cal))["/**"]["ros__parameters"]
    assert params["joint_names"] == list(cal.plan.config.joint_names)
    assert params["action"] == {"controller": "/arm_controller/follow_joint_trajectory", "scheduler": "/scheduler"}
    assert params["topics"] == {"trajectory_out": "/arm_controller/joint_trajectory",
                                "stream_out": "/arm_controller/joint_trajectory"}
    home = cal.results[0]
    assert home.name == "home"
    assert params["shaper"]["family"] == "zv"
    assert params["shaper"]["frequencies_hz"] == pytest.approx([m.hz for m in home.modes], rel=1e-5)
    # without a rule base there is no scheduler to ask
    alone = yaml.safe_load(shaper_yaml(type(cal)(**{**cal.__dict__, "rule_base": None})))["/**"]["ros__parameters"]
    assert "scheduler" not in alone["action"]


def test_scheduler_yaml_reads_the_joint_states_the_calibration_read_and_sends_to_the_shaper_node(calibration):
    params = yaml.safe_load(scheduler_yaml(calibration))["/**"]["ros__parameters"]
    assert params["joint_states"] == "/robot/joint_states"
    assert params["shaper"] == "/shaper"
    assert params["premises"] == ["shoulder_lift_joint", "elbow_joint"]


def test_an_action_not_named_like_a_controllers_leaves_the_topics_at_the_nodes_defaults(calibration):
    cal = type(calibration)(**{**calibration.__dict__, "wiring": {**WIRING, "action": "/robot/move"}})
    params = yaml.safe_load(shaper_yaml(cal))["/**"]["ros__parameters"]
    assert params["action"]["controller"] == "/robot/move" and "topics" not in params


# --------------------------------------------------------------------------- the figures
def _visible(artist) -> bool:
    return artist.get_visible() and (artist.get_alpha() is None or artist.get_alpha() > 0)


def test_modes_vs_pose_draws_every_mode_as_a_point_and_names_every_series(calibration):
    cal = calibration
    names = list(cal.plan.config.joint_names)
    fig = modes_figure(cal)
    axes = np.array(fig.axes).reshape(2, 2)
    for a, joint in enumerate(cal.plan.config.grid_joints):
        other = next(g for g in cal.plan.config.grid_joints if g != joint)
        j, o = names.index(joint), names.index(other)
        freq, damp = axes[0, a], axes[1, a]
        assert freq.get_ylabel() == "natural frequency (Hz)" and damp.get_ylabel() == "damping ratio"
        assert damp.get_xlabel() == f"{joint} (rad)"
        # no line joins two points: the k-th mode by frequency is not one physical mode across poses
        for ax in (freq, damp):
            assert all(line.get_linestyle() == "None" for line in ax.get_lines()), joint
        series = [c for c in freq.containers]
        legend = [t.get_text() for t in freq.get_legend().get_texts()]
        labels = [c.get_label() for c in series]
        assert legend == labels and len(set(labels)) == len(labels) == 3  # one per value of the other joint
        colours = set()
        points = []
        span = np.ptp([r.positions[j] for r in cal.results if r.grid_index is not None])
        for c in series:
            line = c.lines[0]
            assert _visible(line) and line.get_markersize() > 0 and line.get_marker() not in ("", "None")
            colours.add(to_rgba(line.get_color()))
            value = float(c.get_label().split()[1])  # "<other joint> <value> rad"
            assert c.get_label() == f"{other} {value:+.2f} rad"
            rows = [r for r in cal.results if r.grid_index is not None and abs(r.positions[o] - value) < 5e-3]
            want = sorted((r.positions[j], m.hz) for r in rows for m in r.modes)
            got = sorted(zip(line.get_xdata(), line.get_ydata(), strict=True))
            assert len(got) == len(want)
            for (x, y), (xw, yw) in zip(got, want, strict=True):  # x jittered by at most 1 % of the axis
                assert abs(x - xw) <= 0.01 * span and y == pytest.approx(yw)
            points += got
        assert len(colours) == len(series)
        assert len(points) == sum(len(r.modes) for r in cal.results if r.grid_index is not None)


def test_residual_figure_compares_like_with_like_and_every_series_is_visible(calibration):
    cal = calibration
    fig = residual_figure(cal)
    nominal, worst = fig.axes
    assert nominal.get_ylabel() == "predicted residual vibration (%)"
    for ax, series in ((nominal, RESIDUAL_SERIES[:2]), (worst, RESIDUAL_SERIES[2:])):
        lines = ax.get_lines()[:2]
        assert [line.get_label() for line in lines] == [label for _, label in series]
        assert [t.get_text() for t in ax.get_legend().get_texts()] == [label for _, label in series]
        assert ("nominal" in series[0][1]) == ("nominal" in series[1][1])  # like with like
        lo, hi = ax.get_ylim()
        for line, (key, _) in zip(lines, series, strict=True):
            y = np.asarray(line.get_ydata(), dtype=float)
            np.testing.assert_allclose(y, [100 * row[key] for row in cal.residuals])
            assert _visible(line) and line.get_markersize() > 0 and line.get_marker() not in ("", "None")
            assert np.all((y > lo) & (y < hi)), (key, lo, hi)  # zeros too: inside the axes, not on the frame
        assert [t.get_text() for t in ax.get_xticklabels()] == [r.name for r in cal.results]
    # the scheduled shaper is designed on each pose's own modes: nominally zero there, and drawn
    assert max(row["scheduled"] for row in cal.residuals) < 1e-9


def test_write_outputs_draws_the_figures_and_the_report_table_has_every_series(calibration, tmp_path):
    written = {p.name for p in write_outputs(tmp_path, calibration)}
    assert {"modes_vs_pose.png", "residual.png", "shaper.yaml", "scheduler.yaml"} <= written
    table = (tmp_path / "report.md").read_text()
    assert "fixed, worst 2 sigma %" in table and "scheduled, worst 2 sigma %" in table


def test_an_uncertainty_is_printed_to_two_significant_digits_never_as_zero():
    assert plus_minus(9.955, 0.00041, 3) == "9.95500 +- 0.00041"
    assert plus_minus(9.955, 0.012, 3) == "9.955 +- 0.012"
    assert plus_minus(0.0332, 0.00012, 4) == "0.03320 +- 0.00012"
    assert plus_minus(9.955, 0.0, 3) == "9.955 (uncertainty unknown)"
