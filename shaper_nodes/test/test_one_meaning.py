"""One meaning per parameter and per path (issue 32, finding 5), without DDS: the one check every path
that sets the shaper makes, the refusal of a setting that cannot take effect, a params file that cannot
be used, an empty array as a params file gives it, and modes in Hz on the messages."""

from __future__ import annotations

import math

import pytest
import yaml
from rclpy.parameter import Parameter

from shaper_nodes.core.shaping import Mode, ShaperError, design
from shaper_nodes.core.shaping.policy import FREQUENCY_RANGE_HZ, PolicyError, UpdatePolicy, check_design
from shaper_nodes.nodes.shaper_parameters import (
    DesignParams,
    ShaperParams,
    design_from_params,
    displacement,
    ineffective,
)
from shaper_nodes.ros.node_main import params_file_keys_hint, params_file_problem, params_files
from shaper_nodes.ros.parameters import Spec

RATE = 500.0  # Hz: designs must lie below 125 Hz
POLICY = UpdatePolicy.of(["parameters", "service", "user", "scheduler"])


def params(**design: object) -> ShaperParams:
    return ShaperParams(joint_names=("a",), shaper=DesignParams(**design))  # type: ignore[arg-type]


# --- one check for parameters and set_shaper ----------------------------------------------------------


@pytest.mark.parametrize("hz", [159.0, 126.0])
def test_a_mode_the_parameters_refuse_is_refused_on_the_service_path_with_the_same_words(hz):
    """The issue's case: `set_shaper` took 159 Hz at 500 Hz, which the parameters refuse."""
    with pytest.raises(ShaperError) as by_params:
        design_from_params(params(family="zv", frequency_hz=hz), RATE)
    with pytest.raises(ShaperError) as by_service:  # the shaper node's request(): policy.decide
        POLICY.decide("service", design("zv", [Mode.from_hz(hz, 0.05)]), RATE, [0])
    assert f"{hz:g} Hz is too high for command_rate 500 Hz (must be below rate / 4 = 125 Hz)" in str(by_params.value)
    tail = str(by_params.value)[str(by_params.value).index(f"{hz:g} Hz"):]
    assert str(by_service.value) == f"design mode {tail}"  # the same check, the same words
    assert str(by_params.value).startswith("shaper.frequency_hz ")  # the parameter is named


def test_a_mode_below_rate_over_4_passes_both_paths():
    shaper, _ = design_from_params(params(family="zv", frequency_hz=124.0), RATE)
    assert POLICY.decide("service", shaper, RATE, [0]) == "switch"
    check_design(design("zv", [Mode.from_hz(124.0, 0.05)]), RATE)


def test_several_modes_are_checked_one_by_one_and_named():
    with pytest.raises(ShaperError, match=r"shaper.frequencies_hz 130 Hz is too high"):
        design_from_params(params(family="zv", frequencies_hz=(10.0, 130.0), damping_ratios=(0.05, 0.05)), RATE)
    with pytest.raises(ShaperError, match=r"design mode 130 Hz is too high"):
        check_design(design("zv", [Mode.from_hz(10.0, 0.05), Mode.from_hz(130.0, 0.05)]), RATE)


def test_a_frequency_outside_the_parameters_range_is_refused_on_every_path():
    lo, hi = FREQUENCY_RANGE_HZ
    with pytest.raises(ShaperError, match=rf"outside \[{lo:g}, {hi:g}\] Hz"):
        check_design(design("zv", [Mode.from_hz(0.009, 0.0)]), RATE)
    with pytest.raises(ShaperError, match="outside"):  # the lists have no descriptor range: the check holds it
        design_from_params(params(family="zv", frequencies_hz=(0.009,), damping_ratios=(0.0,)), RATE)


def test_an_si_insensitivity_below_the_parameters_range_is_refused_on_the_service_path():
    narrow = design("si", [Mode.from_hz(10.0, 0.05)], insensitivity=0.005)  # the core designs it
    with pytest.raises(ShaperError, match=r"insensitivity 0.005 is outside \[0.01, 1.5\]"):
        POLICY.decide("service", narrow, RATE, [0])


