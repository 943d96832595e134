"""The two-mass rigid-flexible system of seed 004 and its staircase task, free of ROS.

TwoMassPlant
    Seed 004, Fig. 2 and eq. (1): a driving mass m0 at x0 and a driven mass m1 at x1 joined by a
    spring k and a damper c, m0 damped to ground by c0, driven by the force f = dv/dt of the
    velocity command v:

        m0 x0'' + c (x0' - x1') + k (x0 - x1) + c0 x0' = f = v',
        m1 x1'' - c (x0' - x1') - k (x0 - x1)       = 0,

    with c = 0.1 kg/s, m0 = 2 kg, c0 = 30 kg/s, k = 1 N/m and the configuration-dependent mass
    m1 = 10 x0 + 1 kg (eq. (2)), which makes the system nonlinear. Because f is the derivative of
    the command, the state is integrated as (x0, w, x1, x1') with w = m0 x0' - v, so the command
    enters without a derivative (a step of v is a jump of x0' by dv / m0, exactly):

        x0' = (w + v) / m0,   w' = -(c + c0) x0' + c x1' - k (x0 - x1),
        x1'' = (c (x0' - x1') + k (x0 - x1)) / m1(x0).

    The command moves linearly between samples (first-order hold, as for the other plants) and
    the state is advanced with classical RK4, SUBSTEP_SPEED bounding h times the fastest rate
    (c0 / m0 = 15 1/s). At rest x0 = x1, and x0 = v / c0 for a constant m1 (the command
    acts as a position setpoint scaled by 1 / c0); as m1 changes with x0 on the way (eq. (1)
    writes m1 x1'', not d(m1 x1')/dt) the rest pose is off by a path-dependent fraction of a
    percent (0.36 m becomes 0.3614 m after seed 004's steps). m1 is kept at least M1_MIN so
    that the model stays defined for x0 below -0.1 m. /joint_states carries x0 and x0' (the
    pose the scheduler sees), the tip state and the accelerometer x1, x1' and x1''.
two_mass_matrices
    (A, B) of eq. (1) for a given m1: the linear model at one operating point.
StaircaseTask
    Seed 004's task: the command steps to each of a list of levels in turn and dwells after
    each step (one cycle per step), as the five velocity steps of Figs. 4, 5 and 7.
"""

from __future__ import annotations

import math

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START

from .base import PlantBase
from .plants import TaskEvent, check_rate

#: seed 004's parameters: c (kg/s), m0 (kg), c0 (kg/s), k (N/m), m1 = M1_SLOPE x0 + M1_OFFSET (kg)
C, M0, C0, K = 0.1, 2.0, 30.0, 1.0
M1_SLOPE, M1_OFFSET = 10.0, 1.0
#: smallest m1 the model uses, kg
M1_MIN = 0.1
#: RK4 substeps per period are chosen so that h * (c0 + c) / m0 stays at or below this
SUBSTEP_SPEED = 0.05


def m1_of(x0):
    """The configuration-dependent mass m1 = 10 x0 + 1 kg (seed 004 eq. (2)), at least M1_MIN."""
    return np.maximum(M1_SLOPE * np.asarray(x0, dtype=float) + M1_OFFSET, M1_MIN)


