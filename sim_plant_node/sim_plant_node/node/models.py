"""``plant.model`` to the :class:`~sim_plant_node.models.base.Plant` it names, built from the node's parameters.

Each model has one builder in :data:`BUILDERS`; the node calls :func:`build_plant` at start-up and when
a ``plant.*`` parameter changes (with the proposed values, :meth:`~shaper_nodes.ros.parameters.Live.with_changes`),
and from then on knows the model through the Plant interface only. The builders read the typed parameters
(:class:`~.parameters.SimPlantParams`) through :class:`PlantValues`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from shaper_nodes.ros.parameters import flat, read, unflat

from ..arm.description import ArmSpec
from ..models.base import Plant
from ..models.loops import LOOP_MODELS, make_loop_plant
from ..models.pid_loop import PidLoopPlant
from ..models.plants import PLANT_MODELS, CycleTask, make_plant
from ..models.two_mass import StaircaseTask, TwoMassPlant
from .parameters import PLANT_PARAMS, SimPlantParams, check_model

__all__ = ["BUILDERS", "START_ONLY", "NodeValues", "PlantValues", "build_plant", "make_task"]

#: the models chosen at start-up only (a live change to them is refused)
START_ONLY = ("arm",)


class PlantValues:
    """What a builder reads: the node's typed parameters (proposed ones during a change), its rate and joint count.

    Parameters
    ----------
    params : SimPlantParams
        The parameters.
    rate : float
        The node's rate, Hz (read-only ``rate``).
    joints : int
        The joint count (per-joint values given as one value are spread over it).
    """

    def __init__(self, params: SimPlantParams, rate: float, joints: int) -> None:
        self.params, self.rate, self.joints = params, float(rate), joints

    def vector(self, name: str, value: Sequence[float], allow_inf: bool = False) -> np.ndarray:
        """``value`` (of parameter ``name``, for the message) as one value per joint (one value given: for all),
        checked finite (or infinite, with ``allow_inf``); ValueError otherwise."""
        n = self.joints
        v = np.asarray(value, dtype=float).ravel()
        if v.size == 1:
            v = np.full(n, v[0])
        finite = np.isfinite(v) | (allow_inf & np.isinf(v))
        if v.size != n or not np.all(finite):
            kind = "" if allow_inf else "finite "
            raise ValueError(f"{name} needs 1 or {n} {kind}values, got {v.tolist()}")
        return v

    def plant_vectors(self) -> tuple[np.ndarray, ...]:
        """The per-joint plant values of :data:`~.parameters.PLANT_PARAMS`, in that order, all checked
        (``plant.force_limit`` may be infinite)."""
        pl = self.params.plant
        given = (pl.mass, pl.damping, pl.stiffness, pl.stiffness_cubic, pl.gain, pl.force_limit)
        return tuple(self.vector(name, value, name == "plant.force_limit")
                     for name, value in zip(PLANT_PARAMS, given, strict=True))


class NodeValues(PlantValues):
    """The :class:`PlantValues` of an object read as a node is (``get_parameter``, ``rate``, ``n``), with
    ``changes`` (parameter name -> value) over its present values: for a caller that holds a node, not its
    typed parameters."""

    def __init__(self, node: Any, changes: Mapping[str, Any]) -> None:
        super().__init__(unflat(SimPlantParams, {**flat(read(node, SimPlantParams)), **changes}), node.rate, node.n)


def _two_mass(model: str, v: PlantValues, joints: int) -> Plant:
    """Seed 004's two-mass system, m1 = 10 x0 + 1 (models/two_mass.py)."""
    return TwoMassPlant(joints, v.rate)


def _arm(model: str, v: PlantValues, joints: int) -> Plant:
    # on first use: Pinocchio is 0.1-0.3 s of CPU at the start of a plant that is not the arm
    from ..arm.dynamics import ArmModel
    from ..arm.plant import ArmPlant

    arm = v.params.arm
    spec = ArmSpec(payload_mass=float(arm.payload_mass), payload_offset=float(arm.payload_offset))
    return ArmPlant(v.rate, int(arm.substeps), ArmModel(spec))


def _loop(model: str, v: PlantValues, joints: int) -> Plant:
    m, c, k, *_ = v.plant_vectors()  # (all checked)
    return make_loop_plant(model, m, c, k, v.rate, {f"loop.{key}": value for key, value in flat(v.params.loop).items()})


def _open(model: str, v: PlantValues, joints: int) -> Plant:
    """The open-loop 1-D plants: mck and the LIST cases; and mck_pid, the mck plant in C(s)'s loop."""
    m, c, k, k3, kp, f_max = v.plant_vectors()
    try:
        plant = make_plant("mck" if model == "mck_pid" else model, m, c, k, v.rate, stiffness_cubic=k3,
                           gain=kp, force_limit=f_max)
    except ValueError as err:
        raise ValueError(f"plant.{err}") from None  # the plant names its argument first
    if model != "mck_pid":
        return plant
    ctl = v.params.controller
    return PidLoopPlant(m, c, k, v.rate, list(ctl.numerator), list(ctl.denominator))


#: plant.model -> its builder (model name, the parameters, the joint count)
BUILDERS: dict[str, Callable[[str, PlantValues, int], Plant]] = {
    **{name: _open for name in (*PLANT_MODELS, "mck_pid")},
    **{name: _loop for name in LOOP_MODELS},
    "two_mass": _two_mass,
    "arm": _arm,
}


def build_plant(v: PlantValues, joints: int) -> Plant:
    """The model ``plant.model`` names (checked: ValueError), for ``joints`` joints."""
    model = check_model(str(v.params.plant.model))
    return BUILDERS[model](model, v, joints)


def make_task(v: PlantValues, rate: float) -> CycleTask | StaircaseTask:
    """The task the ``task.*`` parameters describe: a staircase (seed 004) when task.levels is set, else
    moves (ValueError if they do not make one)."""
    t = v.params.task
    task = CycleTask(v.vector("task.start", t.start), v.vector("task.goal", t.goal), float(t.max_velocity),
                     float(t.max_acceleration), float(t.dwell), rate, int(t.cycles), str(t.profile), bool(t.round_trip))
    if len(t.levels):  # empty (the default): not set
        return StaircaseTask(v.vector("task.start", t.start), t.levels, float(t.dwell), rate)
    return task
