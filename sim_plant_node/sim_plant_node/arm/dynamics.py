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

Each step solves the rule's 12 x 12 system for the new accelerations,

    [[M(q) + a11, -a11], [-a11, a22]] [q'', theta''] = [-n(q, q') - s, b],

with a11 = h D / 2 + h^2 K / 4 and a22 = B + h (D + F + Kd) / 2 + h^2 (K + Kp) / 4 diagonal
(s the spring and damper torque at the predicted state, b the motor side's right-hand side).
Eliminating theta'' (the motor block is diagonal) leaves the 6 x 6 Schur complement
S = M(q) + diag(a11 - a11^2 / a22): a mass matrix with an added diagonal, which is what
Pinocchio's articulated-body algorithm solves with the model's ``armature``. So one ``aba`` on a
copy of the model with armature a11 - a11^2 / a22 gives q'' = S^-1 (tau - n(q, q')) for
tau = a11 b / a22 - s in O(n), in place of ``crba``, ``nonLinearEffects`` and a dense 12 x 12
solve; theta'' = (b + a11 q'') / a22. Everything else in a step is linear in the state
(x, x', x'') and the loop's drive Kp r + Kd r' + g(r), so one precomputed 36 x 36 matrix gives
the predicted state, s, tau and b less the drive in one product. The results equal the dense
solve to rounding (test_arm.py compares trajectories and the modes as simulated against it).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .description import TOOL_FRAME, ArmSpec, check_payload, payload_inertia, urdf

GRAVITY = 9.81  # m/s^2, the model's gravity (along -z of the base)
_LOCAL = pin.ReferenceFrame.LOCAL


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
        self.h = h = float(step)
        self.n = model.n
        k = np.asarray(model.stiffness, dtype=float)
        d = np.asarray(model.damping, dtype=float) * np.ones(model.n)
        self._k, self._d = k, d
        self._kdf = model.kd + model.motor_friction  # motor-side damping besides the joint's
        a11 = 0.5 * h * d + 0.25 * h * h * k
        a22 = model.motor_inertia + 0.5 * h * (d + self._kdf) + 0.25 * h * h * (k + model.kp)
        self._ratio = a11 / a22
        self._inv_a22 = 1.0 / a22
        # the link side's Schur complement is M(q) + diag(a11 - a11^2 / a22): Pinocchio's armature
        self._armature = a11 - a11 * self._ratio
        self._copy_model()
        self._hh4, self._h2 = 0.25 * h * h, 0.5 * h  # the trapezoidal rule's factors
        self._map = self._linear_map()
        self.reset(np.zeros(model.n) if position is None else position)

    def _copy_model(self) -> None:
        """The copy of the arm's Pinocchio model that the step solves with (its armature is the Schur
        complement's diagonal), made again whenever the arm's inertial parameters change."""
        self._pin_model = pin.Model(self.model.model)
        self._pin_model.armature = self._armature
        self._pin_data = self._pin_model.createData()

    def _linear_map(self) -> np.ndarray:
        """The 36 x 36 matrix W with W (x, x', x'') = (tau, b, x_pred, x'_pred) less the drive's terms.

        x_pred = x + h x' + h^2 x'' / 4 and x'_pred = x' + h x'' / 2 (the rule's predictor);
        s = K (q_p - theta_p) + D (q'_p - theta'_p) the spring and damper on it; the motor rows'
        right-hand side b = drive + s - Kp theta_p - (Kd + F) theta'_p; tau = a11 b / a22 - s.
        """
        n, h = self.n, self.h
        eye, zero = np.eye(2 * n), np.zeros((2 * n, 2 * n))
        pred = np.block([[eye, h * eye, self._hh4 * eye], [zero, eye, self._h2 * eye]])  # -> (x_p, x'_p)
        k, d, kp = np.diag(self._k), np.diag(self._d), np.diag(self.model.kp)
        spring = np.hstack([k, -k, d, -d]) @ pred
        motor = np.hstack([k, -k - kp, d, -d - np.diag(self._kdf)]) @ pred
        return np.vstack([self._ratio[:, None] * motor - spring, motor, pred])

    def reset(self, position: np.ndarray) -> None:
        """At rest (static equilibrium) holding setpoint ``position``."""
        r = np.asarray(position, dtype=float).copy()
        q, theta = self.model.rest(r)
        self._state = np.zeros(6 * self.n)  # (x, x', x''), the 12 coordinates each: what the step's map takes
        self._views()
        self.x = np.concatenate([q, theta])
        self.setpoint = r
        self._setpoint_bytes = r.tobytes()
        self._g_r = self.model.gravity(r)
        self._drive = self.model.kp * r + self._g_r  # the loop's torque but its theta and velocity terms, N m
        self._velocity: np.ndarray | None = None     # the last step's velocity feedforward, rad/s
        self._torque: np.ndarray | None = self._g_r.copy()
        self.time = 0.0

    def _views(self) -> None:
        """The views of the state and of the map's product that each step reads and writes, and its scratch arrays
        (made once per state array: a step then calls NumPy about half as often, with the same operations)."""
        n, st = self.n, self._state
        self._q, self._v, self._a = st[:n], st[2 * n:3 * n], st[4 * n:5 * n]
        self._pos, self._vel, self._pos_vel, self._acc = st[:2 * n], st[2 * n:4 * n], st[:4 * n], st[4 * n:]
        self._acc_link, self._acc_motor = st[4 * n:5 * n], st[5 * n:]
        self._theta, self._theta_dot = st[n:2 * n], st[3 * n:4 * n]  # (motor_position, motor_velocity)
        self._y = np.zeros(6 * n)  # (tau, b, x_pred, x'_pred) less the drive
        self._y_tau, self._y_b, self._y_pred = self._y[:n], self._y[n:2 * n], self._y[2 * n:]
        self._tau, self._motor, self._coupling, self._inc = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(2 * n)

    def model_changed(self) -> None:
        """The model's inertial parameters changed (:meth:`ArmModel.set_payload`): recompute what is kept from
        them. The controller's gravity feedforward at the setpoint follows the new payload (the robot is told
        its payload, as a UR controller's ``set_payload``); the arm's state is kept, so it leaves its old
        equilibrium under the new load from the next step on, as an arm does when it picks up a part."""
        self._copy_model()
        self._g_r = self.model.gravity(self.setpoint)
        self._drive = self.model.kp * self.setpoint + self._g_r
        self._torque = None

    @property
    def x(self) -> np.ndarray:
        """Positions of the links and the motors (q, theta), rad: a view of the state, changed by each step."""
        return self._state[:2 * self.n]

    @x.setter
    def x(self, value: np.ndarray) -> None:
        self._state[:2 * self.n] = value

    def state_copy(self) -> np.ndarray:
        """(x, xd) as a new array: the positions, then the velocities."""
        return self._state[:4 * self.n].copy()

    @property
    def xd(self) -> np.ndarray:
        """Their velocities, rad/s (a view of the state)."""
        return self._state[2 * self.n:4 * self.n]

    @xd.setter
    def xd(self, value: np.ndarray) -> None:
        self._state[2 * self.n:4 * self.n] = value

    @property
    def xdd(self) -> np.ndarray:
        """Their accelerations, rad/s^2 (a view of the state)."""
        return self._state[4 * self.n:]

    @xdd.setter
    def xdd(self, value: np.ndarray) -> None:
        self._state[4 * self.n:] = value

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

    def link_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of :attr:`q` and :attr:`v` (read from the step's views: a period's per-step outputs take them)."""
        return self._q.copy(), self._v.copy()

    def motor_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of :attr:`motor_position` and :attr:`motor_velocity` (from the step's views, as
        :meth:`link_state`)."""
        return self._theta.copy(), self._theta_dot.copy()

    def step(self, setpoint: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Advance one step holding the loop's setpoint (rad) and velocity feedforward (rad/s)."""
        self.advance(*self.hold(setpoint, velocity))

    def hold(self, setpoint: np.ndarray, velocity: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Take the loop's setpoint (rad) and velocity feedforward (rad/s) for the next steps; returns the loop's drive
        (its torque but the theta and velocity terms, N m) and the part of it the link side takes, what
        :meth:`advance` steps with: :meth:`step` is ``advance(*hold(setpoint, velocity))``, and steps of one command
        period (the same setpoint) may take them once."""
        mdl = self.model
        r = np.asarray(setpoint, dtype=float)
        key = r.tobytes()  # the setpoint changes at most once per command period: gravity at it is kept
        if key != self._setpoint_bytes:
            self.setpoint = r.copy()
            self._setpoint_bytes = key
            self._g_r = mdl.gravity(r)
            self._drive = mdl.kp * r + self._g_r
        if velocity is None:
            drive = self._drive
            self._velocity = None
        else:
            self._velocity = rd = np.asarray(velocity, dtype=float)
            drive = self._drive + mdl.kd * rd
        return drive, self._ratio * drive

    def advance(self, drive: np.ndarray, link_drive: np.ndarray) -> None:
        """One step with the loop's ``drive`` and its link side's part ``link_drive`` (:meth:`hold`): the map's product,
        the articulated-body solve, the motor accelerations and the trapezoidal update, in place."""
        y = np.matmul(self._map, self._state, out=self._y)  # (tau, b, x_pred, x'_pred) less the drive
        tau = np.add(self._y_tau, link_drive, out=self._tau)
        link = pin.aba(self._pin_model, self._pin_data, self._q, self._v, tau)
        self._acc_link[:] = link
        motor = np.add(self._y_b, drive, out=self._motor)
        np.multiply(self._inv_a22, motor, out=motor)
        np.add(motor, np.multiply(self._ratio, link, out=self._coupling), out=self._acc_motor)
        self._pos_vel[:] = y[2 * self.n:]
        self._pos += np.multiply(self._hh4, self._acc, out=self._inc)
        self._vel += np.multiply(self._h2, self._acc, out=self._inc)
        self._torque = None
        self.time += self.h

    @property
    def torque(self) -> np.ndarray:
        """The motors' torques after the last step, N m: Kp (r - theta) + Kd (r' - theta') + g(r)."""
        if self._torque is None:
            mdl, n = self.model, self.n
            rd = 0.0 if self._velocity is None else self._velocity
            self._torque = mdl.kp * (self.setpoint - self.x[n:]) + mdl.kd * (rd - self.xd[n:]) + self._g_r
        return self._torque

    def imu(self) -> tuple[np.ndarray, np.ndarray]:
        """The flange IMU's ideal reading: specific force (m/s^2, gravity included) and angular rate (rad/s).

        Both in the flange frame: f = R^T (a - g_vec) with a the flange origin's acceleration.
        """
        mdl = self.model
        model, data, tool = mdl.model, mdl.data, mdl.tool
        pin.forwardKinematics(model, data, self._q, self._v, self._a)
        frame = pin.updateFramePlacement(model, data, tool)
        acc = pin.getFrameClassicalAcceleration(model, data, tool, _LOCAL).linear
        rate = pin.getFrameVelocity(model, data, tool, _LOCAL).angular
        specific = acc + GRAVITY * frame.rotation[2]  # R^T (0, 0, g): g times R's last row
        return specific, np.array(rate)

    def tool_position(self) -> np.ndarray:
        """The flange's position, m (from the link angles)."""
        return self.model.tool_position(self.q)


#: how much stiffer than the arm's joints :func:`rigid_model`'s are: at HOME its joint modes lie at 200-320 Hz
#: (damped 42-55 %), far above the arm's 10-21 Hz and still below the 1 kHz physics step's 500 Hz limit (1000x
#: puts them near it, where the trapezoidal rule warps them); what is left below 50 Hz is the position loop
#: driving the links' inertia (23-45 Hz, damped 31 % and more), measured with :func:`.modal.modes`
RIGID_FACTOR = 100.0


def rigid_model(factor: float = RIGID_FACTOR, spec: ArmSpec | None = None, loop: LoopGains | None = None) -> ArmModel:
    """The arm with its flexibility removed: the same links, motors and position loop, the joints ``factor``
    times stiffer (their damping scales with them, :data:`~.description.DAMPING_TIME`).

    What the flange's accelerometer shows on it after a move is the position loop's transient alone (the
    links follow the motors); on the flexible arm the same move adds the joints' vibration.

    Parameters
    ----------
    factor : float
        Stiffness multiplier, >= 1.
    spec : ArmSpec, optional
        The arm to stiffen (default: the module figures).
    loop : LoopGains, optional
        The motor position loop (default: the arm's).

    Raises
    ------
    ValueError
        ``factor`` is not a finite number >= 1.
    """
    if not (isinstance(factor, (int, float)) and math.isfinite(factor) and factor >= 1.0):
        raise ValueError(f"rigid_model: factor must be finite and >= 1, got {factor!r}")
    spec = spec or ArmSpec()
    stiff = dataclasses.replace(spec, stiffness=tuple(float(factor) * k for k in spec.stiffness))
    return ArmModel(stiff, loop)
