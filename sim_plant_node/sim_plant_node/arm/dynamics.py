"""The elastic-joint arm: rigid-body dynamics from Pinocchio, motors, springs and the position loop.

Model (the flexible-joint model: each link driven by its motor through a torsional spring)::

    M(q) q'' + C(q, q') q' + g(q) = K (theta - q) + D (theta' - q')            links
    B theta'' + F theta' + K (theta - q) + D (theta' - q') = tau               motors
    tau = Kp (r - theta) + Kd (r' - theta') + g(r)                             position loop

q the link angles, theta the motor angles (on the link side of the gear), K and D the joint
stiffness and damping, B the reflected motor inertia, F motor friction; the loop is a stiff
per-joint PD on the motor side with gravity feedforward at the setpoint r (a common industrial
structure: what the encoders see follows the setpoint, the links sag by K^-1 g and swing).
M, C q' + g and g come from Pinocchio (``crba``, ``nonLinearEffects``,
``computeGeneralizedGravity``) on the URDF of :mod:`.description`.

Integration: the trapezoidal rule (Newmark, average acceleration) on the 12 coordinates
x = (q, theta), with M(q) and the nonlinear link terms frozen over each step. The rule is
unconditionally stable and adds no numerical damping, so the stiff motor loop does not limit
the step and the modes decay at their physical rate (frequency error about (w h)^2 / 12).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .description import TOOL_FRAME, ArmSpec, check_payload, payload_inertia, urdf

GRAVITY = 9.81  # m/s^2, the model's gravity (along -z of the base)


@dataclass(frozen=True)
class LoopGains:
    """The motor-side position loop: bandwidth, Hz, and damping ratio per joint (Kp = B w^2, Kd = 2 z B w)."""

    bandwidth_hz: float = 50.0
    damping_ratio: float = 0.7

    def gains(self, motor_inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = 2 * math.pi * self.bandwidth_hz
        return motor_inertia * w * w, 2 * self.damping_ratio * motor_inertia * w


class ArmModel:
    """Pinocchio's model of the rigid arm and the joint, motor and loop constants.

    Parameters
    ----------
    spec : ArmSpec
        The arm (default: the module figures).
    loop : LoopGains
        The motor position loop.
    """

    def __init__(self, spec: ArmSpec | None = None, loop: LoopGains | None = None) -> None:
        spec = spec or ArmSpec()
        loop = loop or LoopGains()
        self.spec = spec
        self.model = pin.buildModelFromXML(urdf(spec))
        self.model.gravity.linear = np.array([0.0, 0.0, -GRAVITY])
        self.data = self.model.createData()
        self.tool = self.model.getFrameId(TOOL_FRAME)
        self.n = self.model.nv
        self.joint_names = tuple(spec.joint_names)
        self.stiffness = np.asarray(spec.stiffness, dtype=float)
        self.damping = spec.damping
        self.motor_inertia = np.asarray(spec.motor_inertia, dtype=float)
        self.motor_friction = np.asarray(spec.motor_friction, dtype=float)
        self.kp, self.kd = loop.gains(self.motor_inertia)
        # the body of the flange's joint without the payload: a payload change replaces what is added to it
        frame = self.model.frames[self.tool]
        self._flange_joint, self._flange_placement = frame.parentJoint, frame.placement
        bare = pin.buildModelFromXML(urdf(dataclasses.replace(spec, payload_mass=0.0)))
        self._flange_body = bare.inertias[self._flange_joint].copy()

    @property
    def payload(self) -> tuple[float, float]:
        """The payload at the flange: mass, kg, and its centre of mass along the flange's z, m."""
        return self.spec.payload_mass, self.spec.payload_offset

    def set_payload(self, mass: float, offset: float | None = None) -> None:
        """Change the payload at the flange (a gripper picks up a part, a tool is changed).

        The flange body's inertia (Pinocchio's ``model.inertias`` of the last joint) becomes the last
        link's plus the payload, a uniform cylinder (:func:`~.description.payload_inertia`) of ``mass`` kg
        centred ``offset`` m along the flange's z, as the URDF of a :class:`~.description.ArmSpec` with this
        payload gives; the mass matrix, gravity and modes follow. The arm's state is not touched: an
        :class:`ElasticArm` on this model calls :meth:`ElasticArm.model_changed` next.

        Parameters
        ----------
        mass : float
            Payload mass, kg, in [0, MAX_PAYLOAD_MASS].
        offset : float, optional
            Its centre of mass along the flange's z, m (default: unchanged).

        Raises
        ------
        ValueError
            The payload is out of range (nothing changes then).
        """
        offset = self.spec.payload_offset if offset is None else offset
        check_payload(mass, offset)
        spec = dataclasses.replace(self.spec, payload_mass=float(mass), payload_offset=float(offset))
        body = self._flange_body.copy()
        if mass > 0:
            body += self._flange_placement.act(pin.Inertia(float(mass), np.array([0.0, 0.0, float(offset)]),
                                                           payload_inertia(float(mass), float(offset))))
        self.model.inertias[self._flange_joint] = body
        self.spec = spec

    def mass(self, q: np.ndarray) -> np.ndarray:
        """Link-side mass matrix M(q), kg m^2 (symmetric)."""
        return np.array(pin.crba(self.model, self.data, q))

    def nonlinear(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """C(q, v) v + g(q), N m."""
        return np.array(pin.nonLinearEffects(self.model, self.data, q, v))

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """g(q), N m."""
        return np.array(pin.computeGeneralizedGravity(self.model, self.data, q))

    def gravity_stiffness(self, q: np.ndarray) -> np.ndarray:
        """dg/dq at q, N m/rad."""
        return np.array(pin.computeGeneralizedGravityDerivatives(self.model, self.data, q))

    def tool_position(self, q: np.ndarray) -> np.ndarray:
        """Position of the flange in the base frame, m."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array(self.data.oMf[self.tool].translation)

    def tool_positions(self, qs: np.ndarray) -> np.ndarray:
        """Flange positions, (N, 3) m, for joint angles (N, n)."""
        return np.array([self.tool_position(q) for q in np.atleast_2d(qs)])

    def rest(self, r: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
        """Static equilibrium (links, motors) holding setpoint r: K (theta - q) = g(q), Kp (r - theta) + g(r) = g(q)."""
        r = np.asarray(r, dtype=float)
        g_r = self.gravity(r)
        q = r.copy()
        theta = r.copy()
        for _ in range(iterations):
            g = self.gravity(q)
            theta = r + (g_r - g) / self.kp
            q = theta - g / self.stiffness
        return q, theta


class ElasticArm:
    """State and integration of the elastic-joint arm under its position loop (module docstring).

    Parameters
    ----------
    model : ArmModel
        The arm.
    step : float
        Integration step, s.
    position : array_like, optional
        Setpoint to start at rest at (default zeros).
    """

    def __init__(self, model: ArmModel, step: float, position: np.ndarray | None = None) -> None:
        if not (math.isfinite(step) and 0 < step <= 0.01):
            raise ValueError(f"integration step must be in (0, 0.01] s, got {step!r}")
        self.model = model
        self.h = float(step)
        n = self.n = model.n
        k, d = np.diag(model.stiffness), np.diag(model.damping)
        self._kb = np.block([[k, -k], [-k, k + np.diag(model.kp)]])
        self._cb = np.block([[d, -d], [-d, d + np.diag(model.kd + model.motor_friction)]])
        h = self.h
        self._rest_of_a = 0.5 * h * self._cb + 0.25 * h * h * self._kb
        self._a = self._rest_of_a.copy()
        self._a[n:, n:] += np.diag(model.motor_inertia)
        self._hh4, self._h2 = 0.25 * h * h, 0.5 * h  # the trapezoidal rule's factors, as step used to form them
        self._kd_zero = model.kd * np.zeros(n)  # kd times a zero velocity feedforward
        self.reset(np.zeros(n) if position is None else position)

    def reset(self, position: np.ndarray) -> None:
        """At rest (static equilibrium) holding setpoint ``position``."""
        r = np.asarray(position, dtype=float).copy()
        q, theta = self.model.rest(r)
        self.x = np.concatenate([q, theta])
        self.xd = np.zeros(2 * self.n)
        self.xdd = np.zeros(2 * self.n)
        self.setpoint = r
        self._setpoint_bytes = r.tobytes()
        self._g_r = self.model.gravity(r)
        self.torque = self._g_r.copy()
        self.time = 0.0

    def model_changed(self) -> None:
        """The model's inertial parameters changed (:meth:`ArmModel.set_payload`): recompute what is kept from
        them. The controller's gravity feedforward at the setpoint follows the new payload (the robot is told
        its payload, as a UR controller's ``set_payload``); the arm's state is kept, so it leaves its old
        equilibrium under the new load from the next step on, as an arm does when it picks up a part."""
        self._g_r = self.model.gravity(self.setpoint)

    @property
    def q(self) -> np.ndarray:
        """Link angles, rad."""
        return self.x[:self.n]

    @property
    def v(self) -> np.ndarray:
        """Link velocities, rad/s."""
        return self.xd[:self.n]

    @property
    def a(self) -> np.ndarray:
        """Link accelerations, rad/s^2."""
        return self.xdd[:self.n]

    @property
    def motor_position(self) -> np.ndarray:
        """Motor angles (link side of the gear), rad: what the joint encoders report."""
        return self.x[self.n:]

    @property
    def motor_velocity(self) -> np.ndarray:
        return self.xd[self.n:]

    def step(self, setpoint: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Advance one step holding the loop's setpoint (rad) and velocity feedforward (rad/s)."""
        n, h, mdl = self.n, self.h, self.model
        r = np.asarray(setpoint, dtype=float)
        key = r.tobytes()  # the setpoint changes at most once per command period: gravity at it is kept
        if key != self._setpoint_bytes:
            self.setpoint = r.copy()
            self._setpoint_bytes = key
            self._g_r = mdl.gravity(r)
        q, v = self.x[:n], self.xd[:n]
        a_mat = self._a
        a_mat[:n, :n] = mdl.mass(q) + self._rest_of_a[:n, :n]
        f = np.empty(2 * n)
        f[:n] = -mdl.nonlinear(q, v)
        if velocity is None:
            f[n:] = mdl.kp * r + self._kd_zero + self._g_r
        else:
            rd = np.asarray(velocity, dtype=float)
            f[n:] = mdl.kp * r + mdl.kd * rd + self._g_r
        hh4, h2 = self._hh4, self._h2
        x_pred = self.x + h * self.xd + hh4 * self.xdd
        xd_pred = self.xd + h2 * self.xdd
        xdd = np.linalg.solve(a_mat, f - self._cb @ xd_pred - self._kb @ x_pred)
        self.x = x_pred + hh4 * xdd
        self.xd = xd_pred + h2 * xdd
        self.xdd = xdd
        theta, thetad = self.x[n:], self.xd[n:]
        if velocity is None:
            self.torque = mdl.kp * (r - theta) + mdl.kd * (0.0 - thetad) + self._g_r
        else:
            self.torque = mdl.kp * (r - theta) + mdl.kd * (rd - thetad) + self._g_r
        self.time += h

    def imu(self) -> tuple[np.ndarray, np.ndarray]:
        """The flange IMU's ideal reading: specific force (m/s^2, gravity included) and angular rate (rad/s).

        Both in the flange frame: f = R^T (a - g_vec) with a the flange origin's acceleration.
        """
        mdl = self.model
        pin.forwardKinematics(mdl.model, mdl.data, self.q, self.v, self.a)
        frame = pin.updateFramePlacement(mdl.model, mdl.data, mdl.tool)
        acc = pin.getFrameClassicalAcceleration(mdl.model, mdl.data, mdl.tool, pin.ReferenceFrame.LOCAL).linear
        rate = pin.getFrameVelocity(mdl.model, mdl.data, mdl.tool, pin.ReferenceFrame.LOCAL).angular
        specific = np.array(acc) + frame.rotation.T @ np.array([0.0, 0.0, GRAVITY])
        return specific, np.array(rate)

    def tool_position(self) -> np.ndarray:
        """The flange's position, m (from the link angles)."""
        return self.model.tool_position(self.q)
