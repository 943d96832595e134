"""What ros2cli's parameter verbs would show for the shaper node, on a machine without ros2cli.

Starts the installed ``shaper_node`` renamed ``left_arm_shaper`` with the shipped params file (as
``ros2 run shaper_nodes shaper_node --ros-args -r __node:=left_arm_shaper --params-file
config/shaper.yaml``), then, over its parameter services as ros2cli does, prints:

1. ``ros2 param dump /left_arm_shaper`` (the same YAML layout),
2. ``ros2 param set /left_arm_shaper shaper.frequency_hz 9`` (an INTEGER), then ``5000`` and ``eight``,
3. ``ros2 param get /left_arm_shaper shaper.frequency_hz``.

Run: ``./run exec python scripts/ros2cli_checks.py`` (docs/reference/ros2cli.md shows its output).
"""

from __future__ import annotations

import os
import pathlib
import sys
import tempfile
import time

import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.parameter import Parameter

from shaper_nodes.ros.launching import NodeProcess
from shaper_nodes.ros.node_main import yaml_value

NODE = "/left_arm_shaper"
CONFIG = pathlib.Path(__file__).resolve().parents[1] / "shaper_nodes" / "config" / "shaper.yaml"


def call(node, srv_type, name: str, request, timeout: float = 60.0):
    cli = node.create_client(srv_type, name)
    if not cli.wait_for_service(timeout_sec=timeout):
        raise SystemExit(f"no service {name}")
    fut = cli.call_async(request)
    rclpy.spin_until_future_complete(node, fut, timeout_sec=timeout)
    return fut.result()


def dump(node) -> str:
    """The YAML ``ros2 param dump`` prints (nested by the dots of the names)."""
    names = sorted(call(node, ListParameters, f"{NODE}/list_parameters", ListParameters.Request()).result.names)
    got = call(node, GetParameters, f"{NODE}/get_parameters", GetParameters.Request(names=names)).values
    lines = [f"{NODE}:", "  ros__parameters:"]
    opened: list[str] = []
    for name, v in zip(names, got, strict=True):
        *path, leaf = name.split(".")
        common = 0
        while common < min(len(path), len(opened)) and path[common] == opened[common]:
            common += 1
        for depth in range(common, len(path)):
            lines.append("    " + "  " * depth + f"{path[depth]}:")
        opened = path
        value = Parameter.from_parameter_msg(ParameterMsg(name=name, value=v)).value
        shown = "NOT_SET" if v.type == ParameterType.PARAMETER_NOT_SET else yaml_value(
            list(value) if not isinstance(value, (str, bool, int, float)) else value)
        lines.append("    " + "  " * len(path) + f"{leaf}: {shown}")
    return "\n".join(lines)


def set_param(node, name: str, value: ParameterValue) -> str:
    (result,) = call(node, SetParameters, f"{NODE}/set_parameters",
                     SetParameters.Request(parameters=[ParameterMsg(name=name, value=value)])).results
    return "Set parameter successful" if result.successful else f"Setting parameter failed: {result.reason}"


def main() -> int:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    log = pathlib.Path(tempfile.mkdtemp()) / "shaper.log"
    proc = NodeProcess("shaper_nodes", "shaper_node", {}, log_path=log, params_file=CONFIG,
                       remaps={"__node": "left_arm_shaper"}).start()
    rclpy.init()
    node = rclpy.create_node("ros2cli_checks")
    try:
        print(f"$ ros2 param dump {NODE}\n{dump(node)}\n")
        for text, value in (("9", ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=9)),
                            ("5000", ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=5000)),
                            ("eight", ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="eight"))):
            print(f"$ ros2 param set {NODE} shaper.frequency_hz {text}\n"
                  f"{set_param(node, 'shaper.frequency_hz', value)}")
        (v,) = call(node, GetParameters, f"{NODE}/get_parameters",
                    GetParameters.Request(names=["shaper.frequency_hz"])).values
        kind = {ParameterType.PARAMETER_DOUBLE: "Double", ParameterType.PARAMETER_INTEGER: "Integer"}.get(v.type, "?")
        print(f"$ ros2 param get {NODE} shaper.frequency_hz\n{kind} value is: {v.double_value}")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        time.sleep(0.1)
        proc.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
