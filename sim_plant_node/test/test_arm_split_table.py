"""The arm demo's servo/vibration table and the corrected goal's verdict over DDS (clients/arm_split.py), ROS-free."""

from __future__ import annotations

import math

from sim_plant_node.arm.metrics import noise_floor
from sim_plant_node.clients import arm_split


def row(case: str, move: str, residual: float, servo: float, vibration: float) -> dict:
    return {"case": case, "move": move, "residual_rms": residual, "servo_rms": servo, "vibration_rms": vibration,
            "linear_rms": 1.01 * residual, "own_rms": residual, "split_s": 0.002}


def rows(learned: dict[str, tuple[float, float]], residual: float = 0.02) -> list[dict]:
    moves = ["1. home->rotated", "5. home->pick"]
    out = [row("scheduled", m, residual, 0.004, 0.01) for m in moves]
    return out + [row("scheduled_list_moves", m, residual, *learned[m.split(". ")[1]]) for m in moves]


def test_the_servo_part_is_judged_where_the_reproduction_reached_it_and_the_vibration_part_everywhere():
    text = "\n".join(arm_split.table(rows({"home->rotated": (0.0008, 0.0100), "home->pick": (0.002, 0.0101)}),
                                     ["none", "scheduled", "scheduled_list_moves"], 0.01))
    assert "| 1. home->rotated | 0.00400 | 0.00080 | 20.0 | 0.0100 | 0.0100 | 100.0 | yes |" in text
    assert "| 5. home->pick | 0.00400 | 0.00200 | 50.0 | 0.0100 | 0.0101 | 101.0 | vibration only |" in text
    assert ": met. Beyond reach by the reproduction, reported: servo part home->pick 50.0 %." in text
    assert "within 1.00 % on every move of every case's last cycle (4 moves)" in text
    text = "\n".join(arm_split.table(rows({"home->rotated": (0.0012, 0.0103), "home->pick": (0.001, 0.01)}),
                                     ["scheduled", "scheduled_list_moves"], 0.0))
    assert "not met (vibration part above 101 %: home->rotated 103.0 %; servo part above 25 %: home->rotated 30.0 %)" \
        in text


def test_moves_at_the_noise_floor_are_not_judged_and_no_table_without_the_schedule():
    floor = noise_floor(0.01).threshold
    assert math.isclose(floor, 0.01777, abs_tol=5e-6) and noise_floor(0.0).threshold == 0.0
    quiet = rows({"home->rotated": (0.004, 0.02), "home->pick": (0.004, 0.02)}, residual=floor)
    text = "\n".join(arm_split.table(quiet, ["scheduled", "scheduled_list_moves"], 0.01))
    assert "no (at the floor)" in text and "not judged (no move above the noise floor)" in text
    assert arm_split.table([r for r in quiet if r["case"] != "scheduled"], ["scheduled_list_moves"], 0.01) == []
    assert arm_split.columns(None)["servo_rms"] != arm_split.columns(None)["servo_rms"]  # NaN: no report
