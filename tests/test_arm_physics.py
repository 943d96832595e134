"""The residual's servo and vibration parts (reproductions.residual_split) and the rigid arm (ROS-free)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from reproductions import arm_learning, arm_mrilc
from reproductions.residual_split import SERVO_ZETA, LinearArm, linear_arm, residual_parts, split_response
from sim_plant_node.arm.dynamics import ArmModel, rigid_model
from sim_plant_node.arm.modal import modes
from sim_plant_node.arm.task import HOME


def oscillators(*modes: tuple[float, float]) -> LinearArm:
    """Uncoupled oscillators (hz, zeta), output the acceleration of each on its own axis."""
    n = len(modes)
    a = np.zeros((2 * n, 2 * n))
    c = np.zeros((3, 2 * n))
    for i, (hz, zeta) in enumerate(modes):
        w = 2 * math.pi * hz
        a[i, n + i] = 1.0
        a[n + i, i], a[n + i, n + i] = -w * w, -2 * zeta * w
        c[i] = a[n + i]
    return LinearArm(a, c, np.eye(n), np.zeros(n))


def test_the_two_parts_add_up_to_the_free_response():
    arm = oscillators((10.0, 0.03), (30.0, 0.7), (20.0, 0.08))
    z0 = np.array([1e-3, -2e-3, 5e-4, 0.01, 0.0, -0.02])
    t = np.linspace(0.0, 1.0, 301)
    servo, vib = split_response(arm, z0, t)
    whole = np.array([arm.c @ expm(arm.a * x) @ z0 for x in t])
    np.testing.assert_allclose(servo + vib, whole, atol=1e-9 * np.abs(whole).max())


def test_a_lightly_damped_mode_is_vibration_and_a_heavily_damped_one_is_servo():
    arm = oscillators((10.0, 0.03), (30.0, 0.7))
    t = np.linspace(0.0, 0.5, 201)
    servo, vib = split_response(arm, np.array([1e-3, 0.0, 0.0, 0.0]), t)  # only the 10 Hz mode moves
    assert np.abs(servo).max() < 1e-12 < np.abs(vib).max()
    servo, vib = split_response(arm, np.array([0.0, 1e-3, 0.0, 0.0]), t)  # only the 30 Hz, zeta 0.7 one
    assert np.abs(vib).max() < 1e-12 < np.abs(servo).max()
    assert 0.03 < SERVO_ZETA < 0.7


def test_the_parts_reproduce_the_simulated_residual_of_a_move():
    """One scheduled move on the offline arm: the linear free response from the state at the commanded end is the
    measured residual (within 3 %), and the schedule leaves the arm vibrating less than unshaped."""
    from reproductions.arm_calibration import goal_waypoints
    from shaper_nodes.core.shaping.vibration import residual_vibration
    from sim_plant_node.arm.metrics import motion_end
    from sim_plant_node.arm.offline import OfflineArm
    from sim_plant_node.arm.task import cycle_moves

    move = cycle_moves()[0]
    shaper = arm_mrilc.modal_zv(ArmModel())(move.positions[-1])
    found = {}
    for name, sh in (("unshaped", None), ("shaped", shaper)):
        arm = OfflineArm(HOME, 500.0, states=True)
        times, pos, vel, acc = goal_waypoints(move, sh, 500.0, 1.5)
        start = arm.run(times, pos, vel, acc)
        ct, cq = arm.record.window("cmd", start, start + times[-1])
        it, imu = arm.record.window("imu", start, start + times[-1])
        end = motion_end(ct, cq)
        k = int(np.argmin(np.abs(np.asarray(arm.record.state_t) - end)))
        assert arm.record.state_t[k] == pytest.approx(end, abs=1e-9)
        parts = residual_parts(arm.plant.model, cq[-1], arm.record.state[k], it, end)
        measured = residual_vibration(it, imu, end, end + 1.0, remove_mean=True).rms
        assert parts.linear_rms == pytest.approx(measured, rel=0.03)
        found[name] = parts
    assert found["shaped"].vibration_rms < 0.5 * found["unshaped"].vibration_rms  # a ZV on the lowest mode only


def test_the_rigid_arm_has_no_lightly_damped_mode_and_the_threshold_parts_the_flexible_arms():
    """The flexible arm: its three joint modes damped 3-8 %, the loop's 25 % and more; the rigid arm: none below."""
    flexible = [m.zeta for m in modes(ArmModel(), HOME)]
    assert sum(z < SERVO_ZETA for z in flexible) == 3
    assert min(z for z in flexible if z >= SERVO_ZETA) > 2 * SERVO_ZETA > 2 * max(z for z in flexible if z < SERVO_ZETA)
    assert all(m.zeta >= SERVO_ZETA for m in modes(rigid_model(), HOME))
    assert linear_arm(rigid_model(), HOME).a.shape == (24, 24)


