# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""reproductions/arm_mrilc.py, fast: MRILC per move on the ROS-free arm, one move, a few cycles.

The schedule here is a stand-in (a ZV on the linearised arm's lowest mode at the goal pose, no calibration
run), which leaves a large residual on the move home->rotated (its second mode rings): the learned
correction must take it to 25 % of the schedule's within a few cycles, its servo part (the position loop's
transient) too, with every limit held exactly.
"""

from __future__ import annotations

import math

import pytest

from reproductions.arm_mrilc import CASES, main, mrilc_case
from sim_plant_node.arm.dynamics import ArmModel

CYCLES = 4
KEYS = {"case", "move", "cycle", "residual_rms", "peak_mm", "settle_s", "move_settle_s", "speed_factor"}


@pytest.fixture(scope="module")
def rows():
    from reproductions.arm_mrilc import modal_zv

    return mrilc_case(CYCLES, 0.0, modal_zv(ArmModel()), moves=1)


def test_rows_follow_the_issue_schema(rows):
    assert [r["case"] for r in rows] == [CASES[0]] + [CASES[1]] * CYCLES
    assert all(set(r) >= KEYS and r["move"] == "home->rotated" and r["speed_factor"] == 1.0 for r in rows)
    assert [r["cycle"] for r in rows[1:]] == list(range(1, CYCLES + 1))
    assert all(math.isfinite(r[k]) for r in rows for k in KEYS - {"case", "move"})


def test_the_learned_correction_reduces_the_residual_inside_the_limits(rows):
    scheduled = rows[0]["residual_rms"]
    learned = [r["residual_rms"] for r in rows[1:]]
    assert learned[0] == pytest.approx(scheduled, rel=1e-9)  # cycle 1 runs without a correction: the schedule
    print("residual / the schedule's, per cycle:", [round(x / scheduled, 4) for x in learned],
          "servo part:", [round(r["servo_rms"] / rows[0]["servo_rms"], 4) for r in rows[1:]])
    # issue 31's goal, here within 4 cycles (measured 0.15), and the position loop's transient (the servo part)
    # learned away with the vibration (measured 0.32 of the schedule's)
    assert learned[-1] < 0.25 * scheduled
    assert rows[-1]["servo_rms"] < 0.5 * rows[0]["servo_rms"]
    # the points sent hold every limit exactly (clipped into them where the correction meets one)
    assert all(r["limit_excess"] == 0.0 for r in rows[1:])
    assert 0 < max(r["max_correction_rad"] for r in rows[1:]) < 0.01


def test_bad_options_are_refused(capsys):
    with pytest.raises(SystemExit):
        main(["--cycles", "0"])
    assert "--cycles must be >= 1" in capsys.readouterr().err
