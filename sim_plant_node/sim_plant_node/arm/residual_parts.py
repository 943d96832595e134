"""The two parts of the arm's residual vibration: the position loop's transient and the joints' vibration.

(The measure, ROS-free. ``python -m reproductions.arm_physics`` prints it for the cycle's moves; the sim plant node
reports it for every move of the arm, :mod:`.residual_watch`.)

After a move's commanded motion ends the setpoint holds still, so what the flange accelerometer
shows in the residual window is the free response of the arm and its position loop from the state
they are in at that instant. About the goal pose's equilibrium that response is linear
(:func:`.modal.linearised`): z' = A z, y = C z, z = (q, theta, q', theta') less
the rest state, y the specific force. Its eigenvalues split it into two sums, exactly:

- the **servo part**: the heavily damped (damping ratio >= :data:`SERVO_ZETA`) and overdamped
  eigenvalues, the motor position loop (50 Hz, damping 0.7 on the motors' inertia) settling its
  tracking lag through the springs;
- the **vibration part**: the lightly damped ones, the arm's modes (6-25 Hz, damping 2-9 %), which
  a shaper or a feedforward of the command acts on by the state it leaves them in.

:func:`residual_parts` gives both from the arm's simulated state at the commanded motion's end
(:class:`~.offline.OfflineArm` with ``states=True``, or the sim plant's own arm), on the IMU's own samples,
with the residual measure's mean removal and window; the sum of the two reproduces the simulated
residual (``linear_rms`` against the measured ``residual_rms``: within 3 % on the cycle's moves unshaped, fixed
and scheduled, docs/results/arm_residual_parts.md; over the learning cases' cycles docs/results/arm_learning.md
prints the largest difference).

Removing the flexibility instead (:func:`.dynamics.rigid_model`, the joints 100x
stiffer) is no decomposition of this arm: on the rigid arm the loop drives the links' inertia
directly and rings more, not less (the ``rigid`` case of :mod:`reproductions.arm_learning`; its
docs page shows both).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SERVO_ZETA", "LinearArm", "Parts", "linear_arm", "linear_cached", "parts_of", "residual_parts",
           "split_response"]

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

    @functools.cached_property
    def modal(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The eigenvalues, eigenvectors, each eigenvector's output (c v) and the servo eigenvalues' mask (module
        docstring; at :data:`SERVO_ZETA`), computed once per linearisation: a move's split then costs one solve."""
        values, vectors = np.linalg.eig(self.a)
        zeta = -values.real / np.maximum(np.abs(values), 1e-300)
        servo = (np.abs(values.imag) <= 1e-9 * np.maximum(1.0, np.abs(values))) | (zeta >= SERVO_ZETA)
        return values, vectors, self.c @ vectors, servo


def linear_arm(model: Any, pose: np.ndarray) -> LinearArm:
    """The arm (:class:`~sim_plant_node.arm.dynamics.ArmModel`) linearised at rest holding ``pose`` (rad)."""
    from .modal import state_matrix, tool_output

    a, minv = state_matrix(model, pose)
    q0, theta0 = model.rest(np.asarray(pose, dtype=float))
    c = tool_output(model, pose, a)
    return LinearArm(a, c, minv, np.concatenate([q0, theta0]))


def linear_cached(model: Any, goal: np.ndarray, cache: dict[Any, LinearArm] | None) -> LinearArm:
    """:func:`linear_arm` at ``goal`` (rad), taken from ``cache`` (keyed by the goal's bytes and the payload) or put
    in it."""
    goal = np.asarray(goal, dtype=float)
    key = (goal.tobytes(), model.payload)
    arm = cache.get(key) if cache is not None else None
    if arm is None:
        arm = linear_arm(model, goal)
        if cache is not None:
            cache[key] = arm
    return arm


def split_response(arm: LinearArm, z0: np.ndarray, times: np.ndarray,
                   servo_zeta: float = SERVO_ZETA) -> tuple[np.ndarray, np.ndarray]:
    """The free response y(t) = c exp(a t) z0 at ``times`` (s from the start, >= 0) as two (len(times), 3) parts,
    servo and vibration (module docstring); their sum is the whole free response, m/s^2."""
    values, vectors, outputs, servo = arm.modal
    if servo_zeta != SERVO_ZETA:
        zeta = -values.real / np.maximum(np.abs(values), 1e-300)
        servo = (np.abs(values.imag) <= 1e-9 * np.maximum(1.0, np.abs(values))) | (zeta >= servo_zeta)
    eta = np.linalg.solve(vectors, np.asarray(z0, dtype=complex))
    gains = outputs * eta  # (3, 4 n): each eigenvalue's output amplitude
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
    """The servo and vibration parts of a move's residual (module docstring), on the IMU's samples in the residual
    window [commanded_end, commanded_end + RESIDUAL_WINDOW) (:func:`.metrics.in_window`'s rule).

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
        Linearisations kept by goal pose and payload (the same goal recurs every cycle; the caller bounds it).
    """
    from .metrics import RESIDUAL_WINDOW, in_window

    t = np.asarray(imu_times, dtype=float)
    sel = in_window(t, commanded_end, commanded_end + RESIDUAL_WINDOW)
    return parts_of(linear_cached(model, goal, cache), state, t[sel] - commanded_end)


def parts_of(arm: LinearArm, state: np.ndarray, times: np.ndarray) -> Parts:
    """The parts of the free response of ``arm`` from ``state`` (the arm's (q, theta, q', theta'), rad and rad/s, at
    the commanded end) at ``times`` (s from it, each one counted), RMS with the mean removed, m/s^2."""
    from shaper_nodes.core.shaping.vibration import residual_vibration

    n2 = arm.rest.size
    z0 = np.concatenate([np.asarray(state[:n2]) - arm.rest, np.asarray(state[n2:])])
    t = np.asarray(times, dtype=float)
    servo, vib = split_response(arm, z0, t)

    def rms(y: np.ndarray) -> float:
        return residual_vibration(t, y, -math.inf, math.inf, remove_mean=True).rms

    return Parts(rms(servo), rms(vib), rms(servo + vib))
