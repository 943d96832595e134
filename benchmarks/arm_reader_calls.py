"""The arm's readers per message, the first two parts of :mod:`benchmarks.arm_readers` (its docstring):
``callbacks`` (in one process, no DDS: the CPU per message of the readers' callbacks on message objects
against serialized bytes) and ``batch`` (over DDS, in one process: a raw Imu reader taking a queued burst one
message per wake-up or all at a poll); and a reader's subscription in each mode (:func:`subscribe`), which the
lockstep part's reader processes use too."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np


# ------------------------------------------------------------------------------------------- callbacks
def _cpu_per_call(fn: Callable[[], None], n: int, repeats: int = 5) -> float:
    """Least CPU time per call of ``fn``, s, over ``repeats`` passes of ``n`` calls."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        for _ in range(n):
            fn()
        best = min(best, time.process_time() - t0)
    return best / n


def callbacks(n: int = 20000) -> dict[str, float]:
    """CPU per message, us, of each reader's callbacks on objects (deserialize + read) and on raw bytes."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Imu, JointState

    from shaper_nodes.core.stamps import stamp_to_sec
    from shaper_nodes.recordings.cdr import ImuCdr, JointStateCdr
    from shaper_nodes.recordings.cdr_sensors import JointStateReader, decode_imu
    from sim_plant_node.arm.description import JOINT_NAMES

    imu = ImuCdr("tool0")
    imu.set_stamp(12, 500_000)
    imu.linear_acceleration[:] = (0.1, -9.8, 0.3)
    js = JointStateCdr(list(JOINT_NAMES), 6, 6, 6)
    js.set_stamp(12, 500_000)
    js.position[:] = np.linspace(-1, 1, 6)
    imu_raw, js_raw = imu.data(), js.data()
    store: list[Any] = []
    names = list(JOINT_NAMES)

    def imu_objects() -> None:  # the demo client's and the identifier's IMU callback as it was
        m = deserialize_message(imu_raw, Imu)
        t = stamp_to_sec(m.header.stamp)
        a = m.linear_acceleration
        store.append((t, (a.x, a.y, a.z)))

    def imu_bytes() -> None:
        store.append(decode_imu(imu_raw))

    def js_objects() -> None:  # the demo client's tip state and reference callbacks as they were
        m = deserialize_message(js_raw, JointState)
        store.append((stamp_to_sec(m.header.stamp), list(m.position)))

    reader = JointStateReader()

    def js_bytes() -> None:
        t, _, position = reader(js_raw)
        store.append((t, list(position)))

    def calibrate_objects() -> None:  # calibrate's joint-state callback as it was (its recording left out)
        m = deserialize_message(js_raw, JointState)
        store.append(np.array([m.position[list(m.name).index(j)] for j in names], dtype=float))

    index = [names.index(j) for j in names]

    def calibrate_bytes() -> None:
        _, _, position = reader(js_raw)
        store.append(np.array([position[i] for i in index], dtype=float))

    out = {}
    for label, fn in (("Imu, objects", imu_objects), ("Imu, raw", imu_bytes), ("JointState, objects", js_objects),
                      ("JointState, raw", js_bytes), ("calibrate JointState, objects", calibrate_objects),
                      ("calibrate JointState, raw", calibrate_bytes)):
        out[label] = 1e6 * _cpu_per_call(fn, n)
        store.clear()
    return out


# ----------------------------------------------------------------------------------------------- batch
def batch(n: int = 2000, repeats: int = 3) -> dict[str, float]:
    """CPU per message, us, of a raw Imu reader over DDS (one process: a writer node and a reader node on one
    executor) taking a burst of ``n`` messages already queued (published reliable, acknowledged by the reader's
    DDS endpoint, none taken yet): one message per wake-up (rclpy's executor, ``raw``) or every queued message
    at a poll (``subscribe_draining``, ``raw_drain``). The least of ``repeats`` bursts each; the process's
    CPU time (its DDS threads included) from the first spin to the last message taken."""
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Imu

    from shaper_nodes.recordings.cdr import ImuCdr, stamp_parts
    from shaper_nodes.recordings.cdr_sensors import decode_imu

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    writer = rclpy.create_node("arm_readers_batch_writer", context=ctx)
    reader = rclpy.create_node("arm_readers_batch_reader", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    for node in (writer, reader):
        ex.add_node(node)
    got: list[Any] = []
    imu = ImuCdr("tool0")
    out: dict[str, float] = {}
    try:
        for mode in ("raw", "raw_drain"):
            topic = f"/arm_readers_batch_{mode}"
            pub = writer.create_publisher(Imu, topic, _stream_qos())
            sub = subscribe(reader, mode, Imu, topic, lambda raw: got.append(decode_imu(raw)))
            deadline = time.monotonic() + 60.0
            while not (pub.get_subscription_count() and sub.get_publisher_count()):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"arm_readers: the batch reader of {topic} did not match within 60 s")
                ex.spin_once(timeout_sec=0.01)
            best = float("inf")
            for _ in range(repeats):
                got.clear()
                for k in range(n):
                    imu.set_stamp(*stamp_parts(k * 1e-3))
                    pub.publish(imu.data())
                if not pub.wait_for_all_acked(Duration(seconds=60)):
                    raise RuntimeError("arm_readers: the batch reader did not acknowledge the burst within 60 s")
                cpu0 = time.process_time()
                while len(got) < n:
                    ex.spin_once(timeout_sec=1.0)
                best = min(best, time.process_time() - cpu0)
            out[mode] = 1e6 * best / n
            reader.destroy_subscription(sub)
            writer.destroy_publisher(pub)
    finally:
        ex.shutdown()
        writer.destroy_node()
        reader.destroy_node()
        ctx.try_shutdown()
    return out


def _stream_qos() -> Any:
    from shaper_nodes.ros.lockstep_reader import STREAM_QOS

    return STREAM_QOS


def subscribe(node: Any, mode: str, cls: Any, topic: str, callback: Callable[[Any], None]) -> Any:
    """The reader's subscription of ``topic`` in ``mode`` (STREAM_QOS)."""
    from shaper_nodes.ros.lockstep_reader import STREAM_QOS, subscribe_draining

    if mode == "raw_drain":
        return subscribe_draining(node, cls, topic, callback, STREAM_QOS)
    return node.create_subscription(cls, topic, callback, STREAM_QOS, raw=mode != "objects")
