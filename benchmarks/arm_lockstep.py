"""Lockstep speed of the six-axis arm: simulated seconds per wall second, six joints, 1 kHz physics.

Methods:

``baseline: pinocchio aba``
    One call of Pinocchio's articulated-body algorithm per 1 ms step (forward dynamics of the
    rigid arm): the least any Pinocchio-based simulation of this arm spends per step.
``ElasticArm step``
    The elastic-joint arm's step (mass matrix, nonlinear terms, the trapezoidal rule's 12 x 12
    solve), 1 kHz.
``ElasticArm step + IMU``
    The same plus the flange IMU (forward kinematics with accelerations) at every step.
``ArmPlant + controller``
    The controller emulation at 500 Hz sampling a trajectory, two physics steps and IMU
    readings per period: what the sim plant node computes per period.
``sim plant node over DDS``
    The sim plant node (``plant.model: arm``, lockstep) executing a FollowJointTrajectory goal
    sent over DDS, with /joint_states (500 Hz), the IMU (1 kHz) and /clock published and one
    subscriber on each; wall time from the goal's acceptance to its result.
``DDS writes alone``
    The ceiling of the node over DDS on this machine: a process that only publishes what the node
    publishes per 2 ms period (one JointState, one Clock and two Imu, all as CDR bytes as the node writes
    them, the node's QoS), as fast as it can, to the same subscriber, with no simulation at all.
``DDS writes alone, the demo's streams``
    The same for the writes of the node in lockstep with the demo's readers: six a period (the reference, two
    Imu, the joint state, the tip state, the clock; every per-step stream reliable and 10000 deep as in lockstep,
    all as CDR bytes as the node writes them) to one raw subscriber of them all. With ``ArmPlant + controller``
    it bounds the node with the demo's readers (``python -m benchmarks.arm_lockstep --bound`` prints only these).
``one Python reader's limit``
    The subscriber's CPU time per message taken (its process, DDS threads included, from its first
    message to its last) with the writer paced at 4x real time, which it follows, as the simulated
    rate at which the node's 2000 messages per simulated second take all of one core: no Python node
    reading all these topics follows faster.
``readers: sim plant node with a drained reader``
    The sim plant node in lockstep (``lockstep.readers``) with one reader process of the demo client's
    four per-step streams taken as the demo's readers take them (raw, every queued message on a 5 ms poll:
    :func:`shaper_nodes.ros.lockstep_reader.subscribe_draining`), a 10 s goal
    (:func:`benchmarks.arm_readers.lockstep`, mode ``raw_drain``); with the samples it lost (0 expected).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numpy as np

HOME = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])


def _rate(fn: Callable[[], None], sim_step: float, steps: int, repeats: int = 3) -> float:
    """Best simulated seconds per wall second of ``steps`` calls of ``fn`` (each ``sim_step`` s simulated)."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            fn()
        best = min(best, time.perf_counter() - t0)
    return steps * sim_step / best


