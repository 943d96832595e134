"""The arm's readers: message objects against serialized bytes, per message and with the sim plant in lockstep.

Run on its own (not by ``./run bench``): ``python -m benchmarks.arm_readers [--seconds S] [--rounds N]``.

Two parts, each a ratio of one run:

``callbacks``
    In one process, no DDS: the CPU time per message of the demo client's callbacks as they were
    (``deserialize_message``, the conversion rclpy does for a subscription that is not raw, then the
    callback reading the message object) and as they are (the serialized bytes read by
    :mod:`shaper_nodes.recordings.cdr_sensors`), on the bytes the sim plant publishes (an Imu and a
    six-joint JointState with positions, velocities and efforts). Also calibrate's and the identifier's
    joint-state callbacks the same way.
``batch``
    Over DDS, in one process: a raw Imu reader's CPU per message taking a burst already in its queue, one
    message per wake-up of rclpy's executor (``raw``) or all of them at a poll (``raw_drain``,
    :func:`shaper_nodes.ros.lockstep_reader.subscribe_draining`).
``lockstep``
    The sim plant node (``plant.model: arm``, ``mode: lockstep``, ``lockstep.readers`` naming the reader)
    executing a FollowJointTrajectory goal of ``--seconds`` simulated s sent to its controller, with one
    reader process that takes the demo client's four per-step streams (/tip_imu at 1 kHz,
    /joint_states, /sim_plant/tip_state and /sim_plant/reference at 500 Hz; reliable, STREAM_QOS) and
    acknowledges them (LockstepReader), either as message objects (``objects``), raw (``raw``), raw with
    every queued message taken on a 5 ms poll (``raw_drain``: ``subscribe_draining``, as the suite's readers) or
    raw on rclpy's
    EventsExecutor (``raw_events``), in rounds that alternate them (``--modes`` picks some), with ``--readers``
    such reader processes (the demo's cases have three: its client, the identifier, the recorder). Per run: the
    plant's simulated s per wall s (from the goal's request
    to its result), the reader's CPU time per simulated s (its process, DDS threads included, from its
    first message to its last), and the samples it lost (gaps in the stamps; 0 expected: the plant
    waits for it).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import pathlib
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

from benchmarks.arm_reader_calls import batch, callbacks, subscribe

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
RATE, SUBSTEPS = 500.0, 2
IMU, LINK, CMD, JOINTS = "/tip_imu", "/sim_plant/tip_state", "/sim_plant/reference", "/joint_states"
READER = "arm_readers_reader"
#: the reader's modes: message objects (the readers before issue 34), raw bytes, raw bytes with every queued message
#: taken on a poll (``subscribe_draining``, the readers now), raw bytes on rclpy's EventsExecutor
MODES = ("objects", "raw", "raw_drain", "raw_events")
#: the plant in lockstep with no reader (the ceiling of the runs with one)
ALONE = "alone"


def succeeded(result: Any, what: str) -> None:
    """Raise unless a FollowJointTrajectory goal's result (``get_result_async``'s) says SUCCEEDED: no rate is
    reported for a goal that failed (aborted, or unknown to a server that went away)."""
    from action_msgs.msg import GoalStatus

    if result.status != GoalStatus.STATUS_SUCCEEDED:
        raise RuntimeError(f"{what}: the goal ended with status {result.status} ({result.result.error_string})")


# -------------------------------------------------------------------------------------------- lockstep
def _sample(seen: dict[str, float], t: float) -> None:
    """The reader's CPU time and its span of stamps at its ``seen["n"]``-th message, stamped ``t`` s."""
    cpu = time.process_time()
    if seen["n"] == 1:
        seen["cpu0"] = cpu
    seen["cpu1"], seen["n1"] = cpu, seen["n"]
    seen["t0"], seen["t1"] = min(seen["t0"], t), max(seen["t1"], t)


