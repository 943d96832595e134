"""tool_deviation.png of the arm demo (clients/arm_demo.py ``plot``), checked on its matplotlib objects: every
case drawn and visible even where two cases have the same trace, the legend naming the cases, the settling
band drawn at its value, units on the axes."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.colors import to_rgba

from sim_plant_node.arm.metrics import SETTLE_TOLERANCE
from sim_plant_node.clients.arm_demo import plot

CASES = ["none", "fixed", "scheduled"]
MOVES = ["1. home->rotated", "2. rotated->place"]


def traces():
    t = np.linspace(-1.0, 1.5, 400)
    ring = np.exp(-3 * np.clip(t, 0, None)) * np.abs(np.sin(60 * t))
    out = {}
    for m, move in enumerate(MOVES):
        out[("none", move)] = (t, 1.0 * ring + 1e-3)
        out[("fixed", move)] = (t, 0.1 * ring + 1e-3)
        # the schedule applies the fixed shaper at the home reach (move 1): the very same trace there
        out[("scheduled", move)] = (t, (0.1 if m == 0 else 0.03) * ring + 1e-3)
    return out


def test_every_case_is_visible_the_legend_names_them_and_the_band_is_drawn(tmp_path):
    data = traces()
    fig = plot(tmp_path / "tool_deviation.png", data, CASES, MOVES)
    assert (tmp_path / "tool_deviation.png").stat().st_size > 0
    band = SETTLE_TOLERANCE * 1e3
    for ax, move in zip(fig.axes, MOVES, strict=True):
        lines = {line.get_label(): line for line in ax.get_lines()}
        assert sorted(lines) == sorted(CASES)
        for case, line in lines.items():
            np.testing.assert_array_equal(line.get_ydata(), data[(case, move)][1])
            assert line.get_visible() and line.get_linewidth() > 0
        # two cases with one trace: distinguishable (colour and style), the one drawn first the wider
        fixed, scheduled = lines["fixed"], lines["scheduled"]
        assert to_rgba(fixed.get_color()) != to_rgba(scheduled.get_color())
        assert fixed.get_linestyle() != scheduled.get_linestyle()
        assert fixed.get_linewidth() > scheduled.get_linewidth() and scheduled.get_zorder() > fixed.get_zorder()
        same = np.array_equal(data[("fixed", move)][1], data[("scheduled", move)][1])
        assert ("scheduled = fixed" in ax.get_title()) == same, ax.get_title()
        # the settling band, 0.05 mm, in the units of the axis
        (patch,) = [p for p in ax.patches if p.get_label().startswith("settling band")]
        ys = patch.get_path().transformed(patch.get_patch_transform()).vertices[:, 1]
        assert patch.get_label() == f"settling band ({band:g} mm)" and band == 0.05
        np.testing.assert_allclose([ys.min(), ys.max()], [0.0, band])
        assert ax.get_ylabel() == "tool dev. (mm)"
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend == ["settling band (0.05 mm)", *CASES]
    assert "(s)" in fig.axes[-1].get_xlabel()