def core(seconds: float = 2.0) -> dict:
    import pinocchio as pin

    from sim_plant_node.arm.dynamics import ArmModel, ElasticArm
    from sim_plant_node.arm.plant import ArmPlant
    from sim_plant_node.controller.jtc import JointTrajectoryController, RawPoint, Tolerances

    model = ArmModel()
    steps = int(seconds * 1000)
    q, v, tau = HOME.copy(), np.zeros(6), np.zeros(6)
    out = {"baseline: pinocchio aba": _rate(lambda: pin.aba(model.model, model.data, q, v, tau), 1e-3, steps)}
    arm = ElasticArm(model, 1e-3, HOME)
    target = HOME + 0.01
    out["ElasticArm step"] = _rate(lambda: arm.step(target), 1e-3, steps)

    def with_imu() -> None:
        arm.step(target)
        arm.imu()

    out["ElasticArm step + IMU"] = _rate(with_imu, 1e-3, steps)
    plant = ArmPlant(500.0, 2)
    plant.reset(HOME)
    names = [f"j{i}" for i in range(6)]
    ctl = JointTrajectoryController(tuple(names), 2e-3, Tolerances(np.zeros(6), np.zeros(6)), HOME)
    far = 10 * seconds * 4
    ctl.accept(names, [RawPoint(far, (HOME + 0.5).tolist(), [0.0] * 6)], 0.0)
    clock = [0.0]

    def period() -> None:
        ctl.update(clock[0], plant.base_position, plant.base_velocity)
        plant.step(ctl.command, velocity=ctl.command_velocity)
        clock[0] += 2e-3

    out["ArmPlant + controller"] = _rate(period, 2e-3, steps // 2)
    return out


def _counting_subscriber(ctx, demo: bool = False) -> tuple:
    """A node counting /joint_states, /tip_imu and /clock (``demo``: also the tip state and the reference, every
    per-step stream reliable, STREAM_QOS), raw: counted, not decoded (it shares the 2 cores); also its process's
    CPU time at the first and the last message."""
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu, JointState

    n = rclpy.create_node("arm_bench", context=ctx)
    from shaper_nodes.ros.lockstep_reader import STREAM_QOS

    counts = {"joint_states": 0, "imu": 0, "clock": 0}
    cpu = {"first": 0.0, "last": 0.0, "n": 0}  # the reader process's CPU time at its first and last message

    def count(key: str) -> Callable[[object], None]:
        def took(_m: object) -> None:
            counts[key] += 1
            cpu["last"], cpu["n"] = time.process_time(), cpu["n"] + 1
            if cpu["n"] == 1:
                cpu["first"] = cpu["last"]
        return took

    n.create_subscription(JointState, "/joint_states", count("joint_states"), STREAM_QOS if demo else 1000, raw=True)
    n.create_subscription(Imu, "/tip_imu", count("imu"), STREAM_QOS if demo else qos_profile_sensor_data, raw=True)
    n.create_subscription(Clock, "/clock", count("clock"), 1000, raw=True)
    if demo:
        for key, topic in (("tip_state", "/sim_plant/tip_state"), ("reference", "/sim_plant/reference")):
            counts[key] = 0
            n.create_subscription(JointState, topic, count(key), STREAM_QOS, raw=True)
    return n, counts, cpu


def node(seconds: float = 10.0, progress: Callable[[str], None] = print) -> dict:
    import rclpy
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from rclpy.executors import SingleThreadedExecutor
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from shaper_nodes.ros.action_client import ResilientActionClient
    from shaper_nodes.ros.launching import NodeProcess
    from sim_plant_node.arm.description import JOINT_NAMES

    from .arm_readers import succeeded

    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    with tempfile.TemporaryDirectory(prefix="arm_bench_") as tmp:
        sim = NodeProcess("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME.tolist()},
                          log_path=pathlib.Path(tmp) / "sim.log", env=env).start()
        ctx = rclpy.context.Context()
        rclpy.init(context=ctx)
        n, counts, _cpu = _counting_subscriber(ctx)
        client = ResilientActionClient(n, FollowJointTrajectory, "/joint_trajectory_controller/follow_joint_trajectory")
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(n)
        try:
            deadline = time.monotonic() + 60
            while not client.server_is_ready():
                if time.monotonic() > deadline or not sim.running():
                    raise RuntimeError("the sim plant's action server did not appear")
                ex.spin_once(timeout_sec=0.05)
            progress(f"arm: sim plant node executing a {seconds:g} s trajectory")
            target = (HOME + 0.3).tolist()
            point = JointTrajectoryPoint(positions=target, velocities=[0.0] * 6,
                                         time_from_start=Duration(sec=int(seconds)))
            goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(JOINT_NAMES),
                                                                         points=[point]))
            # timed from the request: the controller starts on accepting the goal, and a goal response that comes
            # late (or is lost and recovered from the status topic) must not hide the motion before it
            t0 = time.perf_counter()
            sent = client.send_goal_async(goal)
            while not sent.done():
                ex.spin_once(timeout_sec=0.01)
            result = sent.result().get_result_async()
            while not result.done():
                ex.spin_once(timeout_sec=0.01)
            wall = time.perf_counter() - t0
            succeeded(result.result(), "arm_lockstep")
        finally:
            ex.shutdown()
            client.destroy()
            n.destroy_node()
            ctx.try_shutdown()
            sim.stop()
    return {"sim plant node over DDS": seconds / wall, "received": counts}


