"""The suite with standard ROS tools (ros2cli), checked through what those tools use.

ros2cli is not on PyPI, so these tests do what its verbs do, over the same interfaces:
``ros2 param dump`` is ``list_parameters`` + ``get_parameters`` on the node's parameter services;
``ros2 param set NAME x 8`` is ``set_parameters`` with an INTEGER value; ``ros2 run ... -r
__node:=NAME --params-file FILE`` is the installed executable with those ROS arguments; and the
executables' ``--help`` and exit status are run as a shell runs them. See docs/reference/ros2cli.md.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import subprocess

import pytest
import rclpy
import yaml
from conftest import call_answered
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters, SetParametersAtomically
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from shaper_nodes.cli import loop_design, shaper_design
from shaper_nodes.nodes import bag_play, calibrate, identifier, learner, recorder, scheduler, shaper
from shaper_nodes.recordings import BagWriter
from shaper_nodes.ros.launching import executable
from shaper_nodes.ros.parameters import declare_all
from sim_plant_node.node import sim_plant

ROOT = pathlib.Path(__file__).resolve().parents[1]
CONFIG = ROOT / "shaper_nodes" / "config"
TIMEOUT = 60.0


def flatten(tree: dict, prefix: str = "") -> dict:
    out: dict = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def config_values(path: pathlib.Path) -> dict:
    """The parameters a shipped params file sets (it is keyed '/**')."""
    (body,) = yaml.safe_load(path.read_text()).values()
    return flatten(body["ros__parameters"])


def console_scripts(package: str) -> list[str]:
    text = (ROOT / package / "setup.py").read_text()
    return re.findall(r'"(\w+) = [\w.]+:main"', text)


class Services:
    """A probe node calling another node's parameter services, as ros2cli does."""

    def __init__(self, ctx, *nodes: Node) -> None:
        self.probe = rclpy.create_node("ros2cli_probe", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        for n in (self.probe, *nodes):
            self.ex.add_node(n)

    def call(self, srv_type, name: str, request):
        """The answer of a parameter service of another process; sent again while none comes (every request
        here is idempotent in effect: a list, a get, a set of the values already set)."""
        cli = self.probe.create_client(srv_type, name)
        try:
            return call_answered(self.ex, cli, request, name, timeout=TIMEOUT)
        finally:
            self.probe.destroy_client(cli)

    def dump(self, node: str) -> dict[str, ParameterValue]:
        """Every parameter of ``node`` (fully qualified name) and its value: ``ros2 param dump``."""
        names = list(self.call(ListParameters, f"{node}/list_parameters", ListParameters.Request()).result.names)
        got = self.call(GetParameters, f"{node}/get_parameters", GetParameters.Request(names=names)).values
        return dict(zip(names, got, strict=True))

    def set(self, node: str, *params: ParameterMsg, atomically: bool = False):
        if atomically:
            return [self.call(SetParametersAtomically, f"{node}/set_parameters_atomically",
                              SetParametersAtomically.Request(parameters=list(params))).result]
        request = SetParameters.Request(parameters=list(params))
        return self.call(SetParameters, f"{node}/set_parameters", request).results

    def close(self) -> None:
        self.ex.shutdown()
        self.probe.destroy_node()


def value_of(v: ParameterValue):
    return Parameter.from_parameter_msg(ParameterMsg(name="x", value=v)).value


def _bag(path: pathlib.Path) -> pathlib.Path:
    from rclpy.serialization import serialize_message

    w = BagWriter(path)
    w.add_topic("/level", "std_msgs/msg/Float64")
    w.write("/level", 1_000_000_000, serialize_message(Float64(data=1.0)))
    w.close()
    return path


def _calibrate(**kwargs) -> Node:
    node = Node("calibrate", **kwargs)  # calibrate's main makes its node so
    declare_all(node, calibrate.PARAMETERS)
    return node


def _overrides(values: dict) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in values.items()]