def test_the_identity_and_custom_shapers_are_not_held_to_design_modes():
    check_design(design("none"), RATE)
    custom = design("custom", [Mode.from_hz(400.0, 0.0)], amplitudes=[0.5, 0.5], times=[0.0, 0.01])
    check_design(custom, RATE)  # its modes are labels; its impulses are what counts


def test_a_shaper_shorter_than_one_period_is_still_refused_first():
    with pytest.raises(PolicyError, match="shorter than one command period"):
        check_design(design("zv", [Mode.from_hz(1000.0, 0.0)]), 100.0)


# --- a setting that cannot take effect ----------------------------------------------------------------


def test_frequency_hz_while_frequencies_hz_is_set_cannot_take_effect():
    now = params(family="zv", frequencies_hz=(5.0, 8.0), damping_ratios=(0.05, 0.02))
    proposed = params(family="zv", frequency_hz=9.0, frequencies_hz=(5.0, 8.0), damping_ratios=(0.05, 0.02))
    why = ineffective(now, proposed, {"shaper.frequency_hz"})
    assert why is not None and why.startswith("shaper.frequency_hz 9 cannot take effect")
    assert "shaper.frequencies_hz is set ([5, 8] Hz) and takes precedence" in why
    damping = params(family="zv", damping_ratio=0.2, frequencies_hz=(5.0, 8.0), damping_ratios=(0.05, 0.02))
    assert "shaper.damping_ratio 0.2 cannot take effect" in str(ineffective(now, damping, {"shaper.damping_ratio"}))


def test_frequency_hz_takes_effect_when_the_lists_are_empty_or_emptied_with_it():
    single = params(family="zv", frequency_hz=10.0)
    assert ineffective(single, params(family="zv", frequency_hz=9.0), {"shaper.frequency_hz"}) is None
    now = params(family="zv", frequencies_hz=(5.0, 8.0), damping_ratios=(0.05, 0.02))
    emptied = params(family="zv", frequency_hz=9.0)  # one atomic request: lists emptied and the frequency set
    names = {"shaper.frequency_hz", "shaper.frequencies_hz", "shaper.damping_ratios"}
    assert ineffective(now, emptied, names) is None


def test_the_same_value_again_is_no_change():
    """`ros2 param load` of a dump sends every parameter, shaper.frequency_hz at its present value too."""
    now = params(family="zv", frequencies_hz=(5.0, 8.0), damping_ratios=(0.05, 0.02))
    assert ineffective(now, now, {"shaper.frequency_hz", "shaper.damping_ratio", "shaper.family"}) is None


def test_a_change_from_another_source_says_whose_shaper_it_replaces():
    assert displacement("scheduler", 7, "parameters") == "replaces the shaper set by scheduler (revision 7)"
    assert displacement("scheduler", 7, "scheduler") is None


# --- params files and dumps ---------------------------------------------------------------------------


def test_the_params_files_are_taken_from_the_ros_arguments_only():
    argv = ["node", "--params-file", "not_ros.yaml", "--ros-args", "-p", "a:=1", "--params-file", "a.yaml", "--",
            "--ros-args", "--params-file", "b.yaml"]
    assert params_files(argv) == ["a.yaml", "b.yaml"]


@pytest.mark.parametrize(("text", "words"), [
    (None, "no such file"),
    ("/**:\n  ros__parameters:\n    a: [1\n", "not valid YAML at line 4"),
    ("a: 1\n", "key 'a' has no 'ros__parameters' mapping"),
    ("", "not a params file"),
])
def test_a_params_file_that_cannot_be_used_is_named_with_its_problem(tmp_path, text, words):
    path = tmp_path / "p.yaml"
    if text is not None:
        path.write_text(text)
    problem = params_file_problem(["node", "--ros-args", "--params-file", str(path)])
    assert problem is not None and problem.startswith(f"--params-file {path}: ") and words in problem
    assert "\n" not in problem


