"""The arm and its joint_trajectory_controller emulation in one process, without ROS.

What the sim plant node does in lockstep for a FollowJointTrajectory goal, as a function call:
the controller (:mod:`.jtc`) takes the trajectory at its next update, samples it every period
and the arm (:mod:`.plant`) integrates under it; every IMU sample, commanded position and link
angle is kept. For reproductions and tests that need many runs fast and noise-free (the node
over DDS is measured by the integration tests and the demo).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..controller.jtc import JointTrajectoryController, RawPoint, Tolerances
from .description import JOINT_NAMES
from .dynamics import ArmModel
from .plant import ArmPlant


@dataclass
class Record:
    """Everything sampled during runs: times s, IMU specific force (N, 3) m/s^2, commands and link angles (N, 6)."""

    imu_t: list[float] = field(default_factory=list)
    imu: list[np.ndarray] = field(default_factory=list)
    cmd_t: list[float] = field(default_factory=list)
    cmd: list[np.ndarray] = field(default_factory=list)
    link_t: list[float] = field(default_factory=list)
    link: list[np.ndarray] = field(default_factory=list)
    #: the arm's state (links, motors: positions then velocities, (2 n + 2 n,)) after each period, when kept
    state_t: list[float] = field(default_factory=list)
    state: list[np.ndarray] = field(default_factory=list)

    def window(self, which: str, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Samples in [t0, t1) (commands, stamped at their period's start) or (t0, t1] (the others), by
        :func:`.metrics.in_window`'s rule."""
        from .metrics import in_window

        t = np.asarray(getattr(self, which + "_t"))
        v = np.asarray(getattr(self, which))
        sel = in_window(t, t0, t1, "left" if which == "cmd" else "right")
        return t[sel], v[sel]


class OfflineArm:
    """The arm at ``rate`` Hz holding ``start``; :meth:`run` executes one trajectory goal.

    ``model`` (default: the arm of :mod:`.description`) lets a run use another arm, e.g. the same arm with
    its flexibility removed (:func:`.dynamics.rigid_model`); ``states`` keeps the arm's state after every
    period in the record (``state_t``, ``state``).
    """

    def __init__(self, start: Sequence[float] | np.ndarray, rate: float = 500.0, substeps: int = 2,
                 noise: float = 0.0, seed: int = 0, model: ArmModel | None = None,
                 states: bool = False) -> None:
        self.rate = float(rate)
        self.plant = ArmPlant(rate, substeps, model)
        self.plant.reset(np.asarray(start, dtype=float))
        free = Tolerances(np.zeros(6), np.zeros(6))
        self.controller = JointTrajectoryController(JOINT_NAMES, 1.0 / rate, free, np.asarray(start, dtype=float))
        self.time = 0.0
        self.noise = float(noise)
        self._rng = np.random.default_rng(seed)
        self.record = Record()
        self.states = bool(states)

    def run(self, times: Sequence[float] | np.ndarray, positions: np.ndarray, velocities: np.ndarray | None = None,
            accelerations: np.ndarray | None = None) -> float:
        """Execute a trajectory (waypoint times from its start, s; (N, 6) fields) to its end; returns its start."""
        pos = np.asarray(positions, dtype=float)
        vel = None if velocities is None else np.asarray(velocities, dtype=float)
        acc = None if accelerations is None else np.asarray(accelerations, dtype=float)
        points = [RawPoint(float(t), pos[i].tolist(), [] if vel is None else vel[i].tolist(),
                           [] if acc is None else acc[i].tolist()) for i, t in enumerate(times)]
        c = self.controller
        c.accept(list(JOINT_NAMES), points, 0.0)
        c.start_goal(c.defaults)
        start = self.time
        end = start + float(times[-1])
        while self.time < end - 1e-9:
            c.update(self.time, self.plant.base_position, self.plant.base_velocity)
            self.record.cmd_t.append(self.time)
            self.record.cmd.append(c.command.copy())
            self.plant.step(c.command, velocity=c.command_velocity)
            t0 = self.time
            self.time = t0 + 1.0 / self.rate
            for t_sub, force, _ in self.plant.imu_samples:
                noisy = force + (self.noise * self._rng.standard_normal(3) if self.noise > 0 else 0.0)
                self.record.imu_t.append(t0 + t_sub - self.plant.imu_samples[-1][0] + 1.0 / self.rate)
                self.record.imu.append(noisy)
            self.record.link_t.append(self.time)
            self.record.link.append(self.plant.tip_position.copy())
            if self.states:
                self.record.state_t.append(self.time)
                self.record.state.append(self.plant.state)
        c.end_goal()
        return start