def two_mass_matrices(m1: float, m0: float = M0, c: float = C, c0: float = C0,
                      k: float = K) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of seed 004 eq. (1), state (x0, x0', x1, x1') in m and m/s, input f = dv/dt in N."""
    if not (m1 > 0 and m0 > 0):
        raise ValueError(f"masses must be > 0 kg, got m0 = {m0}, m1 = {m1}")
    a = np.array([[0.0, 1.0, 0.0, 0.0],
                  [-k / m0, -(c + c0) / m0, k / m0, c / m0],
                  [0.0, 0.0, 0.0, 1.0],
                  [k / m1, c / m1, -k / m1, -c / m1]])
    b = np.array([[0.0], [1.0 / m0], [0.0], [0.0]])
    return a, b


class TwoMassPlant(PlantBase):
    """Seed 004's two-mass system per joint (see the module docstring); the plant interface of
    sim_plant_node.plants (reset, step, base/tip positions, velocities, tip acceleration).

    Parameters
    ----------
    joints : int
        Number of independent two-mass systems.
    rate : float
        Command rate, Hz.
    """

    def __init__(self, joints: int, rate: float) -> None:
        if int(joints) < 1:
            raise ValueError(f"joints must be >= 1, got {joints!r}")
        self.joints = int(joints)
        self.rate = check_rate(rate)
        self.dt = 1.0 / self.rate
        self.substeps = max(1, math.ceil(self.dt * (C + C0) / M0 / SUBSTEP_SPEED))
        # per joint: x0, w = m0 x0' - v, x1, x1', command v at the end of the last period, its slope
        self._state = np.zeros((self.joints, 6))
        self.cycle_time: float | None = None

    @property
    def state(self) -> np.ndarray:
        """Per joint: x0, m0 x0' - v, x1, x1', the command v and its slope over the last period."""
        return self._state

    @state.setter
    def state(self, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=float)
        if value.shape == (self.joints, 6):
            self._state = value.copy()
        else:  # another plant's state (tip, tip velocity, command, slope): rest under its command
            self.reset(value[:, 2])

    # ----------------------------------------------------------------- model
    def _rhs(self, s: np.ndarray, v: np.ndarray) -> np.ndarray:
        x0, w, x1, x1d = s
        x0d = (w + v) / M0
        spring = K * (x0 - x1) + C * (x0d - x1d)
        return np.array([x0d, -C0 * x0d - spring, x1d, spring / m1_of(x0)])

    def reset(self, command) -> None:
        """At rest under the velocity command ``command`` (m/s): both masses at command / c0 (m).

        The sim plant resets a plant to the command it applies, so this takes the command; with
        the task starting from v = 0 (as seed 004's) both are 0.
        """
        v = np.broadcast_to(np.asarray(command, dtype=float), (self.joints,)).copy()
        p = v / C0
        # at rest x0' = 0, so w = -v
        self.state = np.column_stack([p, -v, p, np.zeros(self.joints), v, np.zeros(self.joints)])

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        """Advance one period while the velocity command v moves linearly to ``command`` (m/s)."""
        v1 = np.asarray(command, dtype=float).reshape(self.joints)
        v0 = self.state[:, 4].copy()
        r = (v1 - v0) / self.dt
        s = self.state[:, :4].T.copy()
        h = self.dt / self.substeps
        for i in range(self.substeps):
            t = i * h
            va, vm, vb = v0 + r * t, v0 + r * (t + 0.5 * h), v0 + r * (t + h)
            k1 = self._rhs(s, va)
            k2 = self._rhs(s + 0.5 * h * k1, vm)
            k3 = self._rhs(s + 0.5 * h * k2, vm)
            k4 = self._rhs(s + h * k3, vb)
            s = s + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        self.state = np.column_stack([s.T, v1, r])
        self.cycle_time = None if cycle_time is None else float(cycle_time) + self.dt

    # ----------------------------------------------------------------- outputs
    @property
    def command(self) -> np.ndarray:
        """The velocity command v at the end of the last period, m/s."""
        return self.state[:, 4].copy()

    @property
    def base_position(self) -> np.ndarray:
        """x0, m (what /joint_states carries)."""
        return self.state[:, 0].copy()

    @property
    def base_velocity(self) -> np.ndarray:
        """x0', m/s."""
        return (self.state[:, 1] + self.state[:, 4]) / M0

    @property
    def tip_position(self) -> np.ndarray:
        """x1, m."""
        return self.state[:, 2].copy()

    @property
    def tip_velocity(self) -> np.ndarray:
        """x1', m/s."""
        return self.state[:, 3].copy()

    @property
    def tip_acceleration(self) -> np.ndarray:
        """x1'', m/s^2."""
        return self._rhs(self.state[:, :4].T, self.state[:, 4])[3]

    @property
    def m1(self) -> np.ndarray:
        """The driven mass now, kg."""
        return m1_of(self.state[:, 0])

    def _modes(self) -> list[tuple[float, float]]:
        out = []
        for m1 in self.m1:
            lam = np.linalg.eigvals(two_mass_matrices(float(m1))[0])
            lam = lam[lam.imag > 0][0]
            out.append((float(abs(lam)), float(-lam.real / abs(lam))))
        return out

    @property
    def natural_frequency(self) -> np.ndarray:
        """Undamped natural frequency of the flexible mode of the model linearised at the present m1, rad/s."""
        return np.array([w for w, _ in self._modes()])

    @property
    def damping_ratio(self) -> np.ndarray:
        """Damping ratio of that mode."""
        return np.array([z for _, z in self._modes()])


class StaircaseTask:
    """The command steps to each level in turn and dwells after each step; one cycle per step.

    Parameters
    ----------
    start : array_like
        The command before the first step, one value per joint.
    levels : array_like
        The levels, ``steps * joints`` values (step-major); one value per step is spread over
        all joints.
    dwell : float
        Time at each level, s (the residual-vibration window follows the step).
    rate : float
        Command rate, Hz.
    """

    def __init__(self, start, levels, dwell: float, rate: float) -> None:
        self.start = np.asarray(start, dtype=float).ravel()
        n = self.start.size
        lv = np.asarray(levels, dtype=float).ravel()
        if lv.size == 0 or not np.all(np.isfinite(lv)):
            raise ValueError(f"task.levels must be finite values, at least one, got {lv.tolist()}")
        if lv.size % n and n > 1:
            raise ValueError(f"task.levels needs a multiple of {n} values (one per joint per step), got {lv.size}")
        self.levels = lv.reshape(-1, n) if lv.size % n == 0 else np.repeat(lv[:, None], n, axis=1)
        if not (dwell > 0 and rate > 0):
            raise ValueError("a staircase task needs dwell > 0 s and rate > 0 Hz")
        self.rate = float(rate)
        self.cycles = self.levels.shape[0]
        self.samples_per_cycle = max(2, int(round(dwell * rate)))
        self.move_duration = 0.0
        self.goal = self.levels[-1]
        self.index = 0

    @property
    def done(self) -> bool:
        return self.index >= self.cycles * self.samples_per_cycle

    def pose(self, cycle: int) -> tuple[np.ndarray, np.ndarray]:
        """(level before, level after) the step of a cycle."""
        return (self.start if cycle == 0 else self.levels[cycle - 1]), self.levels[cycle]

    def step(self) -> tuple[np.ndarray, list[TaskEvent]]:
        """The command for the next sample and the events at it."""
        if self.done:
            raise RuntimeError("task is done")
        cycle, k = divmod(self.index, self.samples_per_cycle)
        a, b = self.pose(cycle)
        events = []
        if k == 0:
            events += [TaskEvent(START, cycle, a, b), TaskEvent(MOTION_END, cycle, a, b)]
        if k == self.samples_per_cycle - 1:
            events.append(TaskEvent(END, cycle, a, b))
        self.index += 1
        return b.copy(), events


#: seed 004's task: five velocity steps. The paper gives the mode parameters at the first and
#: fifth steps as those of m1 = 1.2 kg and 8 kg (eq. (9)), i.e. x0 = 0.02 m and 0.7 m; the three
#: steps between are spaced evenly (0.17 m), so the switch of eq. (9) at 0.35 m falls halfway.
STEP_POSES = (0.02, 0.19, 0.36, 0.53, 0.70)
#: the velocity levels that put x0 at STEP_POSES at rest (x0 = v / c0), m/s
STEP_LEVELS = tuple(C0 * x for x in STEP_POSES)
