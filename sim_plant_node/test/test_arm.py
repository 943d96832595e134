"""The six-axis arm: its URDF from the published figures, its dynamics, its modes and its payload."""

import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

from shaper_nodes.core.identification import identify
from sim_plant_node.arm.description import DH_A, DH_D, LINK_MASSES, PAYLOAD_MASS, ArmSpec, urdf
from sim_plant_node.arm.dynamics import GRAVITY, ArmModel, ElasticArm
from sim_plant_node.arm.modal import lowest, mode_map, modes
from sim_plant_node.controller.splines import Point, Trajectory

HOME = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
#: three poses from folded to stretched (elbow angle), the far ones at the ends of the reach
POSES = {"near": [0.0, -1.2, 2.4, -2.77, -1.57, 0.0], "home": HOME.tolist(), "far": [0.0, -1.9, 0.5, -0.17, -1.57, 0.0]}


@pytest.fixture(scope="module")
def model():
    return ArmModel()


def test_urdf_has_the_published_kinematics_and_masses(model):
    """At zero angles the UR5e's flange sits at (a2 + a3, -(d4 + d6), d1 - d5) by its DH table."""
    expected = np.array([DH_A[1] + DH_A[2], -(DH_D[3] + DH_D[5]), DH_D[0] - DH_D[4]])
    np.testing.assert_allclose(model.tool_position(np.zeros(6)), expected, atol=1e-9)
    total = sum(inertia.mass for inertia in model.model.inertias)
    assert total == pytest.approx(sum(LINK_MASSES) + PAYLOAD_MASS)
    assert model.model.nq == model.model.nv == 6
    assert pin.buildModelFromXML(urdf(ArmSpec(payload_mass=0.0))).nv == 6


def test_at_rest_the_imu_reads_gravity_and_nothing_moves(model):
    arm = ElasticArm(model, 1e-3, HOME)
    start = arm.x.copy()
    for _ in range(500):
        arm.step(HOME)
    f, w = arm.imu()
    assert np.linalg.norm(f) == pytest.approx(GRAVITY, rel=1e-6)
    np.testing.assert_allclose(w, 0.0, atol=1e-9)
    np.testing.assert_allclose(arm.x, start, atol=1e-9)
    # the motors hold the setpoint; the links sag under gravity by K^-1 g
    np.testing.assert_allclose(arm.motor_position, HOME, atol=1e-4)
    np.testing.assert_allclose(model.stiffness * (arm.motor_position - arm.q), model.gravity(arm.q), rtol=1e-6,
                               atol=1e-9)


def test_lowest_mode_moves_with_the_reach_by_more_than_30_percent(model):
    hz = mode_map(model, HOME, (1, 2), np.linspace(-math.pi, 0.0, 4), np.linspace(-2.6, 2.6, 9))
    assert hz.max() / hz.min() > 1.3
    assert hz.min() > 3.0 and hz.max() < 20.0  # where arms of this size have their lowest modes


@pytest.mark.parametrize("pose", POSES)
def test_free_decay_identified_from_the_simulation_agrees_with_modal_analysis(model, pose):
    """A small step of the setpoint; the flange IMU's free decay identified by the suite's fit."""
    q = np.array(POSES[pose])
    expected = lowest(model, q)
    arm = ElasticArm(model, 1e-3, q)
    target = q + np.array([0.0, 0.004, 0.008, 0.0, 0.0, 0.0])
    times, accel = [], []
    for _ in range(4000):
        arm.step(target)
        times.append(arm.time)
        accel.append(arm.imu()[0])
    t = np.array(times)
    window = t > 0.3  # the faster, better damped modes have died out
    fits = identify(t[window], np.array(accel)[window], max_modes=3)
    fit = min(fits, key=lambda f: abs(f.omega - expected.omega))
    assert fit.omega == pytest.approx(expected.omega, rel=0.02)
    assert fit.zeta == pytest.approx(expected.zeta, rel=0.20)


def test_modes_are_sorted_and_lightly_damped_at_the_bottom(model):
    ms = modes(model, HOME)
    assert [m.omega for m in ms] == sorted(m.omega for m in ms)
    assert 0.01 < ms[0].zeta < 0.1
    assert np.max(np.abs(ms[0].link_shape)) == pytest.approx(1.0)


