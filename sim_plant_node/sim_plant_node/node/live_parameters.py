"""Parameters changed while the sim plant node runs (:class:`~.sim_plant.SimPlantNode`'s part): the new values
checked whole, then applied at the next step; a refused change leaves the plant as it was."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter

from shaper_nodes.ros.parameters import flat

from .models import START_ONLY, PlantValues, build_plant
from .parameters import PLANT_KEYS, SimPlantParams

if TYPE_CHECKING:
    from .sensors import Sensors


class LiveParameters:
    """The ``on_set_parameters`` check of the node (module docstring): a mixin of
    :class:`~.sim_plant.SimPlantNode`, whose attributes it uses are declared below."""

    if TYPE_CHECKING:
        plant: Any
        params: Any
        sensors: Sensors
        rate: float
        n: int

        def get_logger(self) -> Any: ...

    def _values(self, params: SimPlantParams) -> PlantValues:
        """``params`` (present or proposed) as the plant's builders read them."""
        return PlantValues(params, self.rate, self.n)

    def _validate_params(self, params: list[Parameter]) -> SetParametersResult:
        changed = {p.name for p in params}
        q = self.params.with_changes(params)  # the parameters as they would be
        if not self.plant.changes_live and changed.intersection(PLANT_KEYS):
            model = self.params.value.plant.model
            return SetParametersResult(successful=False, reason=f"the {model} (plant.model {model}) is chosen at"
                                       " start-up; its model and plant.* do not change live")
        if "plant.model" in changed and q.plant.model in START_ONLY:
            return SetParametersResult(successful=False,
                                       reason=f"plant.model {q.plant.model} is chosen at start-up only")
        live = self.plant.live_parameters
        v = self._values(q)
        try:
            new = build_plant(v, self.n) if changed.intersection(PLANT_KEYS) else None
            for name, pose in (("task.start", q.task.start), ("task.goal", q.task.goal)):
                if name in changed:
                    v.vector(name, pose)
            apply = self.plant.prepare({n: flat(q)[n] for n in live}) if changed.intersection(live) else None
        except ValueError as err:
            return SetParametersResult(successful=False, reason=str(err))
        self.sensors.changed(q.imu, q.joint_states)
        if apply is not None:  # checked above: takes effect at the next step
            self.get_logger().info(apply())
        if new is not None:  # all checks passed: takes effect at the next step
            try:
                new.state = self.plant.state.copy()
            except ValueError:  # another state layout: start the new model at rest where the output is
                new.reset(self.plant.joint_state()[0])
            new.cycle_time = self.plant.cycle_time
            self.plant = new
        return SetParametersResult(successful=True)
