"""Issue 17's classes of bad input, tried against the real shaper node: what each now gives.

Each row sends one input the issue found passed on, stalled or killed the node, to a real
``ShaperNode`` (in this process; its callbacks are called directly, what it would publish is
captured at its publishers), and prints what the node did: refused with which reason, or what it
passed on; how long that took; and that the node then still shapes a valid sample. Run with
``./run exec python scripts/refusal_table.py`` (``--markdown`` for a table to paste).
"""

from __future__ import annotations

import argparse
import copy
import math
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import rclpy
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper, ShapeTrajectory
from shaper_nodes.core.checks import InputError
from shaper_nodes.nodes.shaper import ShaperNode
from shaper_nodes.ros.conversions import mode_msg

JOINTS = [f"joint_{i + 1}" for i in range(6)]
ZEROS = [0.0] * 6


def _data(sent: bytes) -> list[float]:
    """The data of what the array input published (serialized bytes: the node takes and sends it raw)."""
    return list(deserialize_message(sent, Float64MultiArray).data)


class Captured:
    def __init__(self) -> None:
        self.sent: list[Any] = []
        self.topic_name = "captured"

    def publish(self, msg: Any) -> None:
        self.sent.append(copy.deepcopy(msg))  # as rclpy serializes it: the node may reuse or free it