def _reader(mode: str, name: str = READER) -> None:
    """The reader process ``name``: the demo client's four per-step streams, as objects or raw; prints JSON on
    SIGTERM."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import Imu, JointState

    from shaper_nodes.recordings.cdr_sensors import JointStateReader, decode_imu
    from shaper_nodes.ros.conversions import time_to_sec
    from shaper_nodes.ros.lockstep_reader import LockstepReader

    rclpy.init()
    node = rclpy.create_node(name)
    lock = LockstepReader(node, {IMU: 1.0 / (RATE * SUBSTEPS), LINK: 1.0 / RATE, CMD: 1.0 / RATE, JOINTS: 1.0 / RATE})
    took = lock.took
    seen = {"n": 0, "n1": 1, "cpu0": 0.0, "cpu1": 0.0, "t0": float("inf"), "t1": float("-inf")}
    kept: dict[str, list[Any]] = {IMU: [], LINK: [], CMD: [], JOINTS: []}

    def count(t: float) -> None:
        # the process's CPU time read at the first message and every 256th (reading it costs a system call that
        # sums every thread's time: tens of us under load, which a reader per message would count as its own)
        seen["n"] += 1
        if seen["n"] == 1 or not int(seen["n"]) & 255:
            _sample(seen, t)

    if mode == "objects":  # the demo client's callbacks before issue 34
        def on_imu(m: Any) -> None:
            t = time_to_sec(m.header.stamp)
            a = m.linear_acceleration
            kept[IMU].append((t, (a.x, a.y, a.z)))
            took(IMU, t)
            count(t)

        def on_js(topic: str) -> Callable[[Any], None]:
            def cb(m: Any) -> None:
                t = time_to_sec(m.header.stamp)
                kept[topic].append((t, list(m.position)))
                took(topic, t)
                count(t)
            return cb
    else:
        def on_imu(m: Any) -> None:
            t, a = decode_imu(m)
            kept[IMU].append((t, a))
            took(IMU, t)
            count(t)

        def on_js(topic: str) -> Callable[[Any], None]:
            read = JointStateReader()

            def cb(m: Any) -> None:
                t, _, position = read(m)
                kept[topic].append((t, list(position)))
                took(topic, t)
                count(t)
            return cb
    subs = [subscribe(node, mode, Imu, IMU, on_imu)]
    for topic in (LINK, CMD, JOINTS):
        subs.append(subscribe(node, mode, JointState, topic, on_js(topic)))
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    if mode == "raw_events":
        from rclpy.experimental import EventsExecutor

        ex: Any = EventsExecutor()
    else:
        ex = SingleThreadedExecutor()
    ex.add_node(node)
    ready = False
    try:
        while not stop:
            ex.spin_once(timeout_sec=0.05)
            if not ready and all(sub.get_publisher_count() > 0 for sub in subs):
                ready = True  # every stream matched: the bench may send the goal
                print("ready", flush=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    print(json.dumps({"messages": seen["n"], "sampled": seen["n1"], "cpu": seen["cpu1"] - seen["cpu0"],
                      "span": seen["t1"] - seen["t0"],
                      "lost": lock.lost(), "processed": lock.processed,
                      "counts": {k: len(v) for k, v in kept.items()}}), flush=True)
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


def _cpu_of(pid: int) -> float:
    """CPU time, s, of process ``pid`` so far (user and system, all its threads; Linux /proc)."""
    fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _one(mode: str, seconds: float, tmp: pathlib.Path, progress: Callable[[str], None],
         profile: pathlib.Path | None = None, readers: int = 1) -> dict[str, Any]:
    import rclpy
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from shaper_nodes.ros.action_client import ResilientActionClient
    from shaper_nodes.ros.launching import ChildProcess, NodeProcess, executable, ros_args
    from shaper_nodes.ros.lockstep_reader import AckWatch, header_stamp, subscribe_draining, take_all
    from sim_plant_node.arm.description import JOINT_NAMES

    from .arm_threads import between, run_figures, snapshot

    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    alone = mode == ALONE
    names = [] if alone else [READER if k == 0 else f"{READER}_{k}" for k in range(readers)]
    params = {"plant.model": "arm", "mode": "lockstep", "rate": RATE, "arm.substeps": SUBSTEPS, "task.start": HOME,
              "lockstep_timeout": 60.0, "lockstep.readers": ["/" + name for name in names]}
    if profile is None:
        sim: Any = NodeProcess("sim_plant_node", "sim_plant", params, log_path=tmp / f"sim-{mode}.log", env=env)
    else:  # cProfile in every thread of the plant (benchmarks._profiled), written to profile-<mode>.prof
        sim = ChildProcess([sys.executable, "-m", "benchmarks._profiled", str(profile / f"profile-{mode}.prof"),
                            str(executable("sim_plant_node", "sim_plant")), *ros_args(params)],
                           tmp / f"sim-{mode}.log", env, cwd=pathlib.Path(__file__).resolve().parents[1])
    sim.start()
    procs = _ReaderProcesses(mode, names)  # (alone: none, the plant waits for no reader)

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    n = rclpy.create_node("arm_readers_bench", context=ctx)
    clock = [0.0]

    def on_clock(raw: bytes) -> None:  # (rosgraph_msgs/Clock begins with its Time, as a header does)
        clock[0] = max(clock[0], header_stamp(raw))

    # the bench's own reader of /clock, drained on a poll: a callback per tick (rclpy's executor, ~80 us each) took
    # 0.04 CPU s per simulated s on the two cores the plant and its reader share, more than the plant's main thread
    clock_sub = subscribe_draining(n, Clock, "/clock", on_clock, 100)
    acks = [AckWatch(n, "/" + name) for name in names]
    client = ResilientActionClient(n, FollowJointTrajectory, "/joint_trajectory_controller/follow_joint_trajectory")
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(n)

    def spin_until(done: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline or not sim.running() or procs.ended():
                raise RuntimeError(f"arm_readers: no {what} within {timeout:g} s (or a process ended; {tmp})")
            ex.spin_once(timeout_sec=0.01)
    try:
        spin_until(client.server_is_ready, 60.0, "action server")
        if not alone:
            for ack in acks:
                ack.wait_subscribed(spin_until, (IMU, LINK, CMD, JOINTS), 60.0)
            spin_until(procs.ready, 60.0, "match of the readers' four subscriptions with the plant's publishers")
            end_ready = time.monotonic() + 0.5  # the writers' side of the match (a benchmark: no test waits on it)
            spin_until(lambda: time.monotonic() > end_ready, 5.0, "")
        target = [q + 0.3 for q in HOME]
        point = JointTrajectoryPoint(positions=target, velocities=[0.0] * 6, time_from_start=Duration(sec=int(seconds)))
        goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES), points=[point]))
        progress(f"arm readers: {mode}{f' x {readers}' if readers > 1 and not alone else ''}, a {seconds:g} s goal in"
                 " lockstep")
        assert sim.proc is not None
        pids = [sim.proc.pid, *(proc.pid for proc in procs.procs)]
        threads0 = [snapshot(pid) for pid in pids]  # (per thread: benchmarks.arm_threads)
        cpu0, t0 = _cpu_of(sim.proc.pid), time.perf_counter()
        sent = client.send_goal_async(goal)
        spin_until(sent.done, 60.0, "goal response")
        result = sent.result().get_result_async()
        spin_until(result.done, 600.0, "result")
        wall, plant_cpu = time.perf_counter() - t0, (_cpu_of(sim.proc.pid) - cpu0) / seconds
        threads = [between(a, snapshot(pid)) for pid, a in zip(pids, threads0, strict=True)]
        per_thread = run_figures(pids[0], threads[0], threads[1:], seconds, round(seconds * RATE))
        succeeded(result.result(), "arm_readers")
        take_all(clock_sub, Clock, lambda got: on_clock(got[0]), 1000)  # (the ticks since the last poll)
        end = clock[0]
        if alone:
            return {"mode": mode, "sim s per wall s": seconds / wall, "plant CPU per sim s": plant_cpu, **per_thread}
        for ack in acks:
            try:  # the samples of the run's last period (the reference is stamped at its period's start)
                spin_until(functools.partial(_reached, ack, end - 1.0 / RATE - 1e-6), 60.0, "")
            except RuntimeError:
                raise RuntimeError(f"arm_readers: {ack.reader} acknowledged up to {ack.processed:.4f} s, the clock"
                                   f" is at {end:.4f} s") from None
    finally:
        gots = procs.stop()
        ex.shutdown()
        client.destroy()
        n.destroy_node()
        ctx.try_shutdown()
        sim.stop()
    return {"mode": mode, "readers": readers, "sim s per wall s": seconds / wall, "plant CPU per sim s": plant_cpu,
            **per_thread, **_combined(mode, gots, wall)}


def _reached(ack: Any, t: float) -> bool:
    """Whether the reader of ``ack`` (an AckWatch) acknowledged simulated time ``t`` s."""
    return bool(ack.processed >= t)


class _ReaderProcesses:
    """The reader processes of a lockstep run (``--reader MODE --name NAME``), their output read as they go."""

    def __init__(self, mode: str, names: list[str]) -> None:
        self.procs = [subprocess.Popen([sys.executable, "-m", "benchmarks.arm_readers", "--reader", mode, "--name",
                                        name], stdout=subprocess.PIPE) for name in names]
        self.said: list[list[bytes]] = [[] for _ in self.procs]
        for proc in self.procs:
            os.set_blocking(self._fd(proc), False)

    @staticmethod
    def _fd(proc: subprocess.Popen) -> int:
        assert proc.stdout is not None
        return proc.stdout.fileno()

    def ready(self) -> bool:
        """Whether every reader said its subscriptions matched the plant's publishers."""
        for proc, out in zip(self.procs, self.said, strict=True):
            with contextlib.suppress(BlockingIOError):
                out.append(os.read(self._fd(proc), 65536))
        return all(b"ready" in b"".join(out) for out in self.said)

    def ended(self) -> bool:
        return any(proc.poll() is not None for proc in self.procs)

    def stop(self) -> list[dict[str, Any]]:
        """Stop the readers (SIGTERM); their figures (the JSON line each prints)."""
        outs = []
        for proc, out in zip(self.procs, self.said, strict=True):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            os.set_blocking(self._fd(proc), True)
            outs.append((b"".join(out) + (proc.communicate(timeout=60)[0] or b"")).decode())
        return [json.loads(out.strip().splitlines()[-1]) for out in outs]


