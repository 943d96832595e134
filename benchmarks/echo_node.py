"""A bare echo node: the latency baseline for the shaper node.

It republishes every ``std_msgs/Float64MultiArray`` received on the input topic, unchanged (the
very message object), on the output topic: one subscription, one publisher, a
``SingleThreadedExecutor`` and nothing else. The difference between the shaper node's hop
latency and this node's is what the shaper's own work (validation, FIR, message building) costs.

Run it as ``python -m benchmarks.echo_node [--in TOPIC] [--out TOPIC] [--take] [--ros-args ...]``;
SIGINT stops it cleanly: rclpy's signal handlers are uninstalled first, before any executor is shut down
(:func:`stop_signal_handlers`). ``--take`` echoes the serialized bytes from a lean side node served by the
shaper's take loop (:class:`shaper_nodes.ros.side_node.SideNode` with ``take=True``) instead, written by a publisher
of the main node as the shaper's are: the round trip of a Python node that does no work on the shaper's own path, the
floor of the shaper's hop. ``--take --shape FAMILY`` (with ``--frequency``, ``--damping``, ``--joints``, ``--rate``)
does the shaper's own work on that path before the publish, and nothing else: the core's array path
(:class:`shaper_nodes.ros.raw_stream.RawArrays` over :class:`shaper_nodes.core.shaping.stream.CommandStream`, the shaper
node's default limits), i.e. the floor plus the work a shaper must do, without the rest of the shaper node (its second
streamed input, its QoS event handlers, the rate watch, diagnostics, services): the hop the shaper node's design can
approach at best (docs/results/benchmarks.md, "The floor that does the shaper's work").
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions, uninstall_signal_handlers
from std_msgs.msg import Float64MultiArray

#: default topics (the benchmark driver uses the same defaults)
IN_TOPIC = "/bench/echo_in"
OUT_TOPIC = "/bench/echo_out"
#: QoS depth, as the shaper node's subscriptions and publishers
DEPTH = 10
#: wall s the main thread's wait lasts at most while nothing arrives: a SIGINT whose wake-up of the executor is lost
#: is noticed within it. Twice in suites (sessions 15 and 16) the node, idle, did not end within 60 s of SIGINT; the
#: second time the stack dump (tests/test_bench_echo_stop.py) showed the main thread still in rclpy's wait: rclpy 7.1.6
#: chains to Python's handler (a KeyboardInterrupt pending; none where SIGINT was inherited ignored, as in a
#: background job) and wakes the executors from a thread of its own, and that wake-up did not come. With the bound
#: a pending KeyboardInterrupt, or a context shut down, ends the spin within it. One wake-up a second of an idle
#: main thread (the take loop's node) costs nothing measurable.
STOP_LOOK = 1.0


def stop_signal_handlers() -> None:
    """Uninstall rclpy's signal handlers and join their thread, before the executors are shut down.

    On SIGINT rclpy 7.1.6 wakes a thread of its own that triggers every executor's SIGINT guard condition from a
    global list, with no lock against that list's change: an executor shut down meanwhile (the main thread, woken
    by the first guard condition, runs ``finally`` at once) unregisters its guard condition, which frees the list
    and the guard condition under that thread, and the process ended on SIGSEGV (-11) in
    ``rcl_trigger_guard_condition`` on that thread (a core dump, session 14: about one stop in 20 on a loaded
    machine). Uninstalling joins that thread first (idempotent)."""
    uninstall_signal_handlers()


def _spin(executor: SingleThreadedExecutor, context: Any) -> None:
    """``executor.spin()``, its wait bounded by :data:`STOP_LOOK` (a pending KeyboardInterrupt is then raised, a
    context shut down seen)."""
    while context.ok():
        executor.spin_once(timeout_sec=STOP_LOOK)


class EchoNode(Node):
    """Republish ``Float64MultiArray`` from ``in_topic`` to ``out_topic`` with no processing.

    Parameters
    ----------
    in_topic, out_topic : str
        Topic names.
    **kwargs
        Passed to :class:`rclpy.node.Node` (e.g. ``context``).
    """

    def __init__(self, in_topic: str = IN_TOPIC, out_topic: str = OUT_TOPIC, **kwargs) -> None:
        super().__init__("bench_echo", **kwargs)
        self._pub = self.create_publisher(Float64MultiArray, out_topic, DEPTH)
        self.create_subscription(Float64MultiArray, in_topic, self._pub.publish, DEPTH)
        self.get_logger().info(f"echoing {in_topic} -> {out_topic}")


def lean_shaping(family: str, frequency_hz: float, damping: float, joints: int, rate: float) -> Any:
    """The shaper node's array work alone: a :class:`~shaper_nodes.ros.raw_stream.RawArrays` shaping with ``family``
    (one mode, ``split`` discretization, as the bench's shaper targets) over ``joints`` joints at ``rate`` Hz, with
    the shaper node's default limits and bounds (``ShaperParams()``)."""
    from shaper_nodes.core.shaping import Mode, design, discretize
    from shaper_nodes.core.shaping.stream import CommandStream
    from shaper_nodes.nodes.shaper_parameters import ShaperParams, limits_from_params
    from shaper_nodes.ros.raw_stream import RawArrays

    p = ShaperParams()
    shaper = design(family, [Mode.from_hz(frequency_hz, damping)])
    limits = limits_from_params([f"joint_{i + 1}" for i in range(joints)], p.limits)
    stream = CommandStream(discretize(shaper, rate, "split"), limits, max_abs=float(p.limits.max_abs_value),
                           max_samples=int(p.limits.max_trajectory_samples))
    return RawArrays(stream)


def _spin_take(in_topic: str, out_topic: str, context: rclpy.context.Context, executor: SingleThreadedExecutor,
               shaping: Any = None) -> None:
    """Echo the raw bytes from ``in_topic`` to ``out_topic`` on a take loop until the context shuts down; with
    ``shaping`` (:func:`lean_shaping`) the bytes shaped first."""
    from shaper_nodes.ros.side_node import SideNode
    from shaper_nodes.ros.stream_watch import WorkTiming

    parent = Node("bench_echo", context=context)  # names the side node; spun by ``executor`` for SIGINT only
    side = SideNode(parent, "take", take=True)
    # with SHAPER_WORK_TIMING set (the bench), the callback (the publish) and its wake-up timed as the shaper's
    # (ros/stream_watch.py; a (message, info) callback then, as the shaper's)
    timing = WorkTiming.from_env()
    try:  # from here on a stop (SIGINT) closes the side node, whenever it comes
        # the publisher on the parent, as the shaper node's are on its main node: on the side node its QoS event
        # handlers would sit in the take loop's wait set, a cost per wake-up the shaper's loop does not pay (session
        # 12, hopwork)
        pub = parent.create_publisher(Float64MultiArray, out_topic, DEPTH)
        if shaping is None:
            callback: Any = pub.publish if timing is None else timing.timed_callback(lambda msg, info: pub.publish(msg))
        else:  # the shaper's work, then the publish (timed as the shaper's: work, publish, callback, wake)
            if timing is not None:
                timing.patch(shaping, "shape", "work")
                timing.patch(pub, "publish", "publish")
            shape, publish = shaping.shape, pub.publish

            def callback(data: bytes, info: Any) -> None:
                publish(shape(data))

            if timing is not None:
                callback = timing.timed_callback(callback)
        side.node.create_subscription(Float64MultiArray, in_topic, callback, DEPTH, raw=True)
        side.start()
        parent.get_logger().info(f"echoing {in_topic} -> {out_topic} (raw, take loop"
                                 + (", shaped)" if shaping is not None else ")"))
        executor.add_node(parent)
        _spin(executor, context)
    finally:
        stop_signal_handlers()  # before the side node's executor is shut down (its SIGINT guard condition)
        if timing is not None:
            timing.write()
        side.close()
        parent.destroy_node()


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    argv = list(sys.argv if argv is None else argv)
    parser = argparse.ArgumentParser(prog="python -m benchmarks.echo_node", description=__doc__.split("\n")[0])
    parser.add_argument("--in", dest="in_topic", default=IN_TOPIC, help=f"input topic (default {IN_TOPIC})")
    parser.add_argument("--out", dest="out_topic", default=OUT_TOPIC, help=f"output topic (default {OUT_TOPIC})")
    parser.add_argument("--take", action="store_true", help="echo raw bytes on a take loop (the shaper's stream path)")
    parser.add_argument("--shape", metavar="FAMILY", default="",
                        help="with --take: shape the samples with this shaper family first (the shaper's work alone)")
    parser.add_argument("--frequency", type=float, default=8.0, help="--shape: the mode's frequency, Hz (default 8)")
    parser.add_argument("--damping", type=float, default=0.03, help="--shape: the mode's damping ratio (default 0.03)")
    parser.add_argument("--joints", type=int, default=7, help="--shape: joints per sample (default 7)")
    parser.add_argument("--rate", type=float, default=1000.0, help="--shape: the command rate, Hz (default 1000)")
    args = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if args.shape and not args.take:
        parser.error("--shape needs --take")
    shaping = lean_shaping(args.shape, args.frequency, args.damping, args.joints, args.rate) if args.shape else None

    context = rclpy.context.Context()
    # rclpy installs its SIGINT/SIGTERM handlers (which wake the executor) only for the default
    # context unless asked; without them SIGINT would wait for the next message to be noticed
    rclpy.init(args=argv, context=context, signal_handler_options=SignalHandlerOptions.ALL)
    node = None
    executor = SingleThreadedExecutor(context=context)
    try:
        if args.take:
            _spin_take(args.in_topic, args.out_topic, context, executor, shaping)
        else:
            node = EchoNode(args.in_topic, args.out_topic, context=context)
            executor.add_node(node)
            _spin(executor, context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop_signal_handlers()
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
