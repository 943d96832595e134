"""``plant.model`` to the :class:`~sim_plant_node.models.base.Plant` it names, built from the node's parameters.

Each model has one builder in :data:`BUILDERS`; the node calls :func:`build_plant` at start-up and when
a ``plant.*`` parameter changes, and from then on knows the model through the Plant interface only.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..arm.description import ArmSpec
from ..arm.dynamics import ArmModel
from ..arm.plant import ArmPlant
from ..models.base import Plant
from ..models.loops import LOOP_MODELS, LOOP_PARAMS, make_loop_plant
from ..models.pid_loop import PidLoopPlant
from ..models.plants import PLANT_MODELS, CycleTask, make_plant
from ..models.two_mass import StaircaseTask, TwoMassPlant
from .parameters import PLANT_PARAMS, check_model

__all__ = ["BUILDERS", "START_ONLY", "NodeValues", "Values", "build_plant", "make_task"]

#: the models chosen at start-up only (a live change to them is refused)
START_ONLY = ("arm",)


class Values(Protocol):
    """How a builder reads the node's parameters (a parameter change's values first)."""

    rate: float

    def value(self, name: str) -> Any:
        """The value of parameter ``name``."""

    def vector(self, name: str, allow_inf: bool = False) -> np.ndarray:
        """Parameter ``name`` as one value per joint (one value given: for all), checked finite."""


def _two_mass(model: str, v: Values, joints: int) -> Plant:
    """Seed 004's two-mass system, m1 = 10 x0 + 1 (models/two_mass.py)."""
    return TwoMassPlant(joints, v.rate)


def _arm(model: str, v: Values, joints: int) -> Plant:
    spec = ArmSpec(payload_mass=float(v.value("arm.payload_mass")),
                   payload_offset=float(v.value("arm.payload_offset")))
    return ArmPlant(v.rate, int(v.value("arm.substeps")), ArmModel(spec))


def _loop(model: str, v: Values, joints: int) -> Plant:
    m, c, k, *_ = (v.vector(p, p == "plant.force_limit") for p in PLANT_PARAMS)  # (all checked)
    return make_loop_plant(model, m, c, k, v.rate, {p: v.value(p) for p in LOOP_PARAMS})


def _open(model: str, v: Values, joints: int) -> Plant:
    """The open-loop 1-D plants: mck and the LIST cases; and mck_pid, the mck plant in C(s)'s loop."""
    m, c, k, k3, kp, f_max = (v.vector(p, p == "plant.force_limit") for p in PLANT_PARAMS)
    try:
        plant = make_plant("mck" if model == "mck_pid" else model, m, c, k, v.rate, stiffness_cubic=k3,
                           gain=kp, force_limit=f_max)
    except ValueError as err:
        raise ValueError(f"plant.{err}") from None  # the plant names its argument first
    if model != "mck_pid":
        return plant
    return PidLoopPlant(m, c, k, v.rate, list(v.value("controller.numerator")),
                        list(v.value("controller.denominator")))


#: plant.model -> its builder (model name, the parameters, the joint count)
BUILDERS: dict[str, Callable[[str, Values, int], Plant]] = {
    **{name: _open for name in (*PLANT_MODELS, "mck_pid")},
    **{name: _loop for name in LOOP_MODELS},
    "two_mass": _two_mass,
    "arm": _arm,
}


def build_plant(v: Values, joints: int) -> Plant:
    """The model ``plant.model`` names (checked: ValueError), for ``joints`` joints."""
    model = check_model(str(v.value("plant.model")))
    return BUILDERS[model](model, v, joints)


class NodeValues:
    """The sim plant node's parameters as :func:`build_plant` reads them: ``changes`` (a parameter change's
    values) first, the present values otherwise (the node's ``get_parameter`` and ``_vector``)."""

    def __init__(self, node: Any, changes: dict) -> None:
        self.rate = float(node.rate)
        self._node, self._changes = node, changes

    def value(self, name: str) -> Any:
        return self._changes.get(name, self._node.get_parameter(name).value)

    def vector(self, name: str, allow_inf: bool = False) -> np.ndarray:
        n = self._node.n
        v = np.asarray(self.value(name), dtype=float).ravel()
        if v.size == 1:
            v = np.full(n, v[0])
        finite = np.isfinite(v) | (allow_inf & np.isinf(v))
        if v.size != n or not np.all(finite):
            kind = "" if allow_inf else "finite "
            raise ValueError(f"{name} needs 1 or {n} {kind}values, got {v.tolist()}")
        return v


def make_task(v: Values, rate: float) -> CycleTask | StaircaseTask:
    """The task the ``task.*`` parameters describe: a staircase (seed 004) when task.levels is set, else
    moves (ValueError if they do not make one)."""
    task = CycleTask(v.vector("task.start"), v.vector("task.goal"), float(v.value("task.max_velocity")),
                     float(v.value("task.max_acceleration")), float(v.value("task.dwell")), rate,
                     int(v.value("task.cycles")), str(v.value("task.profile")), bool(v.value("task.round_trip")))
    if len(v.value("task.levels")):  # empty (the default): not set
        return StaircaseTask(v.vector("task.start"), v.value("task.levels"), float(v.value("task.dwell")), rate)
    return task
