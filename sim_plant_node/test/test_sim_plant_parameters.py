"""The sim plant node's parameter table against the plants' own checks."""

import math

import pytest

from sim_plant_node.models.loops import LOOP_PARAMS
from sim_plant_node.node.parameters import PARAMETERS, PLANT_KEYS, PLANT_PARAMS

CHECKED = [spec for spec in PARAMETERS if spec.check is not None]


def test_every_parameter_is_in_the_table_once():
    names = [spec.name for spec in PARAMETERS]
    assert len(names) == len(set(names))
    assert set(PLANT_KEYS) <= set(names)
    assert set(PLANT_PARAMS) | set(LOOP_PARAMS) <= {spec.name for spec in CHECKED}


@pytest.mark.parametrize("spec", [s for s in CHECKED if s.default is not None], ids=lambda s: s.name)
def test_the_plants_accept_every_default(spec):
    spec.check(spec.default)


@pytest.mark.parametrize("spec", [s for s in CHECKED if s.range is not None], ids=lambda s: s.name)
def test_the_plants_accept_both_ends_of_every_range(spec):
    for edge in spec.range:
        spec.check(int(edge) if spec.integer else float(edge))


@pytest.mark.parametrize(("name", "value"), [("plant.mass", [0.0]), ("plant.damping", [-1.0]),
                                             ("plant.force_limit", [math.nan]), ("loop.substeps", 0),
                                             ("loop.nominal", [1.0, 0.0]), ("plant.model", "nope"),
                                             ("task.profile", "nope"), ("task.cycles", 0), ("task.levels", [])])
def test_the_checks_refuse_what_the_plants_refuse(name, value):
    spec = next(s for s in PARAMETERS if s.name == name)
    with pytest.raises(ValueError):
        spec.check(value)
