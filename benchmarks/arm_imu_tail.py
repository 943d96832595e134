"""Whether a burst of the plant's reliable Imu samples reaches a reader to its last sample: message objects against
CDR bytes.

Run on its own: ``python -m benchmarks.arm_imu_tail [--bursts N] [--size S] [--wait W]``.

A writer process publishes ``--bursts`` bursts of ``--size`` Imu samples on the plant's lockstep QoS (reliable,
KEEP_LAST 10000, ``LOCKSTEP_IMU_QOS``), as fast as it can, alternating the way they are published: ``objects`` (an
``Imu`` message object, serialized by rclpy, as the node did before) and ``bytes`` (``ImuCdr``'s bytes, as the node
does now). A reader process takes them raw as calibrate does (reliable, KEEP_LAST 5000, every queued sample per
wake-up: ``subscribe_draining``). After each burst the writer waits until the reader reports the burst's last stamp
or ``--wait`` s pass, and writes nothing meanwhile (as the plant at rest writes no Imu). Printed per burst: the way,
the writer's wall time, whether the last sample came, and how many of the burst's samples the reader took.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import time

TOPIC, DONE = "/arm_tail_imu", "/arm_tail_seen"


def _reader() -> None:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64

    from shaper_nodes.ros.lockstep_reader import subscribe_draining

    rclpy.init()
    node = rclpy.create_node("arm_tail_reader")
    seen = node.create_publisher(Float64, DONE, 10)
    state = {"last": -1.0, "n": 0}

    def on_imu(raw: bytes) -> None:
        sec, nsec = int.from_bytes(raw[4:8], "little", signed=True), int.from_bytes(raw[8:12], "little")
        state["last"] = max(state["last"], sec + 1e-9 * nsec)
        state["n"] += 1

    deep = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    subscribe_draining(node, Imu, TOPIC, on_imu, deep)

    def report() -> None:
        seen.publish(Float64(data=state["last"]))
        seen.publish(Float64(data=-1.0 - state["n"]))  # (negative: the count taken so far)

    node.create_timer(0.05, report)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        ex.spin()


def run(bursts: int, size: int, wait: float) -> list[dict]:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64

    from shaper_nodes.recordings.cdr import ImuCdr, stamp_parts
    from sim_plant_node.node.sim_plant import LOCKSTEP_IMU_QOS

    reader = subprocess.Popen([sys.executable, "-m", "benchmarks.arm_imu_tail", "--reader"], env=dict(os.environ))
    rclpy.init()
    node = rclpy.create_node("arm_tail_writer")
    pub = node.create_publisher(Imu, TOPIC, LOCKSTEP_IMU_QOS)
    got = {"last": -1.0, "n": 0}

    def on_seen(m: Float64) -> None:
        if m.data <= -1.0:
            got["n"] = int(round(-m.data - 1.0))
        else:
            got["last"] = max(got["last"], m.data)

    node.create_subscription(Float64, DONE, on_seen, 10)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    deadline = time.monotonic() + 60
    while pub.get_subscription_count() == 0 or got["n"] < 0 or node.count_publishers(DONE) == 0:
        if time.monotonic() > deadline:
            raise SystemExit("arm_imu_tail: the reader did not match within 60 s")
        ex.spin_once(timeout_sec=0.05)
    end = time.monotonic() + 1.0  # the reader's side of the match
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    cdr, msg = ImuCdr("tool0"), Imu()
    msg.header.frame_id = "tool0"
    msg.orientation_covariance[0] = -1.0
    cdr.orientation_covariance[0] = -1.0
    rows, k = [], 0
    for b in range(bursts):
        way = "objects" if b % 2 == 0 else "bytes"
        n0 = got["n"]
        w0 = time.perf_counter()
        for _ in range(size):
            k += 1
            sec, nsec = stamp_parts(k * 1e-3)
            if way == "bytes":
                cdr.set_stamp(sec, nsec)
                cdr.linear_acceleration[0] = float(k)
                pub.publish(cdr.data())
            else:
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
                msg.linear_acceleration.x = float(k)
                pub.publish(msg)
        wall = time.perf_counter() - w0
        last = k * 1e-3
        t0 = time.monotonic()
        while got["last"] < last - 1e-9 and time.monotonic() - t0 < wait:
            ex.spin_once(timeout_sec=0.05)
        came = got["last"] >= last - 1e-9
        t_last = time.monotonic() - t0
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        rows.append({"burst": b, "way": way, "write s": wall, "last came": came, "after s": t_last,
                     "taken": got["n"] - n0, "load": os.getloadavg()[0]})
        print(json.dumps(rows[-1]), flush=True)
    reader.terminate()
    reader.wait(timeout=30)
    node.destroy_node()
    rclpy.try_shutdown()
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.arm_imu_tail", description=__doc__.splitlines()[0])
    p.add_argument("--bursts", type=int, default=10, help="bursts, alternately objects and bytes (default 10)")
    p.add_argument("--size", type=int, default=3000, help="samples per burst (default 3000)")
    p.add_argument("--wait", type=float, default=30.0, help="s to wait for a burst's last sample (default 30)")
    p.add_argument("--reader", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.reader:
        _reader()
        return 0
    rows = run(args.bursts, args.size, args.wait)
    for way in ("objects", "bytes"):
        mine = [r for r in rows if r["way"] == way]
        print(f"{way}: last sample came in {sum(r['last came'] for r in mine)} of {len(mine)} bursts;"
              f" taken {[r['taken'] for r in mine]}; write s {[round(r['write s'], 3) for r in mine]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