def _combined(mode: str, gots: list[dict[str, Any]], wall: float) -> dict[str, Any]:
    """The readers' figures together: CPU per simulated s summed, per message their mean, samples lost summed."""
    lost: dict[str, int] = {}
    for got in gots:
        if got["messages"] < 2 or got["span"] <= 0:
            raise RuntimeError(f"arm_readers: the {mode} reader took {got['messages']} messages ({got}; {wall:.3f} s)")
        for topic, k in (got["lost"] or {}).items():
            lost[topic] = lost.get(topic, 0) + k
    return {"reader CPU per sim s": sum(got["cpu"] / got["span"] for got in gots),
            "reader CPU per message, us": statistics.mean(1e6 * got["cpu"] / max(got["sampled"] - 1, 1)
                                                          for got in gots),
            "lost": lost, "counts": {k: sum(got["counts"][k] for got in gots) for k in gots[0]["counts"]}}


def lockstep(seconds: float = 10.0, rounds: int = 2, progress: Callable[[str], None] = print,
             modes: tuple[str, ...] = (ALONE, *MODES), profile: pathlib.Path | None = None,
             readers: int = 1) -> list[dict[str, Any]]:
    """``rounds`` x ``modes`` runs of the plant in lockstep with ``readers`` reader processes (module docstring),
    the order reversed every other round."""
    runs = []
    with tempfile.TemporaryDirectory(prefix="arm_readers_") as tmp:
        for k in range(rounds):
            for mode in (modes if k % 2 == 0 else modes[::-1]):
                runs.append(_one(mode, seconds, pathlib.Path(tmp), progress, profile, readers))
    return runs