def _point(t, p, v=None, a=None):
    arr = lambda x: None if x is None else np.asarray(x, dtype=float)  # noqa: E731
    return Point(t, arr(p), arr(v), arr(a))


@pytest.mark.parametrize("fields", ["p", "pv", "pva"])
def test_segments_meet_their_points(fields):
    """Every spline passes through the points with the fields given (linear, cubic, quintic)."""
    pts = [_point(1.0, [1.0], [0.5], [0.0]), _point(2.5, [2.0], [0.0], [-1.0]), _point(3.0, [2.0], [0.0], [0.0])]
    pts = [Point(p.time, p.positions, p.velocities if "v" in fields else None,
                 p.accelerations if "a" in fields else None) for p in pts]
    traj = Trajectory(_point(0.0, [0.0], [0.0], [0.0]), pts)
    for p in pts:
        pos, vel, acc = traj.sample(p.time - 1e-9)
        assert pos == pytest.approx(p.positions, abs=1e-6)
        if p.velocities is not None:
            assert vel == pytest.approx(p.velocities, abs=1e-5)
        if p.accelerations is not None:
            assert acc == pytest.approx(p.accelerations, abs=1e-4)
    if fields == "p":  # linear: constant slope between points
        assert traj.sample(1.5)[1] == pytest.approx([1.0 / 1.5])
    assert traj.sample(10.0)[0] == pytest.approx([2.0])


