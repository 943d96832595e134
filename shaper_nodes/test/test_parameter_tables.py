"""Every node's parameter table held against the core, and against the example config files.

A node declares its parameters from one table (``PARAMETERS``, :mod:`shaper_nodes.ros.parameters`).
Where the core validates the same value, the entry's ``check`` runs that validation: every value the
node accepts (each edge of its range, its default) must be accepted by the core too, so that a
parameter is never accepted by ``ros2 param set`` or at start-up and then refused deeper down.
"""

from __future__ import annotations

import math
import pathlib

import pytest
import yaml

from shaper_nodes.core.learning.mrilc import DEFAULTS, RANGES
from shaper_nodes.nodes import (
    bag_play,
    calibrate,
    identifier,
    learner,
    learner_list,
    learner_mrilc,
    recorder,
    scheduler,
    shaper,
)
from shaper_nodes.ros.parameters import Spec
from sim_plant_node.node import sim_plant

TABLES = {
    "shaper": shaper.PARAMETERS,
    "identifier": identifier.PARAMETERS,
    "learner": learner.PARAMETERS,
    "learner (list)": learner_list.PARAMETERS,
    "learner (mrilc)": learner_mrilc.PARAMETERS,
    "scheduler": scheduler.PARAMETERS,
    "recorder": recorder.PARAMETERS,
    "bag_play": bag_play.PARAMETERS,
    "sim_plant": sim_plant.PARAMETERS,
    "calibrate": calibrate.PARAMETERS,
}
SPECS = [(table, spec) for table, specs in TABLES.items() for spec in specs]
CONFIG = pathlib.Path(__file__).resolve().parents[1] / "config"
SIM_CONFIG = pathlib.Path(__file__).resolve().parents[2] / "sim_plant_node" / "config"


def _id(item: tuple[str, Spec]) -> str:
    return f"{item[0]}:{item[1].name}"


def edges(spec: Spec) -> list[float]:
    assert spec.range is not None
    lo, hi = spec.range
    return [int(lo), int(hi)] if spec.integer else [float(lo), float(hi)]


@pytest.mark.parametrize("item", [s for s in SPECS if s[1].range is not None and s[1].check], ids=_id)
def test_the_core_accepts_both_edges_of_every_range(item):
    _, spec = item
    for value in edges(spec):
        spec.check(value)  # raises if the core refuses a value the node's range admits


@pytest.mark.parametrize("item", [s for s in SPECS if s[1].check and s[1].default is not None], ids=_id)
def test_the_core_accepts_every_default(item):
    _, spec = item
    spec.check(spec.default)


@pytest.mark.parametrize("item", SPECS, ids=_id)
def test_defaults_lie_in_their_range_and_choices_and_descriptions_say_something(item):
    _, spec = item
    assert spec.description.strip().endswith((".", ")")) and len(spec.description) > 10
    if spec.default is None:
        assert spec.type is not None
        return
    if spec.range is not None:
        lo, hi = spec.range
        assert lo <= spec.default <= hi
        assert isinstance(spec.default, int) == spec.integer
        d = spec.descriptor()
        rng = d.integer_range if spec.integer else d.floating_point_range
        assert (rng[0].from_value, rng[0].to_value) == (lo, hi)
    if spec.choices:
        assert spec.default in spec.choices and spec.refusal(spec.default) is None
        assert "must be one of" in spec.refusal("no such choice")


def test_names_are_unique_within_each_node():
    for table, specs in TABLES.items():
        names = [s.name for s in specs]
        assert len(names) == len(set(names)), table
    for mode in ("learner (list)", "learner (mrilc)"):  # a mode adds to the learner's common table
        assert not {s.name for s in TABLES["learner"]} & {s.name for s in TABLES[mode]}


def test_the_mrilc_table_is_the_cores():
    table = {s.name: s for s in learner_mrilc.PARAMETERS}
    assert list(table) == list(DEFAULTS)
    for name, (lo, hi, integer) in RANGES.items():
        assert table[name].range == (lo, hi) and table[name].integer == integer


def test_the_list_step_limits_start_above_zero_as_the_core_requires():
    """The defect the tables fixed: the node allowed max_step_t2 = 0, which the core refuses."""
    table = {s.name: s for s in learner_list.PARAMETERS}
    for name in ("list.max_step_a1", "list.max_step_t2"):
        with pytest.raises(ValueError):
            table[name].check(0.0)
        assert table[name].range[0] > 0.0


def _flatten(tree: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def config_node(path: pathlib.Path) -> str:
    """The node a shipped config file is for (its file name: the files are keyed '/**')."""
    if path.parent == SIM_CONFIG:
        return "sim_plant"
    return {"mrilc": "learner", "calibrate_quick": "calibrate"}.get(path.stem, path.stem)


@pytest.mark.parametrize("path", sorted(CONFIG.glob("*.yaml")) + sorted(SIM_CONFIG.glob("*.yaml")),
                         ids=lambda p: p.name)
def test_example_configs_set_only_declared_parameters_to_values_the_core_takes(path):
    doc = yaml.safe_load(path.read_text())
    (key, body), = doc.items()
    assert key == "/**", f"{path.name}: keyed {key!r}; '/**' applies to the node whatever it is named"
    node = config_node(path)
    values = _flatten(body["ros__parameters"])
    specs = list(TABLES[node])
    if node == "learner":
        specs += TABLES[f"learner ({values.get('mode', 'list')})"]
    table = {s.name: s for s in specs}
    unknown = [n for n in values if n not in table and not (node == "scheduler" and n.startswith("rules."))]
    assert not unknown, f"{path.name}: not declared by the {node} node: {unknown}"
    for name, value in values.items():
        spec = table.get(name)
        if spec is None:
            continue
        if spec.range is not None:
            assert spec.range[0] <= value <= spec.range[1], name
        assert spec.refusal(value) is None, name
        if spec.check and not (isinstance(value, float) and math.isnan(value)):
            spec.check(value)