#: what a sim plant model needs besides its name: seed 000's loop is stable around its own plant (10 rad/s, zeta 0.3)
SIM_EXTRA = {"mck_pid": {"plant.mass": [1.0], "plant.damping": [6.0], "plant.stiffness": [100.0]}}
#: every node of the suite with the least it needs to start: (factory, overrides) by case
CASES = {
    "shaper": (shaper.ShaperNode, lambda tmp: {"joint_names": ["a"]}),
    "identifier": (identifier.IdentifierNode, lambda tmp: {}),
    "learner list": (learner.LearnerNode, lambda tmp: {}),
    "learner mrilc": (learner.LearnerNode, lambda tmp: {"mode": "mrilc"}),
    "scheduler": (scheduler.SchedulerNode, lambda tmp: config_values(CONFIG / "scheduler.yaml")),
    "recorder": (recorder.RecorderNode, lambda tmp: {"output": str(tmp / "rec")}),
    "calibrate": (_calibrate, lambda tmp: {}),
    # start_delay: still waiting when asked (at the end it shuts its context down, as its process ends)
    "bag_play": (bag_play.BagPlayNode, lambda tmp: {"bag": str(_bag(tmp / "bag")), "start_delay": 60.0}),
    **{f"sim_plant {m}": (sim_plant.SimPlantNode, lambda tmp, m=m: {"plant.model": m, **SIM_EXTRA.get(m, {})})
       for m in sim_plant.MODELS},
}


@pytest.mark.parametrize("case", list(CASES))
def test_param_dump_gives_every_parameter_a_value(case, ros_context, tmp_path):
    """`ros2 param dump` stops at a NOT_SET parameter: no node leaves one after construction."""
    factory, overrides = CASES[case]
    node = factory(context=ros_context, parameter_overrides=_overrides(overrides(tmp_path)))
    svc = Services(ros_context, node)
    try:
        dump = svc.dump(node.get_fully_qualified_name())
        assert len(dump) >= 3
        unset = [name for name, v in dump.items() if v.type == ParameterType.PARAMETER_NOT_SET]
        assert not unset, f"{case}: parameters without a value: {unset}"
    finally:
        svc.close()
        if callable(getattr(node, "close", None)):
            node.close()
        node.destroy_node()


def dump_yaml(node: str, dump: dict[str, ParameterValue]) -> str:
    """What ``ros2 param dump NODE`` prints (ros2param's dump verb): the node's full name, then
    ``ros__parameters`` with the names split on '.' into nested mappings, the values as
    ros2param's ``get_value`` gives them (arrays as lists), by ``yaml.dump(default_flow_style=False)``."""
    tree: dict = {}
    for name in sorted(dump):
        *groups, last = name.split(".")
        here = tree
        for g in groups:
            here = here.setdefault(g, {})
        value = value_of(dump[name])
        here[last] = list(value) if isinstance(value, (list, tuple)) or hasattr(value, "tolist") else value
    return yaml.dump({node: {"ros__parameters": tree}}, default_flow_style=False)


def _same(a, b) -> bool:
    """Two parameter values are the same (NaN equals NaN; arrays element by element)."""
    arrays = [isinstance(v, (list, tuple)) or hasattr(v, "tolist") for v in (a, b)]
    if any(arrays):
        return all(arrays) and len(a) == len(b) and all(_same(x, y) for x, y in zip(list(a), list(b), strict=True))
    if isinstance(a, float) and isinstance(b, float) and a != a:
        return b != b
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("case", list(CASES))
def test_a_param_dump_loads_back_with_params_file(case, ros_context, domain_id, tmp_path):
    """`ros2 param dump /NODE > dump.yaml`, then the node started with `--params-file dump.yaml` alone:
    it starts (every parameter, empty arrays and read-only ones included, is taken) and its own dump
    is the same, parameter by parameter."""
    factory, overrides = CASES[case]
    node = factory(context=ros_context, parameter_overrides=_overrides(overrides(tmp_path)))
    svc = Services(ros_context, node)
    try:
        name = node.get_fully_qualified_name()
        first = svc.dump(name)
    finally:
        svc.close()
        if callable(getattr(node, "close", None)):
            node.close()
        node.destroy_node()
    if case == "recorder":  # the recorder refuses to write into a recording that exists: the first one goes
        shutil.rmtree(tmp_path / "rec")
    path = tmp_path / "dump.yaml"
    path.write_text(dump_yaml(name, first))
    if case == "shaper":
        assert "position_lower: []" in path.read_text()  # the case: an empty array in the dump

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain_id, args=["test", "--ros-args", "--params-file", str(path)])
    again = None
    try:
        again = factory(context=ctx)
        svc = Services(ctx, again)
        try:
            second = svc.dump(again.get_fully_qualified_name())
        finally:
            svc.close()
        assert sorted(second) == sorted(first)
        differ = [n for n in first if not (first[n].type == second[n].type
                                           and _same(value_of(first[n]), value_of(second[n])))]
        assert not differ, f"{case}: not loaded back: {[(n, value_of(first[n]), value_of(second[n])) for n in differ]}"
    finally:
        if again is not None:
            if callable(getattr(again, "close", None)):
                again.close()
            again.destroy_node()
        ctx.try_shutdown()


