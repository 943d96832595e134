"""Issue 18's measurement: the recorder killed with ``kill -9`` at random moments, and what is lost.

For each run, the recorder is started as a process (``ros2 run shaper_nodes recorder`` as the
suite starts it, on a ROS domain of its own), an in-process node publishes either a 500 Hz
sensor_msgs/Imu stream (kind ``imu500``) or only low-rate topics (kind ``lowrate``: a
shaper_msgs/CycleEvent at 1 Hz and a latched shaper_msgs/Shaper published once before the
recorder starts), and after a random time the recorder gets SIGKILL. The file is then read back
with the independent ``mcap`` reader (non-seeking, as a file without a footer must be read) and
``mcap_ros2``'s decoder, and compared with what was published before the kill: messages lost,
and the time they span (from the publish time of the first lost message to the kill). The last
columns are what the suite's reader (what ``analyze_bag`` prints) says about the recording: its
upper bound on the loss from the recorder's heartbeat, and whether the bound held.

Run with ``./run exec python scripts/recorder_kill_table.py`` (``--runs``, ``--min``/``--max``
recording seconds, ``--seed``, ``--domain``); it prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import random
import signal
import struct
import tempfile
import time
from dataclasses import dataclass

import rclpy
from builtin_interfaces.msg import Time
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

from shaper_msgs.msg import CycleEvent, Shaper
from shaper_nodes.recordings import Bag, describe_damage
from shaper_nodes.ros.launching import NodeProcess

RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TOPICS = {"imu500": ["/tip_imu"], "lowrate": ["/cycle_events", "/shaper/active_shaper"]}


@dataclass
class Row:
    kind: str
    duration: float        # s from the first publish to the kill
    published: int         # messages published before the kill (the latched one included)
    read: int              # read back by the independent reader
    lost: int              # published before the kill, not in the file
    lost_span: float       # s from the first lost message's publish time to the kill (0 if none lost)
    file_bytes: int
    bound_s: float | None  # the reader's bound on the time lost after the last flush, s
    bound_msgs: int | None  # and on the messages
    holds: bool | None
    since_beat: float | None  # s from the last heartbeat to the kill
    lag: float | None  # the receive lag the last heartbeat gives, s
    text: str


def stamp_of(t: float) -> Time:
    ns = int(t * 1e9)
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)


def independent(path: pathlib.Path) -> dict[str, list]:
    """topic -> decoded messages of every complete record (mcap's non-seeking reader, mcap_ros2)."""
    out: dict[str, list] = {}
    if not path.exists():
        return out
    with open(path, "rb") as f:
        try:
            for _, channel, _, decoded in NonSeekingReader(f, decoder_factories=[DecoderFactory()]
                                                           ).iter_decoded_messages(log_time_order=False):
                out.setdefault(channel.topic, []).append(decoded)
        except (McapError, EOFError, struct.error):
            pass  # the file ends where the kill cut it
    return out


def run_once(kind: str, duration: float, domain: int, out: pathlib.Path) -> Row:
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    node = rclpy.create_node("kill_table_source", context=ctx)
    sent: list[tuple[str, int, float]] = []  # topic, key, publish time
    if kind == "imu500":
        pub = node.create_publisher(Imu, "/tip_imu", RELIABLE)
        pubs, rate = [pub], 500.0
    else:
        latched = node.create_publisher(Shaper, "/shaper/active_shaper", LATCHED)
        latched.publish(Shaper(family="zv", source="kill table", revision=1))
        sent.append(("/shaper/active_shaper", 1, time.time()))
        pub = node.create_publisher(CycleEvent, "/cycle_events", RELIABLE)
        pubs, rate = [pub, latched], 1.0
    rec = NodeProcess("shaper_nodes", "recorder", {"output": str(out), "topics": TOPICS[kind]},
                      log_path=out.with_suffix(".log"), env=env).start()
    deadline = time.monotonic() + 60.0
    while not all(p.get_subscription_count() >= 1 for p in pubs):
        if time.monotonic() > deadline:
            raise RuntimeError(f"the recorder did not subscribe within 60 s (see {out.with_suffix('.log')})")
        time.sleep(0.01)
    start = time.time()
    k = 0
    while True:
        target = start + k / rate
        if target >= start + duration:
            break
        delay = target - time.time()
        if delay > 0:
            time.sleep(delay)
        t = time.time()
        if kind == "imu500":
            msg = Imu()
            msg.header.stamp, msg.header.frame_id = stamp_of(t), str(k)
            msg.linear_acceleration.z = 9.81
        else:
            msg = CycleEvent(event=k % 3, cycle=k // 3, task="kill table")
            msg.header.stamp = stamp_of(t)
        pub.publish(msg)
        sent.append((pub.topic_name, k, t))
        k += 1
    delay = start + duration - time.time()
    if delay > 0:
        time.sleep(delay)
    t_kill = time.time()
    assert rec.proc is not None
    os.kill(rec.proc.pid, signal.SIGKILL)
    rec.proc.wait(timeout=30)
    rec.stop()
    node.destroy_node()
    ctx.try_shutdown()

    mcap = out / f"{out.name}.mcap"
    read = independent(mcap)
    keys: set[tuple[str, int]] = set()
    for m in read.get("/tip_imu", []):
        keys.add(("/tip_imu", int(m.header.frame_id)))
    for m in read.get("/cycle_events", []):
        keys.add(("/cycle_events", int(m.cycle) * 3 + int(m.event)))
    for m in read.get("/shaper/active_shaper", []):
        keys.add(("/shaper/active_shaper", int(m.revision)))
    lost = [(topic, key, t) for topic, key, t in sent if (topic, key) not in keys]
    span = t_kill - min(t for _, _, t in lost) if lost else 0.0
    bound_s = bound_msgs = holds = since_beat = lag = None
    text = "file unreadable"
    try:
        with Bag(out) as bag:
            d = bag.damage[0] if bag.damage else None
            text = describe_damage(d) if d is not None else "closed"
            if d is not None and d.loss is not None:
                bound_s, bound_msgs = d.loss.seconds, d.loss.total
                holds = len(lost) <= bound_msgs and span <= bound_s
            if d is not None and d.heartbeat is not None:
                since_beat, lag = t_kill - d.heartbeat.stamp_ns * 1e-9, d.heartbeat.lag
    except Exception as err:  # the table shows why
        text = f"analysis failed: {err}"
    n_read = sum(len(v) for t, v in read.items() if not t.endswith("/heartbeat"))
    size = mcap.stat().st_size if mcap.exists() else 0
    return Row(kind, t_kill - start, len(sent), n_read, len(lost), span, size, bound_s, bound_msgs, holds,
               since_beat, lag, text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10, help="kills per kind (default 10)")
    ap.add_argument("--min", type=float, default=3.0, help="shortest recording before the kill, s")
    ap.add_argument("--max", type=float, default=15.0, help="longest recording before the kill, s")
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "50")),
                    help="first ROS domain id (one per run, counting up)")
    ap.add_argument("--kinds", default="imu500,lowrate")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        n = 0
        for kind in args.kinds.split(","):
            for i in range(args.runs):
                duration = rng.uniform(args.min, args.max)
                row = run_once(kind, duration, 1 + (args.domain + n) % 200, pathlib.Path(tmp) / f"{kind}_{i}")
                n += 1
                rows.append(row)
                print(f"# {kind} {i}: {row.duration:.2f} s, {row.published} published, {row.read} read,"
                      f" {row.lost} lost ({row.lost_span:.3f} s); bound {row.bound_s} s / {row.bound_msgs}",
                      flush=True)
    head = ("| # | kind | recorded s | published | read back | lost | lost s | MCAP bytes | kill after last"
            " heartbeat s | receive lag s | analysis: at most s | at most msgs | bound held |")
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    def num(x: float | None, fmt: str = ".2f") -> str:
        return "" if x is None else format(x, fmt)

    for i, r in enumerate(rows):
        held = "" if r.holds is None else ("yes" if r.holds else "NO")
        print(f"| {i} | {r.kind} | {r.duration:.2f} | {r.published} | {r.read} | {r.lost} | {r.lost_span:.3f} |"
              f" {r.file_bytes} | {num(r.since_beat, '.3f')} | {num(r.lag, '.3f')} | {num(r.bound_s)} |"
              f" {'' if r.bound_msgs is None else r.bound_msgs} | {held} |")
    for kind in args.kinds.split(","):
        ks = [r for r in rows if r.kind == kind]
        if ks:
            print(f"\n{kind}: most lost {max(r.lost_span for r in ks):.3f} s, {max(r.lost for r in ks)} messages;"
                  f" empty files {sum(r.file_bytes == 0 for r in ks)}; bound held in"
                  f" {sum(bool(r.holds) for r in ks)} of {len(ks)}")
            print(f"  e.g. the analysis: {ks[-1].text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