def traj(points: list[tuple[float, list[float]]], names: list[str] | None = None,
         raw: list[tuple[int, int]] | None = None) -> JointTrajectory:
    msg = JointTrajectory(joint_names=names or JOINTS)
    for k, (t, p) in enumerate(points):
        if raw is not None:
            d = Duration(sec=raw[k][0], nanosec=raw[k][1])
        else:
            ns = int(round(t * 1e9))
            d = Duration(sec=ns // 10**9, nanosec=ns % 10**9)
        msg.points.append(JointTrajectoryPoint(positions=p, time_from_start=d))
    return msg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args(argv)
    rclpy.init(domain_id=201)
    node = ShaperNode(parameter_overrides=[
        Parameter("joint_names", value=JOINTS), Parameter("command_rate", value=500.0),
        Parameter("shaper.family", value="zvd"), Parameter("shaper.frequency_hz", value=8.0),
        Parameter("error_throttle", value=3600.0),
        Parameter("limits.position_lower", value=[-6.28] * 6), Parameter("limits.position_upper", value=[6.28] * 6)])
    t = Table(node)
    t.shaper_rows()
    _print(t.rows, a.markdown)
    node.destroy_node()
    rclpy.shutdown()
    return 0


class Table:
    """The rows, tried one after the other on one node."""

    def __init__(self, node: ShaperNode) -> None:
        self.node = node
        node._array_pub, node._stream_pub, node._traj_pub = Captured(), Captured(), Captured()
        self.refusals: list[InputError] = []
        reject = node._reject
        node._reject = lambda topic, err: (self.refusals.append(err), reject(topic, err))  # type: ignore
        self.rows: list[tuple[str, str, str, float, str]] = []

    def row(self, name: str, before: str, act: Callable[[], str]) -> None:
        node = self.node
        t0 = time.perf_counter()
        try:
            what = act()
        except Exception as err:  # shown, not hidden: the table is the evidence
            what = f"EXCEPTION {type(err).__name__}: {err}"
        dt = time.perf_counter() - t0
        sent = len(node._array_pub.sent)
        node._on_array(serialize_message(Float64MultiArray(data=ZEROS)), None)
        alive = "yes" if len(node._array_pub.sent) == sent + 1 else "NO"
        self.rows.append((name, before, what, dt, alive))

    def array(self, values: list[float]) -> str:
        node = self.node
        n = len(node._array_pub.sent)
        node._on_array(serialize_message(Float64MultiArray(data=values)), None)
        if len(node._array_pub.sent) == n:
            return f"refused {self.refusals[-1].kind}: {self.refusals[-1]}"
        return f"passed on {np.round(_data(node._array_pub.sent[n]), 3).tolist()[:2]}..."

    def goal(self, msg: JointTrajectory) -> str:
        try:
            self.node._action.shaped_goal(FollowJointTrajectory.Goal(trajectory=msg))  # type: ignore[union-attr]
        except InputError as err:
            return f"rejected {err.kind}: {err}"
        return "passed on"

    def poison(self) -> str:
        node = self.node
        self.array([1e17, *ZEROS[1:]])
        node.request(_design("zv", 5.0), "service")
        for _ in range(400):
            node._on_array(serialize_message(Float64MultiArray(data=[0.3] * 6)), None)
        return (f"1e17 refused ({self.refusals[-1].kind}); after a shaper change, steady 0.3 gives"
                f" {_data(node._array_pub.sent[-1])[0]!r}")

    def fields(self) -> str:
        node, out = self.node, []
        for k, with_vel in enumerate([False, True, True, False]):
            pt = JointTrajectoryPoint(positions=[0.01 * k] * 6, time_from_start=Duration(nanosec=2_000_000 * (k + 1)))
            if with_vel:
                pt.velocities = [0.1] * 6
            n = len(node._stream_pub.sent)
            node._on_stream(serialize_message(JointTrajectory(joint_names=JOINTS, points=[pt])), None)
            out.append("shaped" if len(node._stream_pub.sent) > n else f"refused {self.refusals[-1].kind}")
        return "positions / +velocities / +velocities / positions: " + ", ".join(out)

    def shaper_rows(self) -> None:
        node, row = self.node, self.row
        node._on_array(serialize_message(Float64MultiArray(data=ZEROS)), None)
        row("1. array -1.7e308 then +1.7e308", "non-finite setpoints",
            lambda: self.array([-1.7e+308, *ZEROS[1:]]) + "; " + self.array([1.7e+308, *ZEROS[1:]]))
        big = traj([(0.0, ZEROS), (1.0, [1e+308, *ZEROS[1:]])])
        row("1. whole trajectory 0 -> 1e308 in 1 s (service)", "forwarded, infinite accelerations",
            lambda: _srv(node, big))
        row("1. the same as a FollowJointTrajectory goal", "forwarded",
            lambda: self.goal(big))

        row("2. 1e17, shaper change, steady 0.3", "output 0.0 for good", self.poison)
        for amps in ([1000.0, -999.0], [2.0, -1.0]):
            custom = ShaperMsg(family="custom", amplitudes=amps, times=[0.0, 0.1], source="user")
            row(f"3. set_shaper custom {amps}", "accepted: 1 rad step -> 1000 rad" if amps[0] > 2 else "1.8 rad",
                partial(_set, node, custom))
        for n in (25, 12):
            many = ShaperMsg(family="zvd", source="user", design_modes=[
                mode_msg((6.0 + k) / (2 * math.pi), 0.05) for k in range(n)])
            row(f"4. zvd for {n} design modes", "out of memory, node killed" if n == 25 else "531,441 impulses",
                partial(_set, node, many))
        row("4. custom shaper, 10,000 impulses over 60 s", "accepted, throughput 25 msg/s",
            lambda: _set(node, ShaperMsg(family="custom", source="user", amplitudes=[1e-4] * 10_000,
                                         times=np.linspace(0, 60, 10_000).tolist())))
        for span, before in ((1e5, "node killed (1.1 GiB array)"), (3600.0, "stream stalled 46 s, +130 MiB")):
            apart = traj([(0.0, ZEROS), (span, [0.1] * 6)])
            row(f"4. whole trajectory, two points {span:g} s apart", before, partial(_srv, node, apart))
        row("4. whole trajectory of 10^6 points", "45 s of work",
            lambda: _srv(node, JointTrajectory(joint_names=JOINTS, points=[JointTrajectoryPoint(positions=ZEROS)]
                                                 * 1_000_000)))
        row("4. one message with 40,000 duplicate joint names", "stream stalled 31 s",
            lambda: _stream(node, self.refusals, JointTrajectory(joint_names=["joint_1"] * 40_000,
                                                  points=[JointTrajectoryPoint(positions=[0.0] * 40_000)])))
        row("5. negative time_from_start", "shaped and forwarded",
            lambda: _srv(node, traj([(0, ZEROS), (0, ZEROS)], raw=[(-1, 0), (0, 0)])))
        row("5. sec 2^31-1, nanosec 999999999", "wrapped to a negative time",
            lambda: _srv(node, traj([(0, ZEROS)], raw=[(2**31 - 1, 999_999_999)])))
        row("beyond a joint limit (7 rad, limits +-6.28)", "(no limits before)", lambda: self.array([7.0, *ZEROS[1:]]))

        row("7. stream: positions only, then positions + velocities", "every later message refused", self.fields)


def _print(rows: list[tuple[str, str, str, float, str]], markdown: bool) -> None:
    head = ("input", "before", "now", "time", "node shapes the next sample")
    if markdown:
        print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
        for r in rows:
            print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3] * 1e3:.1f} ms | {r[4]} |")
        return
    for r in rows:
        print(f"{r[0]}\n    before: {r[1]}\n    now:    {r[2]}\n    {r[3] * 1e3:.1f} ms; next sample shaped: {r[4]}")


def _design(family: str, hz: float) -> Any:
    from shaper_nodes.core.shaping import Mode, design
    return design(family, [Mode.from_hz(hz, 0.05)])


def _srv(node: ShaperNode, msg: JointTrajectory) -> str:
    resp = node._on_shape_trajectory(ShapeTrajectory.Request(trajectory=msg), ShapeTrajectory.Response())
    return f"{'passed on' if resp.success else 'refused'}: {resp.message}"


def _set(node: ShaperNode, msg: ShaperMsg) -> str:
    resp = node.changes.on_set_shaper(SetShaper.Request(shaper=msg), SetShaper.Response())
    return f"{'accepted' if resp.success else 'refused'}: {resp.message}"


def _stream(node: ShaperNode, refusals: list[InputError], msg: JointTrajectory) -> str:
    n = len(node._stream_pub.sent)
    node._on_stream(serialize_message(msg), None)
    return "passed on" if len(node._stream_pub.sent) > n else f"refused {refusals[-1].kind}: {refusals[-1]}"


if __name__ == "__main__":
    raise SystemExit(main())