@pytest.mark.parametrize("factor", [0.5, float("nan"), float("inf"), "10"])
def test_a_bad_stiffness_factor_is_refused_naming_it(factor):
    with pytest.raises(ValueError, match="factor must be finite and >= 1"):
        rigid_model(factor)  # type: ignore[arg-type]


def _row(case: str, move: str, cycle: int, total: float, servo: float, vib: float, settle: float = 1.0,
         **extra: object) -> dict:
    return {"case": case, "move": move, "cycle": cycle, "residual_rms": total, "late_rms": total,
            "servo_rms": servo, "vibration_rms": vib, "linear_rms": total, "peak_mm": 0.001, "settle_s": 0.1,
            "move_settle_s": settle, "speed_factor": 1.0, **extra}


def test_the_vibration_parts_25_percent_is_a_record_and_the_corrected_goal_is_on_the_servo_part():
    rows = [_row("scheduled", m, 1, 0.01, 0.008, 0.004) for m in ("a", "b")]
    # a: the vibration part down to 20 %, total down to 85 % (the servo part stays); b: 30 %
    rows += [_row("scheduled_list", "a", 1, 0.012, 0.008, 0.004), _row("scheduled_list", "a", 2, 0.0085, 0.008, 0.0008),
             _row("scheduled_list", "b", 1, 0.012, 0.008, 0.004), _row("scheduled_list", "b", 2, 0.009, 0.008, 0.0012)]
    text = "\n".join(arm_learning.checks(rows, 0.0))
    assert "a 20 %; b 30 %" in text
    # the goal once, the corrected goal once, each with its verdict; the vibration part's 25 % a record
    assert text.count("**Issue's goal**") == 1 and text.count("**Corrected goal**") == 1
    assert "not met (above 25 %: a 85 %, b 90 %)" in text
    assert "not met (servo part above 25 %: a, b)" in text
    assert "What the time forbids (a record, not a goal)" in text and "above it on b 30 %." in text
    only_a = "\n".join(arm_learning.checks([r for r in rows if r["move"] == "a"], 0.0))
    assert "at or below it on every move judged." in only_a
    physics = "\n".join(arm_learning.physics([r for r in rows if r["move"] == "a"], 0.0))
    assert "a 80 %" in physics  # the schedule's servo part against its residual
    # with noise, a move whose scheduled residual as measured is not above F + 2 s is not judged: no verdict
    noisy = "\n".join(arm_learning.checks([r for r in rows if r["move"] == "a"], 0.01))
    assert "a 85 % (late 85 %) [at the floor]" in noisy
    assert "not judged (no move above the noise floor)" in noisy and "): met" not in noisy


