"""The arm's joint_trajectory_controller in the sim plant node (:class:`~.sim_plant.SimPlantNode`'s part).

:meth:`ControllerRuns._start_controller` makes the controller's action server and topic
(:mod:`sim_plant_node.controller`) when the model has one (the arm). In lockstep the node steps while the
controller executes a trajectory and no task runs (:meth:`ControllerRuns._free_run`, ~20 ms of wall time a
call on a 2 ms timer); the timer is off while the controller is idle (until a trajectory comes) and while a
lockstep reader holds the plant (until an acknowledgement lets it step). At rest the last joint state is
published again (:meth:`ControllerRuns._idle_joint_states`), as a robot's joint_state_broadcaster does.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, cast

from ..controller.jtc import JointTrajectoryController
from ..controller.server import ControllerServer, tolerances_from

if TYPE_CHECKING:
    import numpy as np
    from rclpy.node import Node

    from .lockstep import Exchange, Readers
    from .sensors import WriteBatch


class ControllerRuns:
    """The trajectory controller's part of the node (module docstring): a mixin of
    :class:`~.sim_plant.SimPlantNode`, whose attributes and methods it uses are declared below."""

    if TYPE_CHECKING:
        jtc: ControllerServer | None
        task: Any
        plant: Any
        params: Any
        mode: str
        rate: float
        sim_time: float
        joint_names: list[str]
        exchange: Exchange
        readers: Readers
        _applied: np.ndarray
        _batch: WriteBatch
        _free_timer: Any
        _free_idle: bool
        _free_held: bool
        _js_pub: Any
        _last_js: Any

        def _now(self) -> float: ...
        def _integrate(self, command: np.ndarray, velocity: np.ndarray | None = None) -> None: ...
        def _publish_clock(self) -> None: ...
        def create_timer(self, *args: Any, **kwargs: Any) -> Any: ...

    def _start_controller(self, action: str, topic: str) -> None:
        """The controller's action server on ``action`` and its topic ``topic``, if the model has one (the arm);
        in lockstep, its stepping timer."""
        p = self.params.value
        if self.plant.trajectory_controller:
            defaults = tolerances_from(tuple(self.joint_names), list(p.jtc.trajectory_tolerance),
                                       list(p.jtc.goal_tolerance), float(p.jtc.goal_time))
            controller = JointTrajectoryController(tuple(self.joint_names), 1.0 / self.rate, defaults, self._applied)
            self.jtc = ControllerServer(cast("Node", self), controller, self._now,
                                        lambda: self.plant.joint_state()[:2], self._jtc_busy, action, topic,
                                        self._trajectory_taken, before_feedback=self._batch.flush)
            if self.mode == "lockstep":
                self._free_timer = self.create_timer(0.002, self._free_run)

    def _jtc_busy(self) -> str | None:
        if self.task is not None:
            return "a task is running: forward_position_controller drives the joints (~/stop_task first)"
        return None

    def _jtc_step(self) -> None:
        """One controller period and one plant period (arm, no task)."""
        assert self.jtc is not None
        self.jtc.update(self._now())
        c = self.jtc.controller
        self._integrate(c.command, c.command_velocity)

    def _idle_joint_states(self) -> None:
        """Lockstep at rest (no trajectory, no task): publish the last joint state again."""
        if (self.jtc is None or not self.jtc.running) and self.task is None and self.exchange.waiting_since is None:
            self._js_pub.publish(self._last_js)

    def _free_run(self) -> None:
        """Lockstep: step while the controller executes a trajectory (no task runs), ~20 ms of wall time a call."""
        if self.jtc is None:
            return
        if not self.jtc.running:  # nothing to step: off until a trajectory comes (_trajectory_taken)
            self._free_idle = True
            self._free_timer.cancel()
            return
        if self.task is not None or self.exchange.waiting_since is not None:
            return
        deadline = time.monotonic() + 0.02
        try:
            while self.jtc.running and time.monotonic() < deadline:
                if not self.readers.may_step(self.sim_time + 1.0 / self.rate):  # held: resumed by an acknowledgement
                    self._free_held = True
                    self._free_timer.cancel()
                    return
                self._jtc_step()
                self._publish_clock()  # the commanded positions (what "at rest" means)
                self._batch.period()
        finally:
            self._batch.flush()  # (before a hold, the goal's result, the next callback)

    def _trajectory_taken(self) -> None:
        """The controller took a trajectory: its idle timer runs again (lockstep)."""
        if self._free_idle:
            self._free_idle = False
            self._free_timer.reset()
