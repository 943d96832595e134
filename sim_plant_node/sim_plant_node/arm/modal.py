"""Modal analysis of the elastic-joint arm, linearised at rest at a pose.

About a static equilibrium the arm of :mod:`.dynamics` is, with x = (q, theta),

    Mb x'' + Cb x' + (Kb + G) x = 0,
    Mb = diag(M(q0), B),  Cb = [[D, -D], [-D, D + F + Kd]],  Kb = [[K, -K], [-K, K + Kp]],
    G = [[dg/dq (q0), 0], [0, 0]]

(the gravity feedforward g(r) is constant at a fixed setpoint; the Coriolis terms vanish at
rest). Its eigenvalues lambda = -zeta w +- i w sqrt(1 - zeta^2) give the modes: natural
frequency |lambda|, damping ratio -Re(lambda) / |lambda|, and the eigenvector's first half the
mode shape (links, then motors). Overdamped (real) eigenvalues are not vibration modes and are
left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .dynamics import ArmModel, ElasticArm


@dataclass(frozen=True)
class ArmMode:
    """One vibration mode of the linearised arm.

    Attributes
    ----------
    omega : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    shape : ndarray
        Mode shape, (2 n,) complex: link angles then motor angles, largest entry 1.
    """

    omega: float
    zeta: float
    shape: np.ndarray

    @property
    def hz(self) -> float:
        """Natural frequency, Hz."""
        return self.omega / (2 * math.pi)

    @property
    def link_shape(self) -> np.ndarray:
        """Real link-side mode shape (largest entry 1), the pattern of joint angles that swings."""
        n = self.shape.size // 2
        s = self.shape[:n]
        s = np.real(s * np.exp(-1j * np.angle(s[np.argmax(np.abs(s))])))
        return s / np.max(np.abs(s))


def linearised(model: ArmModel, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass, damping and stiffness matrices (2 n x 2 n) of the arm at rest holding setpoint ``pose``."""
    n = model.n
    q, _ = model.rest(np.asarray(pose, dtype=float))
    k, d = np.diag(model.stiffness), np.diag(model.damping)
    mb = np.zeros((2 * n, 2 * n))
    mb[:n, :n] = model.mass(q)
    mb[n:, n:] = np.diag(model.motor_inertia)
    cb = np.block([[d, -d], [-d, d + np.diag(model.kd + model.motor_friction)]])
    kb = np.block([[k, -k], [-k, k + np.diag(model.kp)]])
    kb[:n, :n] += model.gravity_stiffness(q)
    return mb, cb, kb


def state_matrix(model: ArmModel, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first-order state matrix A (4 n x 4 n) of the arm linearised at rest holding ``pose``, over the
    state (link and motor angles, then their rates; rad, rad/s), and the inverse of its mass matrix."""
    n = model.n
    mb, cb, kb = linearised(model, pose)
    minv = np.linalg.inv(mb)
    a = np.block([[np.zeros((2 * n, 2 * n)), np.eye(2 * n)], [-minv @ kb, -minv @ cb]])
    return a, minv


def tool_output(model: ArmModel, pose: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The tool IMU's specific force (m/s^2, tool frame) as a linear map C (3 x 4 n) of the state of
    :func:`state_matrix`'s ``a`` at rest holding ``pose``: gravity's tilt with the link angles
    (central differences of 1e-6 rad) plus the links' acceleration through the tool's Jacobian."""
    import pinocchio as pin

    from .dynamics import GRAVITY

    n = model.n
    q0, _ = model.rest(np.asarray(pose, dtype=float))
    pin.computeJointJacobians(model.model, model.data, q0)
    pin.updateFramePlacements(model.model, model.data)
    c_acc = pin.getFrameJacobian(model.model, model.data, model.tool, pin.ReferenceFrame.LOCAL)[:3]
    up = np.array([0.0, 0.0, GRAVITY])

    def tilt(q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(model.model, model.data, q)
        return model.data.oMf[model.tool].rotation.T @ up

    c_q = np.column_stack([(tilt(q0 + 1e-6 * e) - tilt(q0 - 1e-6 * e)) / 2e-6 for e in np.eye(n)])
    c = np.zeros((3, 4 * n))
    c[:, :n] = c_q
    c += c_acc @ a[2 * n:3 * n]  # the links' acceleration (no direct feed: the input drives the motors)
    return c


def modes(model: ArmModel, pose: np.ndarray) -> list[ArmMode]:
    """The vibration modes at ``pose`` (joint setpoint, rad), lowest frequency first."""
    mb, cb, kb = linearised(model, pose)
    m = mb.shape[0]
    minv = np.linalg.inv(mb)
    a = np.block([[np.zeros((m, m)), np.eye(m)], [-minv @ kb, -minv @ cb]])
    values, vectors = np.linalg.eig(a)
    out = []
    for lam, vec in zip(values, vectors.T, strict=True):
        if lam.imag <= 1e-9 * max(1.0, abs(lam)):  # one of each conjugate pair; no real (overdamped) roots
            continue
        w = abs(lam)
        shape = vec[:m] / vec[:m][np.argmax(np.abs(vec[:m]))]
        out.append(ArmMode(float(w), float(-lam.real / w), shape))
    return sorted(out, key=lambda mode: mode.omega)


def lowest(model: ArmModel, pose: np.ndarray) -> ArmMode:
    """The lowest-frequency vibration mode at ``pose``."""
    return modes(model, pose)[0]


def mode_map(model: ArmModel, base_pose: np.ndarray, joints: tuple[int, int], grid_a: np.ndarray,
             grid_b: np.ndarray) -> np.ndarray:
    """Lowest-mode frequency (Hz) over a grid of two joints, the others at ``base_pose``: (len(a), len(b))."""
    out = np.empty((len(grid_a), len(grid_b)))
    pose = np.asarray(base_pose, dtype=float).copy()
    for i, qa in enumerate(grid_a):
        for j, qb in enumerate(grid_b):
            pose[joints[0]], pose[joints[1]] = qa, qb
            out[i, j] = lowest(model, pose).hz
    return out


def simulated_modes(model: ArmModel, pose: np.ndarray, step: float, max_damping: float = 1.0,
                    eps: float = 1e-7, simulator: Any = ElasticArm) -> list[tuple[float, float]]:
    """The modes of the arm *as simulated* at ``pose``: (natural frequency rad/s, damping ratio), lowest first.

    The simulator's one-step map (Newmark trapezoidal rule, step ``step`` s, state x, x', x'') is
    linearised at rest by central differences; each eigenvalue z gives s = ln(z) / step. This is
    what identification from the simulated arm's small free motions converges to: the
    continuous-time :func:`modes` less the integrator's frequency warping and the terms the
    continuous linearisation leaves out (within 0.5 % of it in damping on the UR5e-based arm).
    ``simulator(model, step, pose)`` makes the simulator (its ``x``, ``xd``, ``xdd`` and
    ``step(setpoint, velocity)``); :class:`ElasticArm` unless another integrator is compared.
    """
    pose = np.asarray(pose, dtype=float)
    arm = simulator(model, step, pose)
    m = 2 * model.n

    def advance(s: np.ndarray) -> np.ndarray:
        arm.x, arm.xd, arm.xdd = s[:m].copy(), s[m:2 * m].copy(), s[2 * m:].copy()
        arm.step(pose, np.zeros(model.n))
        return np.concatenate([arm.x, arm.xd, arm.xdd])

    rest = np.concatenate([arm.x, arm.xd, arm.xdd])
    jac = np.empty((3 * m, 3 * m))
    for i in range(3 * m):
        d = np.zeros(3 * m)
        d[i] = eps
        jac[:, i] = (advance(rest + d) - advance(rest - d)) / (2 * eps)
    z = np.linalg.eigvals(jac)
    z = z[np.abs(z) > 1e-9]
    s = np.log(z.astype(complex)) / step
    out = [(float(abs(v)), float(-v.real / abs(v))) for v in s if v.imag > 1e-6 and -v.real / abs(v) < max_damping]
    return sorted(out)