#: --params-file contents that cannot be used, and the words of each one's line
BAD_PARAMS_FILES = [
    (None, "no such file"),
    ("/**:\n  ros__parameters:\n    joint_names: [a\n", "not valid YAML at line"),
    ("joint_names: [a]\n", "has no 'ros__parameters'"),
    ("- 1\n", "not a params file"),
]
NODE_COMMANDS = ["shaper_node", "scheduler", "identifier", "learner", "recorder", "bag_play", "sim_plant", "calibrate"]


@pytest.mark.parametrize(("command", "content", "words"),
                         [(c, *BAD_PARAMS_FILES[i % len(BAD_PARAMS_FILES)]) for i, c in enumerate(NODE_COMMANDS)],
                         ids=NODE_COMMANDS)
def test_a_params_file_that_cannot_be_used_says_why_in_one_line(command, content, words, domain_id, tmp_path):
    """A missing or unparsable --params-file: one line naming the file and the problem, rc != 0, for every node.

    Every node's main asks the one check (shaper_nodes.ros.node_main.params_file_problem, unit-tested on each kind
    of bad file) before rcl reads the file: each installed node is started once, with one kind of bad file in turn,
    so that each kind goes through two nodes' processes (a process per node and kind was 32 starts of Python)."""
    path = tmp_path / "params.yaml"
    if content is not None:
        path.write_text(content)
    package = "sim_plant_node" if command in console_scripts("sim_plant_node") else "shaper_nodes"
    done = _run([str(executable(package, command)), "--ros-args", "--params-file", str(path)], tmp_path, domain_id)
    assert done.returncode != 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(command + ":"), done.stderr
    assert str(path) in lines[0] and words in lines[0], lines[0]
    assert "Traceback" not in done.stderr + done.stdout


def _int(name: str, value: int) -> ParameterMsg:
    return ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value))


def test_a_double_parameter_takes_an_integer_over_the_parameter_service(ros_context):
    """`ros2 param set /shaper shaper.frequency_hz 8` sends an INTEGER: taken as 8.0, range still checked."""
    node = shaper.ShaperNode(context=ros_context, parameter_overrides=_overrides(
        {"joint_names": ["a"], "shaper.family": "zv"}))
    svc = Services(ros_context, node)
    try:
        (ok,) = svc.set("/shaper", _int("shaper.frequency_hz", 8))
        assert ok.successful, ok.reason
        got = svc.dump("/shaper")["shaper.frequency_hz"]
        assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value == 8.0
        assert node.changes.shaper.modes[0].hz == pytest.approx(8.0)  # the design follows

        (high,) = svc.set("/shaper", _int("shaper.frequency_hz", 5000))
        assert not high.successful and "out of range" in high.reason and "1000" in high.reason
        text = ParameterMsg(name="shaper.frequency_hz",
                            value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="eight"))
        (word,) = svc.set("/shaper", text)
        assert not word.successful and "type" in word.reason.lower()
        assert svc.dump("/shaper")["shaper.frequency_hz"].double_value == 8.0  # unchanged by the refusals

        # a double array takes integers too ("[5, 8]" on the command line)
        freqs = ParameterMsg(name="shaper.frequencies_hz", value=ParameterValue(
            type=ParameterType.PARAMETER_INTEGER_ARRAY, integer_array_value=[5, 8]))
        zetas = ParameterMsg(name="shaper.damping_ratios", value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=[0.05, 0.02]))
        (both,) = svc.set("/shaper", freqs, zetas, atomically=True)
        assert both.successful, both.reason
        got = svc.dump("/shaper")["shaper.frequencies_hz"]
        assert got.type == ParameterType.PARAMETER_DOUBLE_ARRAY and list(got.double_array_value) == [5.0, 8.0]
        # and "[]" (which carries no element type) empties it again
        empty = ParameterMsg(name="shaper.frequencies_hz", value=ParameterValue(
            type=ParameterType.PARAMETER_BOOL_ARRAY, bool_array_value=[]))
        empty_z = ParameterMsg(name="shaper.damping_ratios", value=ParameterValue(
            type=ParameterType.PARAMETER_BOOL_ARRAY, bool_array_value=[]))
        (cleared,) = svc.set("/shaper", empty, empty_z, atomically=True)
        assert cleared.successful, cleared.reason
        assert svc.dump("/shaper")["shaper.frequencies_hz"].type == ParameterType.PARAMETER_DOUBLE_ARRAY
        assert [m.hz for m in node.changes.shaper.modes] == pytest.approx([8.0])
    finally:
        svc.close()
        node.destroy_node()


