"""The stream topic's hop in one process, no DDS: JointTrajectory message objects against serialized bytes.

``python -m benchmarks.raw_trajectory [--messages N] [--passes P] [--points K] [--velocities]`` sends
``N`` serialized 7-joint trajectory_msgs/JointTrajectory of ``K`` points each (ZVD 8 Hz, 1 kHz; positions,
and velocities with ``--velocities``) through three paths and prints the CPU time per message, best and
median of ``P`` passes taken in turns (the order reversed every other pass), as
:mod:`benchmarks.raw_path` does for the array input:

``objects``
    what the shaper node did with message objects: ``deserialize_message``, ``trajectory_arrays``, the
    stamps normalised, ``shape_points``, ``trajectory_msg``, ``serialize_message`` (rclpy's take and
    publish do the same conversions in C);
``raw``
    :class:`shaper_nodes.ros.raw_stream.RawTrajectories` ``.shape``: the bytes read, the same conversion
    and rules, the answer packed (what the node does now);
``conversions``
    ``deserialize_message`` and ``serialize_message`` alone, the part the raw path does not pay.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_nodes.core.shaping import Mode, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.stream import NS, CommandStream, normal_stamp
from shaper_nodes.ros.conversions import trajectory_arrays, trajectory_msg
from shaper_nodes.ros.raw_stream import RawTrajectories

from .raw_path import time_paths

JOINTS = 7
NAMES = tuple(f"joint_{i}" for i in range(1, JOINTS + 1))


def _stream() -> CommandStream:
    fir = discretize(design("zvd", [Mode.from_hz(8.0, 0.03)]), 1000.0, "split")
    return CommandStream(fir, JointLimits.from_lists(NAMES, (), (), ()), max_abs=1e6)


def run(messages: int = 20_000, passes: int = 5, points: int = 1,
        velocities: bool = False) -> dict[str, tuple[float, float]]:
    """Per path, (best, median) CPU time per message, us."""
    raws = []
    for k in range(messages):
        msg = JointTrajectory(joint_names=list(NAMES))
        msg.header.frame_id = "base_link"  # stamp 0: "now", as a servo stream may send (never out of order)
        for i in range(points):
            x = (np.arange(JOINTS) * 1e-3 * ((k + i) % 1000)).tolist()
            pt = JointTrajectoryPoint(positions=x, time_from_start=Duration(nanosec=1_000_000 * (i + 1)))
            if velocities:
                pt.velocities = [0.01] * JOINTS
            msg.points.append(pt)
        raws.append(serialize_message(msg))
    objects_stream, raw = _stream(), RawTrajectories(_stream(), NAMES)

    def objects(data: bytes) -> bytes:  # the node's _on_stream before the raw path
        msg = deserialize_message(data, JointTrajectory)
        times, fields = trajectory_arrays(msg, NAMES, require_times=False, limit=objects_stream.max_abs)
        stamp = msg.header.stamp
        stamp.sec, stamp.nanosec = normal_stamp(stamp.sec, stamp.nanosec)
        durations = [p.time_from_start for p in msg.points]
        for d in durations:
            if d.nanosec >= NS:
                d.sec, d.nanosec = normal_stamp(d.sec, d.nanosec)
        shaped = objects_stream.shape_points(times, fields, (stamp.sec, stamp.nanosec))
        return serialize_message(trajectory_msg(msg.header, NAMES, durations, shaped))

    def conversions(data: bytes) -> bytes:
        return serialize_message(deserialize_message(data, JointTrajectory))

    paths: list[tuple[str, Callable[[bytes], bytes]]] = [("objects", objects), ("raw", raw.shape),
                                                         ("conversions", conversions)]
    return time_paths(paths, raws, passes)


def main(argv: list[str] | None = None) -> int:
    """Entry point; prints the table."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.raw_trajectory", description=__doc__.splitlines()[0])
    p.add_argument("--messages", type=int, default=20_000)
    p.add_argument("--passes", type=int, default=5)
    p.add_argument("--points", type=int, default=1, help="points per message (default 1)")
    p.add_argument("--velocities", action="store_true", help="points carry velocities as well")
    args = p.parse_args(argv)
    if args.messages < 1 or args.passes < 1 or args.points < 1:
        p.error("--messages, --passes and --points must be >= 1")
    for name, (best, median) in run(args.messages, args.passes, args.points, args.velocities).items():
        print(f"{name:12s} best {best:6.2f} us/msg, median {median:6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