def print_tables(per_message: dict[str, float], runs: list[dict[str, Any]]) -> None:
    if per_message:
        print("\nThe arm's readers' callbacks, CPU per message (one process, no DDS; least of 5 passes)")
        print(f"{'callback':>38} | {'us':>7} | {'raw / objects':>13}  (a burst: raw_drain / raw)")
    for key, value in per_message.items():
        base = per_message.get(key.replace("raw_drain", "raw") if "burst" in key else
                               key.replace(", raw", ", objects"), value)
        print(f"{key:>38} | {value:7.2f} | {value / base:13.2f}")
    if not runs:
        return
    count = max(r.get("readers", 1) for r in runs)
    print(f"\nThe sim plant in lockstep with {'one reader' if count == 1 else f'{count} readers'} of the demo"
          " client's four streams (reader CPU: all of them)")
    print(f"{'reader':>10} | {'sim s / wall s':>14} | {'plant CPU s / sim s':>19} | {'reader CPU s / sim s':>20} |"
          f" {'us / message':>12} | taken | lost")
    for r in runs:
        if r["mode"] == ALONE:
            print(f"{'no reader':>10} | {r['sim s per wall s']:14.2f} | {r['plant CPU per sim s']:19.3f} |")
            continue
        print(f"{r['mode']:>10} | {r['sim s per wall s']:14.2f} | {r['plant CPU per sim s']:19.3f} |"
              f" {r['reader CPU per sim s']:20.3f} |"
              f" {r['reader CPU per message, us']:12.1f} | {sum(r['counts'].values()):5d} | {r['lost'] or 0}")
    keys = ("sim s per wall s", "reader CPU per sim s")
    ran = [m for m in MODES if any(r["mode"] == m for r in runs)]
    med = {m: {k: statistics.median(r[k] for r in runs if r["mode"] == m) for k in keys} for m in ran}
    for mode in ran[1:]:
        speed, cpu = (med[mode][k] / med[ran[0]][k] for k in keys)
        print(f"medians, {mode} / {ran[0]}: sim s per wall s {speed:.2f}, reader CPU per sim s {cpu:.2f}")
    alone = [r["sim s per wall s"] for r in runs if r["mode"] == ALONE]
    if alone:
        print(f"the plant with no reader: median {statistics.median(alone):.2f} sim s per wall s")
    threaded = [r for r in runs if "plant main thread CPU per sim s" in r]
    if threaded:  # (benchmarks.arm_threads: Linux only)
        print("\nPer run, the plant's main thread (CPU and wait for a core per sim s, preempted per period) and the"
              " readers' DDS receive threads (wake-ups per sim s)")
        for r in threaded:
            label = r["mode"] if r["mode"] != ALONE else "no reader"
            cpu, waiting = r["plant main thread CPU per sim s"], r["plant main thread waiting per sim s"]
            preempted, wakeups = r["plant main thread preemptions per period"], r["readers' DDS wake-ups per sim s"]
            print(f"{label:>10} | {r['sim s per wall s']:6.2f} sim s/wall s | CPU {cpu:.4f} | waiting {waiting:.4f} |"
                  f" preempted {preempted:.2f} | wake-ups {wakeups:.0f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.arm_readers", description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="simulated s of each lockstep run (default 10)")
    p.add_argument("--rounds", type=int, default=2, help="rounds of lockstep runs, one per mode (default 2; 0: none)")
    p.add_argument("--modes", default=",".join((ALONE, *MODES)),
                   help=f"the runs of a round, comma-separated, of {', '.join((ALONE, *MODES))} (default all)")
    p.add_argument("--readers", type=int, default=1, help="reader processes in each lockstep run, each of the four"
                   " streams (default 1; the demo's cases have three: its client, the identifier, the recorder)")
    p.add_argument("--callbacks", action=argparse.BooleanOptionalAction, default=True,
                   help="also the per-message parts (callbacks, batch) before the lockstep runs (default on)")
    p.add_argument("--reader", choices=MODES, help=argparse.SUPPRESS)
    p.add_argument("--name", default=READER, help=argparse.SUPPRESS)
    p.add_argument("--json", type=pathlib.Path, help="also write the figures to this JSON file")
    p.add_argument("--profile-plant", type=pathlib.Path, metavar="DIR",
                   help="run the sim plant under cProfile (every thread's CPU time), one profile-<mode>.prof per mode"
                   " in DIR")
    args = p.parse_args(argv)
    if args.reader:
        _reader(args.reader, args.name)
        return 0
    if args.readers < 1:
        p.error("--readers must be at least 1")
    per_message = callbacks() if args.callbacks else {}
    if args.callbacks:
        per_message.update({f"Imu over DDS, a burst, {mode}": us for mode, us in batch().items()})
    modes = tuple(m.strip() for m in args.modes.split(",") if m.strip())
    unknown = [m for m in modes if m not in (ALONE, *MODES)]
    if unknown or not modes:
        p.error(f"--modes: unknown mode(s) {', '.join(unknown) or '(none given)'}; known: {', '.join((ALONE, *MODES))}")
    runs = lockstep(args.seconds, args.rounds, lambda s: print(f"[bench] {s}", file=sys.stderr, flush=True), modes,
                    args.profile_plant, args.readers)
    print_tables(per_message, runs)
    if args.json:
        args.json.write_text(json.dumps({"callbacks": per_message, "lockstep": runs}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
