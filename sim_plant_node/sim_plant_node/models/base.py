"""The one interface every simulated model implements, free of ROS.

:class:`Plant` is what the sim plant node knows of a model: it steps it, reads its sensors, moves
its state over to another model, and passes it the live changes it takes. The node chooses the model
once (``plant.model``) and dispatches through this interface only, never on the model's kind.
:class:`PlantBase` gives the defaults most models share (a 1-D plant: one accelerometer sample per
step at the tip, no efforts, no loop signals, no live parameters, command feedforward only).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["ImuSample", "Plant", "PlantBase"]

#: one accelerometer (and gyro) sample: stamp s, specific force (x, y, z) m/s^2, angular rate rad/s (None: none)
ImuSample = tuple[float, np.ndarray, np.ndarray | None]


@runtime_checkable
class Plant(Protocol):
    """A simulated model as the sim plant node drives it.

    Traits (fixed for the model)
    ----------------------------
    joint_names : tuple of str or None
        The model's own joints (the arm's six), None: as many as ``joint_names`` gives.
    changes_live : bool
        ``plant.model`` and ``plant.*`` may change while it runs (False: chosen at start-up only).
    trajectory_controller : bool
        Stands behind the joint_trajectory_controller emulation, and (lockstep, at rest) republishes its
        last joint state as a robot's joint_state_broadcaster does.
    gravity_in_imu : bool
        The accelerometer measures gravity too (the residual-vibration measure removes the mean).
    injections : tuple of str
        The feedforward profiles it takes: "command" (added to the setpoint, every model), "effort"
        (added to its controller's output, a model with a controller).
    live_parameters : tuple of str
        The node parameters it takes live through :meth:`prepare` (the arm's payload).
    loop_signals : tuple of str
        The per-joint signals of ``~/loop_state`` in :meth:`loop_state`'s order (empty: none).

    State
    -----
    rate : float
        Command rate, Hz.
    cycle_time : float or None
        s since the current cycle's START at the end of the last step (None: no cycle).
    state : numpy.ndarray
        The model's state; setting it from a model of another layout raises ValueError.
    natural_frequency, damping_ratio : numpy.ndarray
        Its modes (rad/s, 1), per joint.
    """

    joint_names: tuple[str, ...] | None
    changes_live: bool
    trajectory_controller: bool
    gravity_in_imu: bool
    injections: tuple[str, ...]
    live_parameters: tuple[str, ...]
    loop_signals: tuple[str, ...]
    rate: float
    cycle_time: float | None

    @property
    def state(self) -> np.ndarray: ...

    @state.setter
    def state(self, value: np.ndarray) -> None: ...

    @property
    def natural_frequency(self) -> np.ndarray: ...

    @property
    def damping_ratio(self) -> np.ndarray: ...

    # --- a cycle
    def reset(self, position: Any) -> None:
        """At rest at ``position`` (rad or m per joint)."""

    @property
    def setpoint_at_rest(self) -> np.ndarray:
        """The setpoint that holds the model where the last :meth:`reset` put it."""

    def step(self, command: Any, cycle_time: float | None = None, velocity: Any = None) -> None:
        """One command period towards setpoint ``command`` (with its ``velocity`` from a trajectory
        controller, None: none), ``cycle_time`` s after the current cycle's START (None: no cycle)."""

    # --- sensors
    def joint_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """What /joint_states carries: positions, velocities, efforts (None: none)."""

    def tip_state(self) -> tuple[np.ndarray, np.ndarray]:
        """What ``~/tip_state`` carries: tip (link) positions and velocities."""

    def imu(self, t_start: float, t_end: float, axes: Sequence[int]) -> list[ImuSample]:
        """The accelerometer samples of the last step, which ran from ``t_start`` to ``t_end`` s; ``axes``:
        the joint whose tip acceleration each axis x, y, z measures (-1: none), for the models that read
        it so."""

    def loop_state(self) -> np.ndarray | None:
        """The :attr:`loop_signals` after the last step, concatenated (None: the model has none)."""

    # --- changes
    def set_effort(self, effort: np.ndarray | None) -> None:
        """The effort feedforward of the next step (None: none)."""

    def prepare(self, values: Mapping[str, Any]) -> Callable[[], str]:
        """Check the :attr:`live_parameters` ``values`` (all of them; ValueError if refused) and return what
        applies them at the next step (it returns a line for the log)."""


class PlantBase:
    """The defaults of :class:`Plant` for a 1-D model: any joint count, changes live, no controller
    emulation, one accelerometer sample per step from the tip accelerations, no efforts, no loop
    signals, command feedforward only, no live parameters."""

    joint_names: tuple[str, ...] | None = None
    changes_live = True
    trajectory_controller = False
    gravity_in_imu = False
    injections: tuple[str, ...] = ("command",)
    live_parameters: tuple[str, ...] = ()
    loop_signals: tuple[str, ...] = ()

    @property
    def base_position(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def base_velocity(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def tip_position(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def tip_velocity(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def tip_acceleration(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def effort(self) -> np.ndarray | None:
        """The efforts /joint_states carries (None: none)."""
        return None

    @property
    def setpoint_at_rest(self) -> np.ndarray:
        return self.base_position

    def joint_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        return self.base_position, self.base_velocity, self.effort

    def tip_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.tip_position, self.tip_velocity

    def imu(self, t_start: float, t_end: float, axes: Sequence[int]) -> list[ImuSample]:
        acc = self.tip_acceleration
        return [(t_end, np.array([acc[a] if a >= 0 else 0.0 for a in axes]), None)]

    def loop_state(self) -> np.ndarray | None:
        return None

    def set_effort(self, effort: np.ndarray | None) -> None:
        """No controller output to add an effort to: ignored (the node refuses effort profiles for a model
        whose :attr:`injections` lack "effort")."""

    def prepare(self, values: Mapping[str, Any]) -> Callable[[], str]:
        raise ValueError(f"this model takes no live parameters ({', '.join(values)})")