def test_a_params_file_as_ros2_param_dump_writes_it_is_taken(tmp_path):
    path = tmp_path / "dump.yaml"
    path.write_text("/shaper:\n  ros__parameters:\n    limits:\n      position_lower: []\n    use_sim_time: false\n")
    assert params_file_problem(["node", "--ros-args", "--params-file", str(path)]) is None


def test_a_refusal_names_whose_parameters_a_params_file_keyed_by_name_holds(tmp_path):
    """`ros2 param dump /left_arm_shaper > dump.yaml`, then `shaper_node --ros-args --params-file dump.yaml`: the
    node, named shaper, takes none of the file and refuses its missing joint_names; the refusal adds whose the
    file's parameters are. No note for a file keyed /** or for a node renamed to the file's key."""
    dump = tmp_path / "dump.yaml"
    dump.write_text("/left_arm_shaper:\n  ros__parameters:\n    joint_names: [a]\n")
    hint = params_file_keys_hint(["shaper_node", "--ros-args", "--params-file", str(dump)])
    assert "/left_arm_shaper only" in hint and "-r __node:=left_arm_shaper" in hint and "\n" not in hint
    renamed = ["shaper_node", "--ros-args", "-r", "__node:=left_arm_shaper", "--params-file", str(dump)]
    assert params_file_keys_hint(renamed) == ""
    assert "/left_arm_shaper only" in params_file_keys_hint([*renamed[:3], "__node:=right", *renamed[4:]])
    shipped = tmp_path / "any.yaml"
    shipped.write_text("/**:\n  ros__parameters:\n    joint_names: [a]\n")
    assert params_file_keys_hint(["shaper_node", "--ros-args", "--params-file", str(shipped)]) == ""
    assert params_file_keys_hint(["shaper_node"]) == ""


def test_an_array_parameter_takes_no_value_as_the_empty_array():
    """rcl reads `position_lower: []` of a dump as a parameter without a value: it is the empty array."""
    spec = Spec("limits.position_lower", None, "x", type=Parameter.Type.DOUBLE_ARRAY)
    got = spec.convert(Parameter("limits.position_lower", Parameter.Type.NOT_SET, None))
    assert got.type_ == Parameter.Type.DOUBLE_ARRAY and list(got.value) == []
    assert spec.type_refusal(got) is None
    scalar = Spec("command_rate", 500.0, "x")
    assert "cannot be unset" in str(scalar.type_refusal(Parameter("command_rate", Parameter.Type.NOT_SET, None)))


# --- Hz on the messages -------------------------------------------------------------------------------


def test_modes_travel_in_hz_and_come_back_as_the_core_holds_them():
    msgs = pytest.importorskip("shaper_msgs.msg")
    if not hasattr(msgs.Mode(), "frequency_hz"):
        pytest.skip("shaper_msgs with Mode.frequency_hz is not built")
    from shaper_nodes.ros.conversions import estimate_modes, estimate_msg, mode_from_msg, mode_to_msg, shaper_to_msg

    mode = Mode.from_hz(8.5, 0.03)
    msg = mode_to_msg(mode)
    assert msg.frequency_hz == pytest.approx(8.5, rel=1e-15) and msg.damping_ratio == 0.03
    back = mode_from_msg(msg)
    assert back.omega == pytest.approx(mode.omega, rel=1e-15) and back.zeta == mode.zeta
    shaper = shaper_to_msg(design("zv", [mode]), "test", 1)
    assert [m.frequency_hz for m in shaper.design_modes] == [pytest.approx(8.5)]
    est = estimate_msg("identification", [mode], [2 * math.pi * 0.1], [0.01])
    assert estimate_modes(est) == [(pytest.approx(8.5), 0.03)]
    assert list(est.frequency_hz_std) == [pytest.approx(0.1)] and list(est.damping_ratio_std) == [0.01]
    with pytest.raises(ShaperError, match=r"frequency_hz must be finite and > 0 Hz, got -1.0"):
        mode_from_msg(msgs.Mode(frequency_hz=-1.0, damping_ratio=0.0))


# --- a -p override of another type than the params file's (session 15, the owner's walk) ----------------------