def _write(periods: int, pace: float = 0.0, demo: bool = False) -> None:
    """The writer process of ``writes``: prints its wall time for ``periods`` periods as JSON (``pace``: simulated
    s per wall s to keep to; 0: as fast as it can). ``demo``: the writes of the node in lockstep with the demo's
    readers (also the tip state and the reference; every per-step stream reliable and 10000 deep, STREAM_QOS)."""
    import rclpy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu, JointState

    from shaper_nodes.recordings.cdr import ImuCdr, JointStateCdr, clock_cdr, stamp_parts
    from shaper_nodes.ros.lockstep_reader import STREAM_QOS
    from sim_plant_node.arm.description import JOINT_NAMES
    from sim_plant_node.node.sim_plant import LOCKSTEP_IMU_QOS
    from sim_plant_node.node.writer_profile import use_writer_profile

    use_writer_profile()  # the node's writer times (as the sim_plant executable)
    rclpy.init()
    n = rclpy.create_node("arm_bench_writer")
    deep = STREAM_QOS if demo else 10
    pubs = [n.create_publisher(JointState, "/joint_states", deep),
            n.create_publisher(Imu, "/tip_imu", LOCKSTEP_IMU_QOS), n.create_publisher(Clock, "/clock", 10)]
    if demo:
        pubs += [n.create_publisher(JointState, "/sim_plant/tip_state", deep),
                 n.create_publisher(JointState, "/sim_plant/reference", deep)]
    deadline = time.monotonic() + 60
    while any(p.get_subscription_count() == 0 for p in pubs):
        if time.monotonic() > deadline:
            raise SystemExit("no subscriber matched within 60 s")
        time.sleep(0.01)
    time.sleep(0.5)  # the matched subscriber's side of discovery
    js_pub, imu_pub, clock_pub = pubs[:3]
    names = list(JOINT_NAMES)
    js, imu, tip, ref = JointStateCdr(names, 6, 6, 6), ImuCdr("tool0"), JointStateCdr(names, 6, 6, 0), \
        JointStateCdr(names, 6, 0, 0)
    t0 = time.perf_counter()
    for k in range(periods):  # per period what the node writes: two IMU samples, the joint state, the clock
        if pace > 0:
            left = t0 + k * 2e-3 / pace - time.perf_counter()
            if left > 0:
                time.sleep(left)
        sec, nsec = stamp_parts(k * 2e-3)
        if demo:  # the reference, stamped at the period's start
            ref.set_stamp(sec, nsec)
            ref.position[:] = k
            pubs[4].publish(ref.data())
        for _ in range(2):  # (as the node: serialized in place, sensors.Sensors.publish_imu)
            imu.set_stamp(sec, nsec)
            imu.linear_acceleration[0] = float(k)
            imu_pub.publish(imu.data())
        js.set_stamp(sec, nsec)
        js.position[:] = k
        js_pub.publish(js.data())
        if demo:
            tip.set_stamp(sec, nsec)
            tip.position[:] = k
            pubs[3].publish(tip.data())
        clock_pub.publish(clock_cdr(sec, nsec))
    wall = time.perf_counter() - t0
    print(json.dumps({"wall": wall}), flush=True)
    n.destroy_node()
    rclpy.try_shutdown()


def writes(periods: int = 5000, pace: float = 4.0) -> dict:
    """Simulated s per wall s of the writes alone (the ``_write`` process) to the node's subscriber, as fast as the
    writer can; then, paced at ``pace`` (a rate the reader follows), the reader's CPU time per message."""
    fast = _writes(periods, 0.0)
    paced = _writes(int(periods * 0.4), pace)
    per_message = paced["cpu per message"]
    # the node's topics carry 2000 messages per simulated second: the rate at which this reader's CPU is all taken
    return {"DDS writes alone": fast["rate"], "writes received": fast["received"],
            "reader CPU per message, us": 1e6 * per_message, "reader took, paced": paced["received"],
            "one Python reader's limit": 1.0 / (2000 * per_message)}


def demo_writes(periods: int = 5000) -> dict:
    """Simulated s per wall s of the writes of the node in lockstep with the demo's readers alone (six a period:
    the reference, two Imu, the joint state, the tip state, the clock; the per-step streams reliable, STREAM_QOS)
    to one raw subscriber of them all, as fast as the writer can."""
    fast = _writes(periods, 0.0, demo=True)
    return {"DDS writes alone, the demo's streams": fast["rate"], "demo writes received": fast["received"]}


def _writes(periods: int, pace: float, demo: bool = False) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    n, counts, cpu = _counting_subscriber(ctx, demo)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(n)
    env_cmd = [sys.executable, "-m", "benchmarks.arm_lockstep", "--write", str(periods), "--pace", str(pace),
               *(["--demo"] if demo else [])]
    proc = subprocess.Popen(env_cmd, stdout=subprocess.PIPE, text=True)
    try:
        while proc.poll() is None:
            ex.spin_once(timeout_sec=0.01)
        out = proc.stdout.read() if proc.stdout else ""
        if proc.returncode != 0:
            raise RuntimeError(f"the writer process failed (exit {proc.returncode})")
        wall = json.loads(out.strip().splitlines()[-1])["wall"]
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # what is still in flight
            ex.spin_once(timeout_sec=0.01)
    finally:
        if proc.poll() is None:
            proc.kill()
        ex.shutdown()
        n.destroy_node()
        ctx.try_shutdown()
    return {"rate": periods * 2e-3 / wall, "received": counts,
            "cpu per message": (cpu["last"] - cpu["first"]) / max(cpu["n"] - 1, 1)}


