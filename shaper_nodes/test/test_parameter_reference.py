"""The typed parameter classes and the generated reference docs/reference/parameters.md.

Each node writes its parameters once, as a parameter class (:mod:`shaper_nodes.ros.parameters`):
the node declares its table from it, reads it as a typed object (refreshed on change), and the
reference is generated from the tables. The reference must match the declarations.
"""

from __future__ import annotations

import dataclasses

import pytest
import rclpy
from parameter_decls import generator
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from shaper_nodes.nodes import bag_play, calibrate, identifier, learner, learner_list, recorder, scheduler, shaper
from shaper_nodes.ros.parameters import Live, declare, flat, param, read, table, unflat
from sim_plant_node.node import parameters as sim_plant

CLASSES = [(identifier, identifier.IdentifierParams), (learner, learner.LearnerParams),
           (learner_list, learner_list.ListModeParams), (scheduler, scheduler.SchedulerParams),
           (recorder, recorder.RecorderParams), (bag_play, bag_play.BagPlayParams),
           (calibrate, calibrate.CalibrateParams), (shaper, shaper.ShaperParams),
           (sim_plant, sim_plant.SimPlantParams)]


def test_the_generated_reference_matches_the_declarations():
    gen = generator()
    have = gen.TARGET.read_text(encoding="utf-8")
    assert have == gen.generate(), (
        f"{gen.TARGET.relative_to(gen.ROOT)} differs from the parameter declarations: regenerate it with"
        " `./run exec python scripts/parameters_doc.py` (check with --check)")


def test_the_reference_has_a_row_for_every_parameter_of_every_executable():
    gen = generator()
    text = gen.TARGET.read_text(encoding="utf-8")
    for name, _, tables in gen.sections():
        assert f"\n## {name}\n" in text
        for _, specs in tables:
            for spec in specs:
                assert f"| `{spec.name}` |" in text, spec.name


@pytest.mark.parametrize(("module", "cls"), CLASSES, ids=[c.__name__ for _, c in CLASSES])
def test_each_node_table_is_its_class(module, cls):
    assert table(cls) == module.PARAMETERS
    assert len({s.name for s in table(cls)}) == len(table(cls))


@pytest.mark.parametrize(("module", "cls"), CLASSES, ids=[c.__name__ for _, c in CLASSES])
def test_a_class_built_without_a_node_holds_the_declared_defaults(module, cls):
    values = flat(cls())
    assert list(values) == [s.name for s in module.PARAMETERS]
    for spec in module.PARAMETERS:
        assert values[spec.name] == spec.initial, spec.name
    assert unflat(cls, values) == cls()
    assert unflat(cls, {}) == cls()


def test_a_class_field_without_param_is_refused():
    @dataclasses.dataclass(frozen=True)
    class Bad:
        x: int = 3

    with pytest.raises(TypeError, match=r"Bad\.x"):
        table(Bad)


@dataclasses.dataclass(frozen=True)
class _Gains:
    kp: float = param(1.0, "Proportional gain.", (0.0, 10.0))
    names: tuple[str, ...] = param(None, "Joints.", read_only=True, type=Parameter.Type.STRING_ARRAY)


@dataclasses.dataclass(frozen=True)
class _Probe:
    rate: float = param(100.0, "Rate, Hz.", (1.0, 1000.0), read_only=True)
    mode: str = param("a", "Mode.", choices=("a", "b"))
    lam: float = param(0.5, "A keyword as a name.", name="lambda")
    gains: _Gains = dataclasses.field(default_factory=_Gains)


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_declare_reads_typed_values_and_follows_changes(context):
    node = Node("probe", context=context, parameter_overrides=[
        Parameter("rate", value=250), Parameter("gains.names", value=["j1", "j2"])])
    try:
        live: Live[_Probe] = declare(node, _Probe)
        p = live.value
        assert p == _Probe(rate=250.0, gains=_Gains(names=("j1", "j2")))
        assert isinstance(p.rate, float) and p.gains.kp == 1.0 and p.lam == 0.5
        assert node.get_parameter("lambda").value == 0.5
        assert node.describe_parameter("rate").floating_point_range[0].to_value == 1000.0
        # a change (an integer for a double, as ros2 param set sends it) is read again
        assert node.set_parameters([Parameter("gains.kp", value=3)])[0].successful
        assert live.value.gains.kp == 3.0 and p.gains.kp == 1.0  # the earlier object is not changed
        # refused changes leave the typed object as it was
        assert not node.set_parameters([Parameter("mode", value="c")])[0].successful
        assert not node.set_parameters([Parameter("gains.kp", value=11.0)])[0].successful
        assert not node.set_parameters([Parameter("rate", value=200.0)])[0].successful
        assert live.value == _Probe(rate=250.0, gains=_Gains(kp=3.0, names=("j1", "j2")))
        assert read(node, _Gains, "gains.") == live.value.gains
    finally:
        node.destroy_node()


def test_an_empty_array_is_read_as_an_empty_tuple(context):
    node = Node("probe", context=context)
    try:
        live = declare(node, _Probe)
        assert live.value.gains.names == () and node.get_parameter("gains.names").value == []
    finally:
        node.destroy_node()


def test_a_post_set_callback_added_after_declare_reads_the_new_values_after_refresh(context):
    node = Node("probe", context=context)
    try:
        live = declare(node, _Probe)
        seen = []
        node.add_post_set_parameters_callback(lambda params: seen.append(live.refresh().gains.kp))
        assert node.set_parameters([Parameter("gains.kp", value=2.5)])[0].successful
        assert seen == [2.5] and live.value.gains.kp == 2.5
    finally:
        node.destroy_node()


def test_with_changes_shows_proposed_values_without_taking_them(context):
    node = Node("probe", context=context)
    try:
        live = declare(node, _Probe)
        proposed = live.with_changes([Parameter("gains.kp", value=4.0), Parameter("mode", value="b"),
                                      Parameter("elsewhere", value=1)])
        assert proposed == _Probe(mode="b", gains=_Gains(kp=4.0)) and live.value == _Probe()
    finally:
        node.destroy_node()
