"""The arm's stepping path with fewer numpy calls gives what it gave before: the elastic arm's step on one state
array bit for bit, the controller's trajectory samples (all three polynomials in one product) to float rounding."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sim_plant_node.arm.dynamics import ArmModel, ElasticArm
from sim_plant_node.arm.plant import ArmPlant
from sim_plant_node.controller.jtc import JointTrajectoryController, RawPoint, Tolerances
from sim_plant_node.controller.splines import Point, Trajectory

HOME = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])


def _reference_step(arm: ElasticArm, x: np.ndarray, xd: np.ndarray, xdd: np.ndarray, drive: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The step as it was written before the state became one array (three arrays, concatenated per step)."""
    n = arm.n
    y = arm._map @ np.concatenate([x, xd, xdd])
    link = pin.aba(arm._pin_model, arm._pin_data, x[:n], xd[:n], y[:n] + arm._ratio * drive)
    xdd = np.concatenate([link, arm._inv_a22 * (y[n:2 * n] + drive) + arm._ratio * link])
    return y[2 * n:4 * n] + arm._hh4 * xdd, y[4 * n:] + arm._h2 * xdd, xdd


def test_the_step_on_one_state_array_is_the_step_before_bit_for_bit():
    model = ArmModel()
    arm = ElasticArm(model, 1e-3, HOME)
    x, xd, xdd = arm.x.copy(), arm.xd.copy(), arm.xdd.copy()
    for k in range(300):
        r = HOME + 0.2 * np.sin(0.01 * k)
        rd = np.full(6, 0.2 * 0.01 * np.cos(0.01 * k) / 1e-3)
        arm.step(r, rd)
        drive = model.kp * r + model.gravity(r) + model.kd * rd
        x, xd, xdd = _reference_step(arm, x, xd, xdd, drive)
        assert np.array_equal(arm.x, x) and np.array_equal(arm.xd, xd) and np.array_equal(arm.xdd, xdd), k


def _reference_imu(arm: ElasticArm, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The flange IMU as it was written before the step kept its views and scratch arrays."""
    mdl = arm.model
    pin.forwardKinematics(mdl.model, mdl.data, q, v, a)
    frame = pin.updateFramePlacement(mdl.model, mdl.data, mdl.tool)
    acc = pin.getFrameClassicalAcceleration(mdl.model, mdl.data, mdl.tool, pin.ReferenceFrame.LOCAL).linear
    rate = pin.getFrameVelocity(mdl.model, mdl.data, mdl.tool, pin.ReferenceFrame.LOCAL).angular
    return acc + 9.81 * frame.rotation[2], np.array(rate)


def test_a_period_of_the_arm_plant_is_the_steps_before_bit_for_bit():
    # ArmPlant takes the period's setpoint once (ElasticArm.hold) and advances its physics steps on views and scratch
    # arrays: states, IMU samples and torques are those of the step written out per physics step, to the last bit
    plant = ArmPlant(500.0, substeps=2)
    plant.reset(HOME)
    arm, model, n = plant.arm, plant.arm.model, plant.n
    x, xd, xdd = arm.x.copy(), arm.xd.copy(), arm.xdd.copy()
    for k in range(300):
        r = HOME + 0.2 * np.sin(0.01 * min(k, 200))  # (from 200 on the setpoint holds: gravity at it is kept)
        rd = None if k % 7 == 3 or k >= 200 else np.full(6, 0.2 * 0.01 * np.cos(0.01 * k) / 2e-3)
        plant.step(r, velocity=None if rd is None else rd.copy())
        drive = model.kp * r + model.gravity(r) + (0.0 if rd is None else model.kd * rd)
        for j in range(2):
            x, xd, xdd = _reference_step(arm, x, xd, xdd, drive)
            f, w = _reference_imu(arm, x[:n], xd[:n], xdd[:n])
            _, f_got, w_got = plant.imu_samples[j]
            assert np.array_equal(f_got, f) and np.array_equal(w_got, w), (k, j)
        assert np.array_equal(arm.x, x) and np.array_equal(arm.xd, xd) and np.array_equal(arm.xdd, xdd), k
        torque = model.kp * (r - x[n:]) + model.kd * ((0.0 if rd is None else rd) - xd[n:]) + model.gravity(r)
        assert np.array_equal(plant.effort, torque), k


def test_the_state_views_write_through_and_read_back():
    arm = ElasticArm(ArmModel(), 1e-3, HOME)
    arm.x, arm.xd, arm.xdd = np.arange(12.0), np.arange(12.0) + 12, np.arange(12.0) + 24
    assert np.array_equal(arm._state, np.arange(36.0))
    assert np.array_equal(arm.q, np.arange(6.0)) and np.array_equal(arm.motor_velocity, np.arange(18.0, 24.0))


@pytest.mark.parametrize("fields", ["positions", "velocities", "accelerations"])
def test_stacked_samples_equal_the_samples_to_rounding(fields):
    rng = np.random.default_rng(3)

    def point(t: float) -> Point:
        v = rng.normal(size=4) if fields != "positions" else None
        a = rng.normal(size=4) if fields == "accelerations" else None
        return Point(t, rng.normal(size=4), v, a)

    start = Point(-0.1, rng.normal(size=4), np.zeros(4), np.zeros(4) if fields == "accelerations" else None)
    traj = Trajectory(start, [point(0.3), point(0.8), point(1.7)])
    for t in np.linspace(-0.3, 2.0, 461):
        got = traj.sample_stacked(float(t))
        want = np.concatenate(traj.sample(float(t)))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_the_controller_commands_the_next_sample_and_reports_the_present_one():
    names = tuple(f"j{i}" for i in range(6))
    ctl = JointTrajectoryController(names, 2e-3, Tolerances(np.full(6, 1.0), np.full(6, 1.0)), HOME)
    ctl.accept(list(names), [RawPoint(0.5, (HOME + 0.1).tolist(), [0.05] * 6, [0.0] * 6),
                             RawPoint(1.0, (HOME + 0.2).tolist(), [0.0] * 6, [0.0] * 6)], 0.0)
    position, velocity = HOME.copy(), np.zeros(6)
    for k in range(600):
        if ctl.holding and k:  # the goal reached: the last point is held, nothing sampled
            break
        t = 2e-3 * k
        ctl.update(t, position, velocity)
        assert ctl.trajectory is not None
        now, nxt = ctl.trajectory.sample(t), ctl.trajectory.sample(t + 2e-3)
        for got, want in zip(ctl.desired, now, strict=True):
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(ctl.command, nxt[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(ctl.command_velocity, nxt[1], rtol=1e-12, atol=1e-12)
        position, velocity = ctl.command.copy(), ctl.command_velocity.copy()
    assert ctl.holding and np.allclose(ctl.command, HOME + 0.2)
