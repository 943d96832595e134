"""A flexible joint inside a feedback loop, with a feedforward input (seed 000's set-up), free of ROS.

Per joint, the base-driven m-c-k plant of seed 000 eq. (12),

    P(s) = x2 / x1 = (c s + k) / (m s^2 + c s + k)     (= (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2)),

is driven by the control effort u = x1 = u1 + u2, where u1 = C(s) (r - y) is the output of a
continuous feedback controller C (by default seed 000's PID with derivative filter, eq. 13) on
the error between the reference r (the shaped setpoint) and the output y = x2, and u2 is a
feedforward effort (the learned MRILC profile). r and u2 are held over each period (zero-order
hold, as a digital setpoint and a digital feedforward are); the continuous loop is integrated
exactly over each period with the matrix exponential, so nothing depends on a solver step.

What the node publishes for this model: /joint_states position y, velocity y', effort u (the
total control effort, u1 + u2); ~/tip_state y and y'; the accelerometer y'' (the left limit at
the end of the period). ``natural_frequency`` and ``damping_ratio`` are the plant's own mode.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from shaper_nodes.core.lazy import lazy_module
from shaper_nodes.core.learning.mrilc import PAPER_CONTROLLER, MrilcError, controller

if TYPE_CHECKING:
    import control as ct
else:  # imported when a loop is built (plant.model mck_pid), not at every sim plant start
    ct = lazy_module("control")

from .base import PlantBase
from .plants import MckMode, check_rate


class PidLoopPlant(MckMode, PlantBase):
    """Per-joint m-c-k plants, each in the loop of the same controller C (see the module docstring).

    Parameters
    ----------
    mass, damping, stiffness : array_like
        Per joint (kg, N s/m, N/m or their rotational equivalents); mass, stiffness > 0,
        damping >= 0.
    rate : float
        Sample (command) rate, Hz.
    numerator, denominator : sequence of float
        C(s), highest power first; it must stabilise every joint's loop.
    """

    #: a command profile adds to the reference r, an effort profile to the controller output (u2)
    injections: tuple[str, ...] = ("command", "effort")

    def __init__(self, mass, damping, stiffness, rate: float, numerator=PAPER_CONTROLLER[0],
                 denominator=PAPER_CONTROLLER[1]) -> None:
        m, c, k = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (mass, damping, stiffness))
        if not (m.shape == c.shape == k.shape) or not all(np.all(np.isfinite(v)) for v in (m, c, k)):
            raise ValueError("mass, damping, stiffness must be finite and of one size per joint")
        if np.any(m <= 0) or np.any(k <= 0) or np.any(c < 0):
            raise ValueError("plant parameters need mass > 0, stiffness > 0, damping >= 0")
        check_rate(rate)
        try:
            cs = ct.ss(controller(numerator, denominator))
        except MrilcError as err:
            raise ValueError(f"controller: {err}") from None
        self.m, self.c, self.k = m, c, k
        self.rate, self.dt, self.joints = float(rate), 1.0 / float(rate), m.size
        self.numerator, self.denominator = list(numerator), list(denominator)
        loops = [self._loop(ct.ss(ct.tf([ci, ki], [mi, ci, ki])), cs) for mi, ci, ki in zip(m, c, k, strict=True)]
        self._a = np.stack([lp[0] for lp in loops])      # continuous closed loop, per joint
        self._b = np.stack([lp[1] for lp in loops])      # inputs (r, u2)
        self._cy = np.stack([lp[2] for lp in loops])     # y = cy x
        self._cu, self._du = np.stack([lp[3] for lp in loops]), np.stack([lp[4] for lp in loops])  # u
        n = self._a.shape[1]
        phi, gam = [], []
        from scipy.linalg import expm  # on first use: scipy.linalg is 0.2-0.5 s of CPU at a process's start

        for a, b in zip(self._a, self._b, strict=True):
            big = np.zeros((n + 2, n + 2))
            big[:n, :n], big[:n, n:] = a, b
            e = expm(big * self.dt)
            phi.append(e[:n, :n])
            gam.append(e[:n, n:])
        self._phi, self._gam = np.stack(phi), np.stack(gam)
        self.x = np.zeros((self.joints, n))
        self.w = np.zeros((self.joints, 2))   # inputs held over the last period: r, u2
        self.feedforward = np.zeros(self.joints)  # u2 for the next period (set by the node)
        self.cycle_time: float | None = None

    @staticmethod
    def _loop(p: ct.StateSpace, cs: ct.StateSpace):
        ap, bp, cp = p.A, p.B, p.C
        ac, bc, cc, dc = cs.A, cs.B, cs.C, cs.D
        if np.any(np.abs(p.D) > 0):
            raise ValueError("the plant must be strictly proper")
        a = np.block([[ap - bp @ dc @ cp, bp @ cc], [-bc @ cp, ac]])
        b = np.block([[bp @ dc, bp], [bc, np.zeros((ac.shape[0], 1))]])
        if not np.all(np.linalg.eigvals(a).real < 0):
            raise ValueError("the controller does not stabilise the loop for these plant parameters")
        cy = np.hstack([cp, np.zeros((1, ac.shape[0]))])[0]
        cu = np.hstack([-dc @ cp, cc])[0]
        du = np.array([dc[0, 0], 1.0])
        return a, b, cy, cu, du

    # ------------------------------------------------------------------ the common plant interface
    @property
    def state(self) -> np.ndarray:
        return np.hstack([self.x, self.w])

    @state.setter
    def state(self, value) -> None:
        value = np.asarray(value, dtype=float)
        n = self.x.shape[1]
        if value.shape != (self.joints, n + 2):
            raise ValueError("state of another plant model")
        self.x, self.w = value[:, :n].copy(), value[:, n:].copy()

    def reset(self, position) -> None:
        """Every joint at rest at ``position``: y = r = u = position, u2 = 0."""
        p = np.broadcast_to(np.asarray(position, dtype=float), (self.joints,))
        self.w = np.column_stack([p, np.zeros(self.joints)])
        self.x = np.stack([-np.linalg.solve(a, b @ w) for a, b, w in zip(self._a, self._b, self.w, strict=True)])

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        """One period with the reference ``command`` and u2 = ``self.feedforward`` held."""
        r = np.asarray(command, dtype=float).reshape(self.joints)
        self.cycle_time = None if cycle_time is None else float(cycle_time) + self.dt
        self.w = np.column_stack([r, np.asarray(self.feedforward, dtype=float).reshape(self.joints)])
        self.x = np.einsum("jab,jb->ja", self._phi, self.x) + np.einsum("jab,jb->ja", self._gam, self.w)

    def set_effort(self, effort: np.ndarray | None) -> None:
        """u2 of the next period (None: none)."""
        self.feedforward = np.zeros(self.joints) if effort is None else effort

    @property
    def base_position(self) -> np.ndarray:
        """The output y (what the loop measures and /joint_states carries)."""
        return np.einsum("ja,ja->j", self._cy, self.x)

    @property
    def base_velocity(self) -> np.ndarray:
        return np.einsum("ja,jab,jb->j", self._cy, self._a, self.x) + np.einsum(
            "ja,jab,jb->j", self._cy, self._b, self.w)

    tip_position = base_position
    tip_velocity = base_velocity

    @property
    def tip_acceleration(self) -> np.ndarray:
        """y'' at the end of the last period (left limit), with the inputs of that period."""
        ax = np.einsum("jab,jb->ja", self._a, self.x) + np.einsum("jab,jb->ja", self._b, self.w)
        return np.einsum("ja,jab,jb->j", self._cy, self._a, ax)

    @property
    def effort(self) -> np.ndarray:
        """The total control effort u = u1 + u2 at the end of the last period."""
        return np.einsum("ja,ja->j", self._cu, self.x) + np.einsum("ja,ja->j", self._du, self.w)
