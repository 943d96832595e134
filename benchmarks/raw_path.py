"""The array hop's conversions in one process, no DDS: message objects against serialized bytes.

``python -m benchmarks.raw_path [--messages N] [--passes P]`` sends ``N`` serialized 7-joint
std_msgs/Float64MultiArray (ZVD 8 Hz, 1 kHz) through three paths and prints the CPU time per message,
best and median of ``P`` passes taken in turns (the order reversed every other pass):

``objects``
    what the shaper node did with message objects: ``deserialize_message``, ``shape_array``,
    ``serialize_message`` (rclpy's take and publish do the same conversions in C);
``raw``
    :class:`shaper_nodes.ros.raw_stream.RawArrays` ``.shape``: the bytes read, ``shape_array``, the
    answer written in place (what the node does now);
``conversions``
    ``deserialize_message`` and ``serialize_message`` alone, the part the raw path does not pay.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from shaper_nodes.core.shaping import Mode, design, discretize
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.stream import CommandStream
from shaper_nodes.ros.raw_stream import RawArrays

JOINTS = 7


def _stream() -> CommandStream:
    fir = discretize(design("zvd", [Mode.from_hz(8.0, 0.03)]), 1000.0, "split")
    names = tuple(f"joint_{i}" for i in range(JOINTS))
    return CommandStream(fir, JointLimits.from_lists(names, (), (), ()), max_abs=1e6)


def run(messages: int = 20_000, passes: int = 5) -> dict[str, tuple[float, float]]:
    """Per path, (best, median) CPU time per message, us."""
    raws = []
    for k in range(messages):
        msg = Float64MultiArray(data=(np.arange(JOINTS) * 1e-3 * (k % 1000)).tolist())
        msg.layout.data_offset = k
        raws.append(serialize_message(msg))
    objects_stream, raw = _stream(), RawArrays(_stream())

    def objects(data: bytes) -> bytes:
        msg = deserialize_message(data, Float64MultiArray)
        msg.data = objects_stream.shape_array(msg.data)
        return serialize_message(msg)

    def conversions(data: bytes) -> bytes:
        return serialize_message(deserialize_message(data, Float64MultiArray))

    paths: list[tuple[str, Callable[[bytes], bytes]]] = [("objects", objects), ("raw", raw.shape),
                                                         ("conversions", conversions)]
    return time_paths(paths, raws, passes)


def time_paths(paths: list[tuple[str, Callable[[bytes], bytes]]], raws: list[bytes],
               passes: int) -> dict[str, tuple[float, float]]:
    """CPU time per message, us, of each path over ``raws``, ``passes`` times in alternating order: per path
    the best and the median pass."""
    times: dict[str, list[float]] = {name: [] for name, _ in paths}
    for k in range(passes):
        for name, fn in paths if k % 2 else paths[::-1]:
            t = time.process_time_ns()
            for data in raws:
                fn(data)
            times[name].append((time.process_time_ns() - t) / len(raws) / 1000)
    return {name: (min(v), sorted(v)[len(v) // 2]) for name, v in times.items()}


def main(argv: list[str] | None = None) -> int:
    """Entry point; prints the table."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.raw_path", description=__doc__.splitlines()[0])
    p.add_argument("--messages", type=int, default=20_000)
    p.add_argument("--passes", type=int, default=5)
    args = p.parse_args(argv)
    for name, (best, median) in run(args.messages, args.passes).items():
        print(f"{name:12s} best {best:6.2f} us/msg, median {median:6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