def test_a_params_file_with_integers_for_doubles_starts_the_node(domain_id, tmp_path):
    """`frequency_hz: 5` in a params file (an integer to YAML) works at start-up, for read-only ones too."""
    path = tmp_path / "shaper.yaml"
    path.write_text("/**:\n  ros__parameters:\n    joint_names: [a, b]\n    command_rate: 500\n"
                    "    shaper:\n      family: zv\n      frequency_hz: 5\n    limits:\n      velocity: [2, 3]\n")
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain_id, args=["test", "--ros-args", "--params-file", str(path)])
    node = shaper.ShaperNode(context=ctx)
    try:
        freq, rate, vel = (node.get_parameter(n) for n in ("shaper.frequency_hz", "command_rate", "limits.velocity"))
        assert (freq.type_, freq.value) == (Parameter.Type.DOUBLE, 5.0)
        assert (rate.type_, rate.value) == (Parameter.Type.DOUBLE, 500.0)
        assert (vel.type_, list(vel.value)) == (Parameter.Type.DOUBLE_ARRAY, [2.0, 3.0])
        assert node.describe_parameter("command_rate").read_only  # still read-only after the conversion
        assert node.changes.shaper.modes[0].hz == pytest.approx(5.0)
    finally:
        node.destroy_node()
        ctx.try_shutdown()


def test_a_renamed_node_keeps_the_parameters_of_the_shipped_params_file(start_node, ros_context):
    """`ros2 run shaper_nodes shaper_node --ros-args -r __node:=left_arm_shaper --params-file config/shaper.yaml`."""
    path = CONFIG / "shaper.yaml"
    start_node("shaper_nodes", "shaper_node", {}, params_file=path, remaps={"__node": "left_arm_shaper"})
    svc = Services(ros_context)
    try:
        dump = svc.dump("/left_arm_shaper")
        want = config_values(path)
        assert want, "the shipped file sets parameters"
        for name, value in want.items():
            got = value_of(dump[name])
            if isinstance(value, list):
                assert list(got) == pytest.approx(value) if value and not isinstance(value[0], str) else \
                    list(got) == value, name
            else:
                assert got == pytest.approx(value) if isinstance(value, float) else got == value, name
    finally:
        svc.close()


def _run(cmd: list[str], cwd: pathlib.Path, domain_id: int, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT, **kwargs)


@pytest.mark.parametrize(("command", "words", "status"), [
    (["shaper_node"], "joint_names", 1),
    (["shaper_node", "--ros-args", "-p", "joint_names:=[a]", "-p", "shaper.frequency_hz:=abc"], "frequency_hz", 1),
    (["shaper_node", "--ros-args", "-p", "joint_names:=[a]", "-p", "shaper.frequency_hz:=5000"], "out of range", 1),
    (["shaper_node", "--ros-args", "-p", "joint_names:=[a]", "-p", "discretization:=nearest"], "discretization", 1),
    (["scheduler"], "premises", 1),
    (["bag_play"], "bag", 1),
    (["calibrate"], "joint_names", 2),  # calibrate's refusals exit 2 (docs/guide/calibration.md)
])
def test_a_node_without_a_required_parameter_says_why_in_one_line(command, words, status, domain_id, tmp_path):
    package = "sim_plant_node" if command[0] in console_scripts("sim_plant_node") else "shaper_nodes"
    done = _run([str(executable(package, command[0])), *command[1:]], tmp_path, domain_id)
    assert done.returncode == status, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0] and lines[0].startswith(command[0] + ":"), done.stderr
    assert "Traceback" not in done.stderr + done.stdout