def test_a_payload_set_at_run_time_is_the_arm_built_with_that_payload():
    """set_payload changes the flange body in place: mass matrix, gravity, its derivative and the modes are
    those of the arm whose URDF has that payload, at every pose (to the URDF's nine significant digits); back
    to the old payload gives the old arm."""
    arm, built = ArmModel(), ArmModel(ArmSpec(payload_mass=4.5, payload_offset=0.12))
    q = np.array(POSES["far"]) + 0.1
    old = arm.mass(q), arm.gravity(q)
    arm.set_payload(4.5, 0.12)
    assert arm.payload == (4.5, 0.12)
    for pose in (q, HOME):
        np.testing.assert_allclose(arm.mass(pose), built.mass(pose), rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(arm.nonlinear(pose, np.ones(6)), built.nonlinear(pose, np.ones(6)), rtol=1e-8,
                                   atol=1e-8)
        np.testing.assert_allclose(arm.gravity_stiffness(pose), built.gravity_stiffness(pose), rtol=1e-8, atol=1e-8)
    assert sum(i.mass for i in arm.model.inertias) == pytest.approx(sum(LINK_MASSES) + 4.5)
    assert lowest(arm, HOME).hz == pytest.approx(lowest(built, HOME).hz, rel=1e-8)
    arm.set_payload(PAYLOAD_MASS, 0.08)
    np.testing.assert_allclose(arm.mass(q), old[0], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(arm.gravity(q), old[1], atol=1e-9)
    arm.set_payload(0.0)  # none: the bare flange
    assert sum(i.mass for i in arm.model.inertias) == pytest.approx(sum(LINK_MASSES))


def test_a_heavier_payload_lowers_every_pose_s_lowest_mode_and_adds_its_weight_to_the_gravity_load():
    """Physics: more mass at the tool, lower modes (the stiffness is the same); the static torque at the
    shoulder grows by the added weight times its horizontal distance from the shoulder_lift axis."""
    arm = ArmModel()
    masses = (0.0, 1.0, 2.0, 3.5, 5.0)
    for pose in POSES.values():
        hz = []
        for m in masses:
            arm.set_payload(m)
            hz.append(lowest(arm, np.array(pose)).hz)
        assert all(b < a for a, b in itertools.pairwise(hz)), (pose, hz)
    q = HOME.copy()
    arm.set_payload(2.0)
    g2 = arm.gravity(q)
    arm.set_payload(5.0)
    g5 = arm.gravity(q)
    # the payload's centre (0.08 m along the flange's z) and the shoulder_lift axis (through the shoulder), base frame
    pin.framesForwardKinematics(arm.model, arm.data, q)
    centre = arm.data.oMf[arm.tool].act(np.array([0.0, 0.0, 0.08]))
    axis = arm.data.oMi[2]
    lever = np.cross(axis.rotation[:, 2], centre - axis.translation)  # torque per unit force along -z ...
    expected = float(np.dot(lever, np.array([0.0, 0.0, -GRAVITY * 3.0])))
    assert g5[1] - g2[1] == pytest.approx(-expected, rel=1e-9)


def test_a_payload_out_of_range_is_refused_and_changes_nothing():
    arm = ArmModel()
    before = arm.mass(HOME)
    for mass, offset in ((-0.1, 0.08), (math.nan, 0.08), (25.0, 0.08), (1.0, -0.01), (1.0, math.inf)):
        with pytest.raises(ValueError, match="payload"):
            arm.set_payload(mass, offset)
    assert arm.payload == (PAYLOAD_MASS, 0.08)
    np.testing.assert_allclose(arm.mass(HOME), before)


def test_after_a_payload_change_the_arm_settles_to_its_new_rest_and_rings_at_the_new_mode():
    """The state is kept: holding the same setpoint, the arm leaves its old rest, swings, and comes to the
    rest of the heavier arm; the swing is the new lowest mode, not the old one."""
    model = ArmModel()
    arm = ElasticArm(model, 1e-3, HOME)
    model.set_payload(4.5)
    arm.model_changed()
    times, accel = [], []
    for _ in range(6000):
        arm.step(HOME)
        times.append(arm.time)
        accel.append(arm.imu()[0])
    q_rest, theta_rest = model.rest(HOME)
    np.testing.assert_allclose(arm.q, q_rest, atol=2e-6)
    np.testing.assert_allclose(arm.motor_position, theta_rest, atol=2e-6)
    t = np.array(times)
    fits = identify(t[t > 0.3], np.array(accel)[t > 0.3], max_modes=3)
    new, old = lowest(model, HOME), lowest(ArmModel(), HOME)
    fit = min(fits, key=lambda f: abs(f.omega - new.omega))
    assert fit.omega == pytest.approx(new.omega, rel=0.02)
    assert abs(fit.omega - old.omega) > 0.1 * old.omega


class DenseReference:
    """The trapezoidal rule on x = (q, theta) as ElasticArm integrated it before its Schur-complement
    step: the full 12 x 12 matrices from crba and nonLinearEffects, one dense solve per step."""

    def __init__(self, model: ArmModel, h: float, pose: np.ndarray) -> None:
        n, self.model, self.h = model.n, model, h
        k, d = np.diag(model.stiffness), np.diag(model.damping * np.ones(n))
        self.kb = np.block([[k, -k], [-k, k + np.diag(model.kp)]])
        self.cb = np.block([[d, -d], [-d, d + np.diag(model.kd + model.motor_friction)]])
        self.mb = np.zeros((2 * n, 2 * n))
        self.mb[n:, n:] = np.diag(model.motor_inertia)
        q, theta = model.rest(pose)
        self.x, self.xd, self.xdd = np.concatenate([q, theta]), np.zeros(2 * n), np.zeros(2 * n)

    def step(self, r: np.ndarray, rd: np.ndarray) -> None:
        mdl, n, h = self.model, self.model.n, self.h
        q, v = self.x[:n], self.xd[:n]
        self.mb[:n, :n] = mdl.mass(q)
        f = np.concatenate([-mdl.nonlinear(q, v), mdl.kp * r + mdl.kd * rd + mdl.gravity(r)])
        x_pred = self.x + h * self.xd + h * h / 4 * self.xdd
        xd_pred = self.xd + h / 2 * self.xdd
        a = self.mb + h / 2 * self.cb + h * h / 4 * self.kb
        self.xdd = np.linalg.solve(a, f - self.cb @ xd_pred - self.kb @ x_pred)
        self.x = x_pred + h * h / 4 * self.xdd
        self.xd = xd_pred + h / 2 * self.xdd


def test_the_schur_complement_step_equals_the_dense_solve_over_a_move(model):
    """3 s at 1 kHz: a fast 0.5 s move of every joint from HOME (setpoint and velocity feedforward, as
    the trajectory controller gives them), then the free swing. The step through Pinocchio's aba on
    the Schur complement agrees with the dense 12 x 12 solve to 1e-9 of each signal's range (rounding
    differs in the last bits; nothing else may), and so do the motor torques."""
    h, steps, move = 1e-3, 3000, 500
    arm, ref = ElasticArm(model, h, HOME), DenseReference(model, h, HOME)
    delta = np.array([0.4, -0.3, 0.5, 0.6, -0.5, 0.8])
    xs, refs, torques, ref_torques = [], [], [], []
    for i in range(steps):
        s = min((i + 1) / move, 1.0)
        r = HOME + delta * (3 * s**2 - 2 * s**3)
        rd = delta * (6 * s - 6 * s**2) / (move * h) if i < move else np.zeros(6)
        arm.step(r, rd)
        ref.step(r, rd)
        xs.append(np.concatenate([arm.x, arm.xd, arm.xdd]))
        refs.append(np.concatenate([ref.x, ref.xd, ref.xdd]))
        torques.append(arm.torque.copy())
        ref_torques.append(model.kp * (r - ref.x[6:]) + model.kd * (rd - ref.xd[6:]) + model.gravity(r))
    xs, refs = np.array(xs), np.array(refs)
    scale = np.ptp(refs, axis=0) + np.abs(refs).max(axis=0)
    assert np.max(np.abs(xs - refs) / scale) < 1e-9
    assert np.ptp(refs[:, 6:12], axis=0).min() > 0.1  # it did move
    t, t_ref = np.array(torques), np.array(ref_torques)
    assert np.max(np.abs(t - t_ref) / (np.ptp(t_ref, axis=0) + np.abs(t_ref).max(axis=0))) < 1e-9


def test_the_modes_as_simulated_are_unchanged_by_the_schur_complement_step(model):
    """simulated_modes linearises the one-step map by central differences; with the same differences
    the dense solve's map gives the same frequencies and damping ratios. The two maps differ only in
    rounding, which the differences amplify by 1 / eps (the gap shrinks tenfold from eps 1e-5 to
    1e-4): with eps 1e-4 it measured 3e-8 in frequency and 4e-7 in damping (relative), against 1e-6
    and 1e-5 allowed here, while the estimate itself moves by 1e-4 and 1e-3 between eps 1e-7
    (simulated_modes' default) and 1e-5, whichever step computes it."""
    from sim_plant_node.arm.modal import simulated_modes

    eps = 1e-4
    got = simulated_modes(model, HOME, 1e-3, max_damping=0.3, eps=eps)
    expected = simulated_modes(model, HOME, 1e-3, max_damping=0.3, eps=eps, simulator=DenseReference)
    assert len(got) == len(expected) >= 3
    got, expected = np.array(got), np.array(expected)
    np.testing.assert_allclose(got[:, 0], expected[:, 0], rtol=1e-6)
    np.testing.assert_allclose(got[:, 1], expected[:, 1], rtol=1e-5)


def test_the_plant_s_joint_and_tip_states_are_its_properties_to_the_bit():
    """ArmPlant.joint_state and tip_state (read from the step's views) are base_position, base_velocity, effort,
    tip_position and tip_velocity, as copies, over a move and after a reset (the views made again)."""
    from sim_plant_node.arm.plant import ArmPlant

    plant = ArmPlant(500.0, 2)
    for pose in (HOME, np.array(POSES["near"])):
        plant.reset(pose)
        for k in range(60):
            plant.step(pose + 0.002 * k, velocity=np.full(6, 0.5) if k % 2 else None)
            got = (*plant.joint_state(), *plant.tip_state())
            want = (plant.base_position, plant.base_velocity, plant.effort, plant.tip_position, plant.tip_velocity)
            for g, w in zip(got, want, strict=True):
                assert g.tobytes() == w.tobytes()
            for g in got:  # copies: the next step does not change them
                g += 1.0
            assert plant.base_position.tobytes() == want[0].tobytes()