def run(*, progress: Callable[[str], None] = print) -> dict:
    progress("arm: core stepping rates")
    out = core()
    out.update(node(progress=progress))
    progress("arm: the node's DDS writes alone")
    out.update(writes())
    out.update(demo_writes())
    from .arm_readers import lockstep as readers_lockstep

    drained = readers_lockstep(10.0, 1, progress, ("raw_drain",))[0]
    out["readers: sim plant node with a drained reader"] = drained["sim s per wall s"]
    out["readers: lost"] = sum((drained["lost"] or {}).values())
    return out


def print_table(fig: dict) -> None:
    base = fig["baseline: pinocchio aba"]
    print("\nLockstep speed of the arm (6 joints, 1 kHz physics): simulated s per wall s, and against one"
          " Pinocchio aba call per step")
    print(f"{'method':>28} | {'sim s / wall s':>14} | {'x of baseline':>13}")
    print("-" * 62)
    for key, value in fig.items():
        if isinstance(value, float) and not key.startswith("reader"):
            print(f"{key:>28} | {value:14.1f} | {value / base:13.3f}")
    if "reader CPU per message, us" in fig:
        took = fig["reader took, paced"]
        print(f"(the reader, the writer paced at 4x: {fig['reader CPU per message, us']:.1f} us of CPU per message"
              f" taken; it took {took['joint_states']} joint states, {took['imu']} IMU and {took['clock']} clock"
              " ticks of 2000, 4000 and 2000)")
    rec = fig.get("received", {})
    if rec:
        print(f"(the node run: received {rec['joint_states']} joint states, {rec['imu']} IMU messages and"
              f" {rec['clock']} clock ticks; IMU and clock are best effort or lossy under load)")
    rec = fig.get("writes received", {})
    if rec:
        print(f"(the writes alone: received {rec['joint_states']} joint states, {rec['imu']} IMU messages and"
              f" {rec['clock']} clock ticks)")
    if "DDS writes alone, the demo's streams" in fig:
        d = fig["DDS writes alone, the demo's streams"]
        print(f"(the writes of the node with the demo's readers alone, six a period, reliable: {d:.1f} sim s per wall"
              f" s; with ArmPlant + controller one process is bound to"
              f" {1 / (1 / d + 1 / fig['ArmPlant + controller']):.1f} here)")
    if "readers: sim plant node with a drained reader" in fig:
        print(f"(the node in lockstep with a drained reader of the demo client's four streams:"
              f" {fig['readers: sim plant node with a drained reader']:.2f} sim s per wall s,"
              f" {fig['readers: lost']} samples lost)")
    if "DDS writes alone" in fig and "sim plant node over DDS" in fig:
        bound = 1.0 / (1.0 / fig["DDS writes alone"] + 1.0 / fig["ArmPlant + controller"])
        print(f"the node over DDS at {fig['sim plant node over DDS'] / fig['DDS writes alone']:.2f} of the writes"
              f" alone; one process that simulates and writes, one after the other, is bound to {bound:.1f} sim s"
              f" per wall s here (the node at {fig['sim plant node over DDS'] / bound:.2f} of that)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", type=int, metavar="PERIODS", help="be the writer process of the writes-alone run")
    parser.add_argument("--pace", type=float, default=0.0, help="the writer's pace, sim s per wall s (0: flat out)")
    parser.add_argument("--demo", action="store_true", help="the writer: the node's writes with the demo's readers")
    parser.add_argument("--bound", action="store_true", help="only the rates of the one-process bound: ArmPlant +"
                        " controller, the writes alone and the demo's streams' writes alone")
    args = parser.parse_args()
    if args.write:
        _write(args.write, args.pace, args.demo)
    elif args.bound:
        fig = {k: v for k, v in core().items() if k == "ArmPlant + controller"}
        fig.update(writes())
        fig.update(demo_writes())
        sim, w, d = fig["ArmPlant + controller"], fig["DDS writes alone"], fig["DDS writes alone, the demo's streams"]
        print(json.dumps({k: v for k, v in fig.items() if isinstance(v, float)}, indent=1))
        print(f"one-process bound: {1 / (1 / sim + 1 / w):.1f} sim s per wall s (4 writes a period),"
              f" {1 / (1 / sim + 1 / d):.1f} with the demo's streams (6 writes a period)")
    else:
        fig = run()
        print_table(fig)
