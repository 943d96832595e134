"""The arm as one of the simulated plant node's models (``plant.model: arm``), free of ROS.

:class:`ArmPlant` gives the node what every plant gives (``step``, ``reset``, ``base_position``
and ``base_velocity`` for ``/joint_states``, ``tip_position``/``tip_velocity``, the modes) and
what only the arm has: the flange IMU sampled at every physics step (``imu_samples``), the
motor torques (``effort``) and the flange position.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..models.base import ImuSample, PlantBase
from .description import JOINT_NAMES, check_payload
from .dynamics import ArmModel, ElasticArm
from .modal import modes


class ArmPlant(PlantBase):
    """The elastic-joint arm stepped at ``rate`` Hz, ``substeps`` physics steps per period.

    Parameters
    ----------
    rate : float
        Command (controller update) rate, Hz.
    substeps : int
        Physics steps per command period (the IMU's rate is rate x substeps).
    model : ArmModel, optional
        The arm (default: the UR5e-based arm of :mod:`.description`).

    As a :class:`~sim_plant_node.models.base.Plant`: its six joints, chosen at start-up, behind the
    joint_trajectory_controller emulation, the IMU's specific force with gravity, the payload live.
    """

    joint_names: tuple[str, ...] | None = JOINT_NAMES
    changes_live = False
    trajectory_controller = True
    gravity_in_imu = True
    live_parameters: tuple[str, ...] = ("arm.payload_mass", "arm.payload_offset")

    def __init__(self, rate: float, substeps: int = 2, model: ArmModel | None = None) -> None:
        if not (isinstance(substeps, int) and 1 <= substeps <= 100):
            raise ValueError(f"arm.substeps must be an integer in [1, 100], got {substeps!r}")
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be finite and > 0 Hz, got {rate!r}")
        self.rate = rate
        self.model = model or ArmModel()
        self.n = self.model.n
        self.substeps = substeps
        self.arm = ElasticArm(self.model, 1.0 / (rate * substeps))
        self.cycle_time: float | None = None
        self.imu_samples: list[tuple[float, np.ndarray, np.ndarray]] = []  # (time since reset s, f m/s^2, w rad/s)
        self._modes = modes(self.model, np.zeros(self.n))
        self._rest = np.zeros(self.n)  # the setpoint of the last reset

    def reset(self, position) -> None:
        """At rest holding ``position`` (rad); the modes are those of that pose."""
        p = np.asarray(position, dtype=float)
        self._rest = p.copy()
        self.arm.reset(p)
        self._modes = modes(self.model, p)

    def set_payload(self, mass: float, offset: float | None = None) -> None:
        """Change the payload at the flange: ``mass`` kg, centre of mass ``offset`` m along the flange's z
        (default unchanged). The inertia and the controller's gravity feedforward follow at once; the modes
        are those at the present setpoint with the new payload; the state is kept (the arm swings under the
        new load from the next step on). Raises ValueError for a payload out of range (nothing changes)."""
        self.model.set_payload(mass, offset)
        self.arm.model_changed()
        self._modes = modes(self.model, self.arm.setpoint)

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        """One command period holding the position setpoint ``command`` (rad), velocity ``velocity`` (rad/s)."""
        arm = self.arm
        drive = arm.hold(command, velocity)  # (one setpoint for the period's physics steps: taken once)
        samples = []
        for _ in range(self.substeps):
            arm.advance(*drive)
            f, w = arm.imu()
            samples.append((arm.time, f, w))
        self.imu_samples = samples

    def prepare(self, values: Mapping[str, Any]) -> Callable[[], str]:
        """Check the payload ``values`` (``arm.payload_mass`` kg, ``arm.payload_offset`` m; ValueError if out of
        range); what it returns applies it (:meth:`set_payload`) and tells the modes it gives."""
        mass, offset = float(values["arm.payload_mass"]), float(values["arm.payload_offset"])
        check_payload(mass, offset)

        def apply() -> str:
            self.set_payload(mass, offset)
            return f"payload {mass:g} kg at {offset:g} m: modes at the present pose now " + ", ".join(
                f"{w / (2 * math.pi):.4g} Hz zeta {z:.3g}" for w, z in zip(
                    self.natural_frequency[:3], self.damping_ratio[:3], strict=True))
        return apply

    @property
    def state(self) -> np.ndarray:
        """Positions and velocities of the links and motors (no other model takes them)."""
        return self.arm.state_copy()

    @state.setter
    def state(self, value: np.ndarray) -> None:
        raise ValueError("the arm's state is its own")

    @property
    def setpoint_at_rest(self) -> np.ndarray:
        """The setpoint of the last :meth:`reset` (the motors sit off it under gravity)."""
        return self._rest.copy()

    def imu(self, t_start: float, t_end: float, axes: Sequence[int]) -> list[ImuSample]:
        """The flange IMU at every physics step of the last period, stamped from ``t_start`` (``axes``: unused,
        the flange's three axes)."""
        last = self.imu_samples[-1][0]
        return [(t_start + t_sub - last + 1.0 / self.rate, f, w) for t_sub, f, w in self.imu_samples]

    @property
    def base_position(self) -> np.ndarray:
        """Motor-side joint positions, rad (what the encoders report)."""
        return self.arm.motor_position.copy()

    @property
    def base_velocity(self) -> np.ndarray:
        return self.arm.motor_velocity.copy()

    @property
    def effort(self) -> np.ndarray:
        """Motor torques, N m."""
        return self.arm.torque.copy()

    @property
    def tip_position(self) -> np.ndarray:
        """Link angles, rad (after the springs)."""
        return self.arm.q.copy()

    @property
    def tip_velocity(self) -> np.ndarray:
        return self.arm.v.copy()

    def joint_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Motor positions and velocities and the motor torques (:attr:`base_position`, :attr:`base_velocity`,
        :attr:`effort`), read once per period by the controller and once by /joint_states: without the properties'
        chains of slices."""
        position, velocity = self.arm.motor_state()
        return position, velocity, self.arm.torque.copy()

    def tip_state(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`tip_position` and :attr:`tip_velocity` (as :meth:`joint_state`)."""
        return self.arm.link_state()

    @property
    def tip_acceleration(self) -> np.ndarray:
        """The last IMU specific force (x, y, z of the flange, m/s^2), padded to the joint count."""
        f = self.imu_samples[-1][1] if self.imu_samples else np.zeros(3)
        return np.concatenate([f, np.zeros(max(self.n - 3, 0))])

    @property
    def natural_frequency(self) -> np.ndarray:
        """The n lowest modes at the last reset pose (or payload change), rad/s."""
        return np.array([m.omega for m in self._modes[:self.n]])

    @property
    def damping_ratio(self) -> np.ndarray:
        return np.array([m.zeta for m in self._modes[:self.n]])

    def tool_position(self) -> np.ndarray:
        """The flange's position, m."""
        return self.arm.tool_position()