EXECUTABLES = [("shaper_nodes", n) for n in console_scripts("shaper_nodes")] + \
    [("sim_plant_node", n) for n in console_scripts("sim_plant_node")]
NODES = {"shaper_node": shaper, "identifier": identifier, "scheduler": scheduler, "recorder": recorder,
         "bag_play": bag_play, "calibrate": calibrate, "sim_plant": sim_plant}


@pytest.mark.parametrize(("package", "name"), EXECUTABLES, ids=[n for _, n in EXECUTABLES])
def test_every_executable_answers_help_without_starting(package, name, help_texts, domain_id, tmp_path):
    """``--help`` and ``-h`` print the usage, exit 0 and write nothing. ``--help`` is the session's run
    (tests/conftest.py's ``help_texts``, from which test_docs.py builds docs/reference/executables.md too)."""
    assert len(EXECUTABLES) >= 13
    assert name in help_texts, f"{name} is not in scripts/executables_doc.py's list"
    shown = help_texts[name]
    done = _run([str(executable(package, name)), "-h"], tmp_path, domain_id)
    for flag, out, err, code, wrote in (("--help", shown["stdout"], shown["stderr"], shown["returncode"],
                                         shown["wrote"]),
                                        ("-h", done.stdout, done.stderr, done.returncode,
                                         sorted(p.name for p in tmp_path.iterdir()))):
        assert code == 0, err
        assert out.startswith("usage:"), out[:200]
        assert "Traceback" not in err
        assert not wrote, f"{name} {flag} wrote {wrote}"
    for out in (shown["stdout"], done.stdout) if name in NODES else ():  # a node's usage: every parameter, and how
        for spec in NODES[name].PARAMETERS:  # to start it
            assert f"  {spec.name} (" in out, spec.name
        assert f"ros2 run {package} {name}" in out


def test_help_before_ros_args_only():
    from shaper_nodes.ros.node_main import wants_help

    assert wants_help(["x", "--help"]) and wants_help(["x", "-h", "--ros-args", "-p", "a:=1"])
    assert not wants_help(["x", "--ros-args", "-p", "a:=--help"]) and not wants_help(["x"])


@pytest.mark.parametrize("build", [shaper_design.build_parser, loop_design.build_parser])
def test_every_help_text_of_the_design_clis_formats(build):
    """An unescaped % in a help string garbles argparse's output (it once printed a dict)."""
    import argparse

    parsers = [build()]
    for p in list(parsers):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                parsers += list(action.choices.values())
    for p in parsers:
        text = p.format_help()
        assert "option_strings" not in text and "%(" not in text, p.prog


@pytest.mark.parametrize("command", [["shaper_design", "list"], ["shaper_design", "--help"],
                                     ["loop_design", "--help"], ["shaper_node", "--help"]])
def test_a_closed_pipe_ends_quietly(command, domain_id, tmp_path):
    """`shaper_design list | head -1`: the reader has gone before the output is written."""
    read, write = os.pipe()
    os.close(read)  # a reader that closed at once: every write fails with EPIPE
    try:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
        done = subprocess.run([str(executable("shaper_nodes", command[0])), *command[1:]], stdout=write,
                              stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=env, timeout=TIMEOUT)
    finally:
        os.close(write)
    assert done.returncode in (0, 141), done.stderr  # 141: 128 + SIGPIPE, as a shell reports it
    assert done.stderr == ""


def test_shaper_design_list_into_head(domain_id, tmp_path):
    exe = executable("shaper_nodes", "shaper_design")
    done = _run(["bash", "-c", f"'{exe}' list | head -1"], tmp_path, domain_id)
    assert done.returncode == 0 and len(done.stdout.splitlines()) == 1
    assert "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr
