"""The two parts of the arm's residual vibration: the position loop's transient and the joints' vibration.

(The measure; ``python -m reproductions.arm_physics`` prints it for the cycle's moves.)

After a move's commanded motion ends the setpoint holds still, so what the flange accelerometer
shows in the residual window is the free response of the arm and its position loop from the state
they are in at that instant. About the goal pose's equilibrium that response is linear
(:func:`sim_plant_node.arm.modal.linearised`): z' = A z, y = C z, z = (q, theta, q', theta') less
the rest state, y the specific force. Its eigenvalues split it into two sums, exactly:

- the **servo part**: the heavily damped (damping ratio >= :data:`SERVO_ZETA`) and overdamped
  eigenvalues, the motor position loop (50 Hz, damping 0.7 on the motors' inertia) settling its
  tracking lag through the springs;
- the **vibration part**: the lightly damped ones, the arm's modes (6-25 Hz, damping 2-9 %), which
  a shaper or a feedforward of the command acts on by the state it leaves them in.

:func:`residual_parts` gives both from the arm's simulated state at the commanded motion's end
(:class:`~sim_plant_node.arm.offline.OfflineArm` with ``states=True``), on the IMU's own samples,
with the residual measure's mean removal and window; the sum of the two reproduces the simulated
residual (``linear_rms`` against the measured ``residual_rms``; within 3 % on the cycle's moves,
docs/results/arm_learning.md prints the largest difference).

Removing the flexibility instead (:func:`sim_plant_node.arm.dynamics.rigid_model`, the joints 100x
stiffer) is no decomposition of this arm: on the rigid arm the loop drives the links' inertia
directly and rings more, not less (the ``rigid`` case of :mod:`reproductions.arm_learning`; its
docs page shows both).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: eigenvalues of the linearised arm with this damping ratio or more (and the real ones) are the position loop's
#: transient; the arm's modes have 2-9 % (the calibration's schedule), the loop's coupled ones 30 % and more
SERVO_ZETA = 0.12


@dataclass(frozen=True)
class LinearArm:
    """The arm at rest holding a setpoint, linearised: z' = a z (+ the loop's drive), y = c z.

    Attributes
    ----------
    a : ndarray
        (4 n, 4 n) state matrix, z = (q, theta, q', theta') about the rest state, 1/s.
    c : ndarray
        (3, 4 n) the flange accelerometer's specific force (flange frame) per unit of z, m/s^2.
    minv : ndarray
        (2 n, 2 n) the inverse of the mass matrix diag(M(q0), B), 1/(kg m^2).
    rest : ndarray
        (2 n,) the rest positions (links, motors), rad.
    """

    a: np.ndarray
    c: np.ndarray
    minv: np.ndarray
    rest: np.ndarray


def linear_arm(model: Any, pose: np.ndarray) -> LinearArm:
    """The arm (:class:`~sim_plant_node.arm.dynamics.ArmModel`) linearised at rest holding ``pose`` (rad)."""
    from sim_plant_node.arm.modal import state_matrix, tool_output

    a, minv = state_matrix(model, pose)
    q0, theta0 = model.rest(np.asarray(pose, dtype=float))
    c = tool_output(model, pose, a)
    return LinearArm(a, c, minv, np.concatenate([q0, theta0]))


def split_response(arm: LinearArm, z0: np.ndarray, times: np.ndarray,
                   servo_zeta: float = SERVO_ZETA) -> tuple[np.ndarray, np.ndarray]:
    """The free response y(t) = c exp(a t) z0 at ``times`` (s from the start, >= 0) as two (len(times), 3) parts,
    servo and vibration (module docstring); their sum is the whole free response, m/s^2."""
    values, vectors = np.linalg.eig(arm.a)
    eta = np.linalg.solve(vectors, np.asarray(z0, dtype=complex))
    gains = (arm.c @ vectors) * eta  # (3, 4 n): each eigenvalue's output amplitude
    zeta = -values.real / np.maximum(np.abs(values), 1e-300)
    servo = (np.abs(values.imag) <= 1e-9 * np.maximum(1.0, np.abs(values))) | (zeta >= servo_zeta)
    t = np.asarray(times, dtype=float)[:, None]
    waves = np.exp(t * values[None, :])  # (len(times), 4 n)
    return (np.real(waves[:, servo] @ gains[:, servo].T), np.real(waves[:, ~servo] @ gains[:, ~servo].T))


@dataclass(frozen=True)
class Parts:
    """A move's residual split (RMS over the residual window, mean removed, m/s^2)."""

    servo_rms: float
    vibration_rms: float
    linear_rms: float  # the two together, as the linear model has them (check against the measured residual)


def residual_parts(model: Any, goal: np.ndarray, state: np.ndarray, imu_times: np.ndarray, commanded_end: float,
                   cache: dict[Any, LinearArm] | None = None) -> Parts:
    """The servo and vibration parts of a move's residual (module docstring).

    Parameters
    ----------
    model : ArmModel
        The arm the move ran on (its present payload).
    goal : ndarray
        The setpoint held after the commanded motion, rad.
    state : ndarray
        The arm's state at ``commanded_end`` ((q, theta, q', theta'), rad and rad/s).
    imu_times : ndarray
        The IMU's sample times, s (those in the residual window are used).
    commanded_end : float
        When the commanded motion ended, s.
    cache : dict, optional
        Linearisations kept by goal pose and payload (the same goal recurs every cycle).
    """
    from shaper_nodes.core.shaping.vibration import residual_vibration
    from sim_plant_node.arm.metrics import RESIDUAL_WINDOW

    goal = np.asarray(goal, dtype=float)
    key = (goal.tobytes(), model.payload)
    arm = cache.get(key) if cache is not None else None
    if arm is None:
        arm = linear_arm(model, goal)
        if cache is not None:
            cache[key] = arm
    n2 = arm.rest.size
    z0 = np.concatenate([np.asarray(state[:n2]) - arm.rest, np.asarray(state[n2:])])
    t = np.asarray(imu_times, dtype=float)
    sel = (t >= commanded_end) & (t <= commanded_end + RESIDUAL_WINDOW)
    servo, vib = split_response(arm, z0, t[sel] - commanded_end)

    def rms(y: np.ndarray) -> float:
        return residual_vibration(t[sel], y, commanded_end, commanded_end + RESIDUAL_WINDOW, remove_mean=True).rms

    return Parts(rms(servo), rms(vib), rms(servo + vib))