@pytest.mark.parametrize(("file_value", "rule", "kept"), [
    ("500", "command_rate:=250.0", "an integer (500)"),
    ("8.0", "shaper.frequency_hz:=ten", "a double (8.0)"),
    ("[2, 8]", "shaper.frequencies_hz:=[2.5, 8.5]", "an integer array ([2, 8])"),
    ("3", "queue_depth:=[1, 2]", "an integer (3)"),
])
def test_an_override_rcl_would_drop_is_refused_naming_both_values(tmp_path, file_value, rule, kept):
    """rcl keeps a params file's value beside a -p override of another type, and rclpy reads the first in its
    order (bool, integer, double, string, arrays): the override was dropped without a word. The check is held to
    what rclpy does: the value it reads from a real context is the file's."""
    name = rule.split(":=")[0]
    head, _, last = name.rpartition(".")
    body = f"      {last}: {file_value}\n" if head else f"    {last}: {file_value}\n"
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n" + (f"    {head}:\n" if head else "") + body)
    argv = ["shaper_node", "--ros-args", "--params-file", str(path), "-p", rule]
    problem = params_file_problem(argv)
    assert problem is not None and problem.startswith(f"-p {rule}: ") and "\n" not in problem
    assert f"gives {name} {kept}" in problem and "drop the override" in problem
    _assert_rclpy_reads(argv, name, yaml.safe_load(file_value))


def _assert_rclpy_reads(argv, name, value):
    """What rclpy reads for ``name`` from these arguments in a real context is ``value`` (the earlier one)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    context = Context()
    rclpy.init(args=argv, context=context)
    try:
        node = Node("shaper", context=context)
        assert node._parameter_overrides[name].value == value
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


@pytest.mark.parametrize("rule", ["command_rate:=250", "command_rate:=250.0", "shaper:joint_names:=[a, b]",
                                  "other:=1.5"])
def test_an_override_rcl_takes_is_not_refused(tmp_path, rule):
    """An override of the file's type, of a type rclpy reads before the file's (an integer over a double: the
    node converts it), or of a parameter the file does not set, is rcl's to take."""
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    command_rate: 500.0\n    joint_names: [j]\n")
    assert params_file_problem(["node", "--ros-args", "--params-file", str(path), "-p", rule]) is None


def test_a_later_params_file_of_another_type_is_refused_as_rcl_would_drop_it(tmp_path):
    """Two params files (calibration.md's walkthrough gives calibrate.yaml, then calibrate_quick.yaml): rcl keeps
    the first file's value beside the second's of another type, as for a -p override."""
    first, second, other = tmp_path / "a.yaml", tmp_path / "b.yaml", tmp_path / "c.yaml"
    first.write_text("/**:\n  ros__parameters:\n    command_rate: 500\n")
    second.write_text("/**:\n  ros__parameters:\n    command_rate: 250.0\n")
    other.write_text("/shaper:\n  ros__parameters:\n    command_rate: 250.0\n")
    argv = ["shaper_node", "--ros-args", "--params-file", str(first), "--params-file", str(second)]
    problem = params_file_problem(argv)
    assert problem is not None and problem.startswith(f"--params-file {second} (/**): command_rate is a double (250.0)")
    assert f"where --params-file {first} (/**) before it gives an integer (500)" in problem
    _assert_rclpy_reads(argv, "command_rate", 500)
    # a -p rule after another of a type rclpy reads first
    rules = ["shaper_node", "--ros-args", "-p", "command_rate:=500", "-p", "command_rate:=250.0"]
    assert "where -p command_rate:=500 gives command_rate an integer (500)" in params_file_problem(rules)
    # the node's own entry beside /**: two entries, no mixing (rclpy reads the node's own); the same type: none
    keyed = ["shaper_node", "--ros-args", "--params-file", str(first), "--params-file", str(other)]
    assert params_file_problem(keyed) is None
    _assert_rclpy_reads(keyed, "command_rate", 250.0)
    assert params_file_problem(["shaper_node", "--ros-args", "--params-file", str(second), "-p",
                                "command_rate:=100.0"]) is None
