"""MRILC per move's lifted operator on the arm: the flange accelerometer's response to each B-spline coefficient
of a joint profile correction, on the arm linearised at rest at the move's goal pose.

:func:`lifted_operator` is what ``reproductions.arm_mrilc`` and the learner node's MRILC per move
(``mode: mrilc_moves``, ``mrilc_moves.operator: sim_plant_node.arm.lifted:arm_operator``) use;
:func:`arm_operator` is the node's entry: the simulator's arm model, built once per process and payload;
:func:`arm_modes` its modes at a pose for a payload (``mrilc_moves.modes``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: output samples the linearised response is delayed by: 0. The model holds each setpoint over the controller's
#: period as the controller does, so no extra delay: measured on the offline arm (home->rotated, joints 1-3, the
#: response to one B-spline of 4 ms and of 40 ms spacing in the residual window), the columns correlate
#: 0.98-0.996 with the measured response with no shift, 0.43-0.95 with a shift of one sample (the shift the
#: 40 ms B-splines alone did not resolve: 0.995 either way)
DELAY = 0
#: s the controller emulation holds each setpoint (its period at 500 Hz)
HOLD = 2e-3

#: the arms the node's operators were built on, by payload (None: the model's default)
_MODEL: dict[float | None, Any] = {}


def lifted_operator(model: Any, pose: np.ndarray, count: int, samples: int, first: int = 0, spacing: float = 0.04,
                    period: float = 1e-3, delay: int = DELAY, hold: float = HOLD) -> np.ndarray:
    """G: the specific force's response ((samples x 3) rows, k-major; m/s^2 per rad) to each B-spline coefficient
    (joint-major columns, ``count`` B-splines ``spacing`` s apart per joint), on the arm linearised at rest holding
    ``pose`` (rad); the setpoint held ``hold`` s as the controller does (2 ms), the response integrated exactly
    every ``hold`` / 2 s (the IMU's period) and sampled every ``period`` s (a multiple of ``hold`` / 2); the first
    B-spline starts ``first`` output samples after the move's start, the response ``delay`` samples later."""
    from scipy.linalg import expm

    from shaper_nodes.core.learning.mrilc.profile import spline_basis

    from .modal import state_matrix, tool_output

    h = hold / 2
    per = int(round(period / h))
    if per < 1 or abs(per * h - period) > 1e-9 * period:
        raise ValueError(f"the output period {period} s must be a multiple of {h} s (half the controller's period)")
    n = 6
    a, minv = state_matrix(model, pose)
    drive = np.zeros((2 * n, 2 * n))  # the loop's torque from (dr, dr'): (Kp + dg/dq(r)) dr + Kd dr'
    drive[n:, :n] = np.diag(model.kp) + model.gravity_stiffness(np.asarray(pose, dtype=float))
    drive[n:, n:] = np.diag(model.kd)
    b = np.vstack([np.zeros((2 * n, 2 * n)), minv @ drive])
    big = expm(np.block([[a, b], [np.zeros((2 * n, 6 * n))]]) * h)
    ad, bd = big[:4 * n, :4 * n], big[:4 * n, 4 * n:]
    c = tool_output(model, pose, a)
    shift = int(round(spacing / period))
    steps = samples * per
    held = hold * np.floor(np.arange(steps) * h / hold + 1e-9)  # the controller's period each step is in
    b0, b1, _ = spline_basis(held, spacing, 1)
    g = np.zeros((samples * 3, count * n))
    for j in range(n):
        z = np.zeros(4 * n)
        resp = np.zeros((samples, 3))
        u = np.zeros(2 * n)
        for m in range(steps):
            u[j], u[n + j] = b0[m, 0], b1[m, 0]
            z = ad @ z + bd @ u
            if (m + 1) % per == 0:
                resp[(m + 1) // per - 1] = c @ z
        lag = delay + first
        resp = (np.vstack([np.zeros((lag, 3)), resp[:samples - lag]]) if lag >= 0
                else np.vstack([resp[-lag:], np.zeros((-lag, 3))]))
        for i in range(count):
            col = np.zeros((samples, 3))
            col[i * shift:] = resp[:samples - i * shift]
            g[:, j * count + i] = col.ravel()
    return g


def arm_operator(pose: np.ndarray, count: int, samples: int, first: int, spacing: float, period: float,
                 payload: float | None = None) -> np.ndarray:
    """:func:`lifted_operator` on the simulator's arm (:class:`~.dynamics.ArmModel`), the entry the learner node's
    ``mrilc_moves.operator`` names: at the model's default payload, or with ``payload`` kg at the flange (the
    payload the robot is told: the node's ``mrilc_moves.payload_mass`` when it is set; one model built per
    payload, at its first call)."""
    from .dynamics import ArmModel

    key = None if payload is None else float(payload)
    if key not in _MODEL:
        model = ArmModel()
        if key is not None:
            model.set_payload(key)
        _MODEL[key] = model
    return lifted_operator(_MODEL[key], np.asarray(pose, dtype=float), count, samples, first, spacing, period)


#: the arm the node's modes are computed on (one model, its payload set per call)
_MODES_MODEL: list[Any] = []


def arm_modes(pose: np.ndarray, payload: float) -> list[float]:
    """The simulator's arm's vibration modes (Hz, lowest first) at ``pose`` (rad) holding ``payload`` kg at the
    flange: the entry the learner node's ``mrilc_moves.modes`` names (the payload worked out from a drifted mode,
    :mod:`shaper_nodes.core.learning.mrilc.payload`). Raises ValueError for a payload the model cannot take."""
    from .dynamics import ArmModel
    from .modal import modes

    if not _MODES_MODEL:
        _MODES_MODEL.append(ArmModel())
    model = _MODES_MODEL[0]
    if model.payload[0] != float(payload):
        model.set_payload(float(payload))
    return [md.omega / (2.0 * np.pi) for md in modes(model, np.asarray(pose, dtype=float))]