def test_the_mrilc_summary_judges_the_residual_and_its_vibration_part():
    base = {"residual_rms": 0.01, "move_settle_s": 1.0, "speed_factor": 1.0, "max_correction_rad": 1e-4,
            "max_correction_rad_s": 1e-3, "max_correction_rad_s2": 0.1, "limit_excess": 0.0}
    rows = [{**base, "case": arm_mrilc.CASES[0], "move": "a", "cycle": 1, "residual_rms_noise_free": 0.01,
             "servo_rms": 0.008, "vibration_rms": 0.004}]
    rows += [{**base, "case": arm_mrilc.CASES[1], "move": "a", "cycle": c, "residual_rms_noise_free": res,
              "servo_rms": 0.008 * res / 0.01, "vibration_rms": v}
             for c, res, v in ((1, 0.01, 0.004), (2, 0.002, 0.0009))]
    text = arm_mrilc.summary(rows)
    assert "| 0.225 (0.225) |" in text  # the vibration ratio at the last cycle (and its best)
    assert "**Goal**" in text and "no move slower): met." in text
    assert "**Its vibration part** at cycle 2 at most 25 % of the schedule's on every move: met." in text
    # a residual above 25 % of the schedule's, or a limit not held exactly, is not met
    rows[-1]["residual_rms_noise_free"] = 0.003
    assert "not met (above 25 %: a 30 %)" in arm_mrilc.summary(rows)
    rows[-1]["residual_rms_noise_free"], rows[-1]["limit_excess"] = 0.002, 1e-18
    assert "no move slower): not met." in arm_mrilc.summary(rows)


def test_the_factor_over_the_schedule_is_judged_on_the_whole_residual_and_by_the_time_the_goal_allows():
    rows = [_row("scheduled", m, 1, 0.01, 0.008, 0.004) for m in ("a", "b")]
    # a: the servo part down to 10 %, the vibration part kept; b: the servo part only down to 50 %
    rows += [_row("scheduled_list_factor", "a", 1, 0.01, 0.008, 0.004),
             _row("scheduled_list_factor", "a", 2, 0.0045, 0.0008, 0.004),
             _row("scheduled_list_factor", "b", 1, 0.01, 0.008, 0.004),
             _row("scheduled_list_factor", "b", 2, 0.007, 0.004, 0.004)]
    text = "\n".join(arm_learning.checks(rows, 0.0))
    assert "**Issue's goal**" in text and "not met (above 25 %: a 45 %, b 70 %)" in text  # the 25 %: neither
    assert "Servo part against the schedule's (the moves judged): a 10 %; b 50 %." in text
    assert "**Corrected goal** (the one that counts" in text and "not met (servo part above 25 %: b)" in text
    only_a = "\n".join(arm_learning.checks([r for r in rows if r["move"] == "a"], 0.0))
    assert "never worse than the schedule after cycle 1): met." in only_a
    # a cycle slower than the schedule by more than a sample fails it
    slow = [r for r in rows if r["move"] == "a"] + [_row("scheduled_list_factor", "a", 3, 0.0045, 0.0008, 0.004,
                                                         settle=1.01)]
    assert "never worse than the schedule after cycle 1): not met" in "\n".join(arm_learning.checks(slow, 0.0))
    # with noise: the moves judged are those whose scheduled residual as measured is above F + 2 s (0.01777 m/s^2
    # at 0.01), the ratios on the arm's own residual; below it no move is judged and no verdict is given
    assert "not judged (no move above the noise floor)" in "\n".join(arm_learning.checks(rows, 0.01))
    loud = [{**r, "residual_rms": 0.018 if r["move"] == "a" else 0.0177} for r in rows]
    noisy = "\n".join(arm_learning.checks(loud, 0.01))
    assert "0.01777 m/s^2: a;" in noisy and "b 100 % (late" in noisy and "[at the floor]" in noisy
    assert "not met (above 25 %: a 45 %)" in noisy  # the arm's own residual, 0.0045 against 0.01
    assert "Servo part against the schedule's (the moves judged): a 10 %." in noisy
    assert "never worse than the schedule after cycle 1): met." in noisy
