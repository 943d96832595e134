"""The scheduler: one interpolation plus shaper design, and the node's CPU share at 500 Hz.

Timing (ROS-free, best of ``repeats`` passes of ``number`` calls each):

``evaluate + design``
    What the scheduler does per update: the TS rule base of config/scheduler.yaml (seed 004's
    two-mass system, eight rules, 4x4 models) evaluated at a pose (weights, interpolated model,
    its eigenvalues and lightly damped modes), and the ZV shaper designed on the mode.
``baseline: design``
    The ZV design alone (``core.shaping.families.design``), what any shaper change costs.

CPU share: the scheduler node (config/scheduler.yaml's rule base, evaluating every 0.05 s, a shaper
node answering its requests) gets ``/joint_states`` at 500 Hz for ``seconds`` s, the pose
sweeping 0..0.7 m so that it keeps sending shapers; its CPU time (``/proc/<pid>/stat``) over
that window divided by the window is its share of one core. The baseline is a bare rclpy node
(``rclpy.create_node``'s defaults: parameter services, /rosout) with one /joint_states
subscription that does nothing, on the same topic with the same QoS as the scheduler's
(``JOINT_STATES_DEPTH``, reliable, volatile), fed the same way. A third process, the *lean idle
node*, is that subscription alone on a node without parameter services, type description service
or /rosout, as the scheduler's own feed node (ros/side_node.py): the least an rclpy process pays
for the stream.

Run it with ``python -m benchmarks.scheduler`` or as part of ``python -m benchmarks``;
``python -m benchmarks.scheduler --baseline-node [--lean]`` is the bare node.
"""

from __future__ import annotations

import math
import os
import pathlib
import sys
import tempfile
import time
from collections.abc import Callable

import numpy as np

from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict
from shaper_nodes.core.shaping import Mode, design


def _spec() -> dict:
    from reproductions.scheduler_rules import rule_base_spec

    return rule_base_spec(np.linspace(0.0, 0.7, 8))


def best_call_time(fn: Callable[[], object], number: int, repeats: int) -> float:
    """Best over ``repeats`` passes of the mean time of one of ``number`` calls of ``fn``, s."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def timing(number: int = 200, repeats: int = 7) -> dict:
    core = Scheduler(rule_base_from_dict(_spec()), "model", "zv")
    poses = iter(np.tile(np.linspace(0.0, 0.7, 97), 10**6))

    def evaluate_design() -> None:
        core.scheduled(core.evaluate([next(poses)]))

    mode = Mode(0.5, 0.06)
    t_full = best_call_time(evaluate_design, number, repeats)
    t_design = best_call_time(lambda: design("zv", [mode]), number, repeats)
    return {"evaluate_design_us": 1e6 * t_full, "design_us": 1e6 * t_design, "ratio": t_full / t_design}


def _baseline_main(lean: bool) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState

    from shaper_nodes.nodes.scheduler import JOINT_STATES_DEPTH

    rclpy.init()
    if lean:
        node = Node("bench_idle", start_parameter_services=False, enable_rosout=False,
                    parameter_overrides=[Parameter("start_type_description_service", value=False)])
    else:
        node = Node("bench_idle")
    node.create_subscription(JointState, "/joint_states", lambda m: None, JOINT_STATES_DEPTH)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


#: the processes whose CPU is measured (the first is the baseline of the goal)
LABELS = ("idle node", "scheduler", "lean idle node", "scheduler, feed thread")


def cpu_share(seconds: float = 5.0, rate: float = 500.0, repeats: int = 2,
              progress: Callable[[str], None] = print) -> dict:
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from reproductions.scheduler_rules import scheduler_parameters
    from shaper_nodes.ros.launching import ChildProcess, NodeProcess

    from .proc_cpu import proc_cpu_seconds

    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    out: dict = {"rate_hz": rate, "seconds": seconds}
    with tempfile.TemporaryDirectory(prefix="sched_bench_") as tmp:
        log = pathlib.Path(tmp)
        shaper = NodeProcess("shaper_nodes", "shaper_node", {"joint_names": ["joint_1"], "command_rate": 500.0,
                                                             "retime_sources": ["scheduler"]},
                             log_path=log / "shaper.log", env=env).start()
        ctx = rclpy.context.Context()
        rclpy.init(context=ctx)
        node = Node("bench_driver", context=ctx)
        pub = node.create_publisher(JointState, "/joint_states", 50)
        runs: dict[str, list[dict]] = {label: [] for label in LABELS}
        try:
            def make(label: str, r: int) -> ChildProcess:
                if not label.startswith("scheduler"):
                    lean = ["--lean"] if label == "lean idle node" else []
                    return ChildProcess([sys.executable, "-m", "benchmarks.scheduler", "--baseline-node", *lean],
                                        log / f"idle{r}{len(lean)}.log", env=env, cwd=os.getcwd())
                feed = {"feed": "thread"} if label == "scheduler, feed thread" else {}  # rclpy's executor
                return NodeProcess("shaper_nodes", "scheduler", {**scheduler_parameters(_spec()), **feed},
                                   log_path=log / f"scheduler{r}.log", env=env)

            # alternated (idle, scheduler, lean, lean, scheduler, idle, ...) so that a drift of the outside load
            # hits all
            order = [(r, label) for r in range(repeats) for label in (LABELS if r % 2 == 0 else LABELS[::-1])]
            for r, label in order:
                proc = make(label, r)
                progress(f"scheduler: CPU of the {label} at {rate:g} Hz joint states ({seconds:g} s)")
                popen = proc.start().proc
                assert popen is not None  # (start() sets it)
                deadline = time.monotonic() + 120.0  # generous: a start-up at load 30 took more than 30 s
                while pub.get_subscription_count() < 1:
                    if time.monotonic() > deadline or not proc.running():
                        raise RuntimeError(f"{label} did not start or subscribe (see its log)")
                    time.sleep(0.05)
                time.sleep(1.0)  # discovery settles, the node warms up
                msg = JointState(name=["joint_1"], position=[0.0])
                n = int(seconds * rate)
                c0, t0 = proc_cpu_seconds(popen.pid), time.monotonic()
                for k in range(n):
                    msg.position = [0.35 + 0.35 * math.sin(2 * math.pi * 0.2 * k / rate)]
                    pub.publish(msg)
                    wait = t0 + (k + 1) / rate - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                c1, t1 = proc_cpu_seconds(popen.pid), time.monotonic()
                runs[label].append({"cpu_pct": 100.0 * (c1 - c0) / (t1 - t0), "sent_hz": n / (t1 - t0)})
                proc.stop()
                while pub.get_subscription_count() > 0 and time.monotonic() < t1 + 10.0:
                    time.sleep(0.05)
        finally:
            node.destroy_node()
            ctx.try_shutdown()
            shaper.stop()
    for label, got in runs.items():  # the least of the windows: outside load only adds
        out[label] = {"cpu_pct": min(g["cpu_pct"] for g in got), "sent_hz": min(g["sent_hz"] for g in got),
                      "windows_pct": [g["cpu_pct"] for g in got]}
    out["repeats"] = repeats
    out["ratio"] = out["scheduler"]["cpu_pct"] / max(out["idle node"]["cpu_pct"], 1e-9)
    out["ratio_lean"] = out["scheduler"]["cpu_pct"] / max(out["lean idle node"]["cpu_pct"], 1e-9)
    out["ratio_feed_thread"] = out["scheduler, feed thread"]["cpu_pct"] / max(out["idle node"]["cpu_pct"], 1e-9)
    return out


def run(*, seconds: float = 5.0, progress: Callable[[str], None] = print) -> dict:
    progress("scheduler: timing one interpolation + design")
    return {"timing": timing(), "cpu": cpu_share(seconds, progress=progress)}


def print_table(result: dict) -> None:
    t, c = result["timing"], result["cpu"]
    print("scheduler (seed 004 rule base, 8 rules, 4x4 models)")
    print(f"  evaluate + ZV design : {t['evaluate_design_us']:8.1f} us per update")
    print(f"  baseline: ZV design  : {t['design_us']:8.1f} us            ratio {t['ratio']:.2f}")
    print(f"  CPU at {c['rate_hz']:g} Hz joint states ({c['seconds']:g} s):")
    for label in LABELS:
        windows = ", ".join(f"{w:.1f}" for w in c[label]["windows_pct"])
        print(f"    {label:14s}: {c[label]['cpu_pct']:5.1f} % of one core (fed at {c[label]['sent_hz']:.0f} Hz;"
              f" windows {windows})")
    print(f"    ratio scheduler / idle node: {c['ratio']:.2f}; scheduler / lean idle node: {c['ratio_lean']:.2f};"
          f" the scheduler with its feed on rclpy's executor / idle node: {c['ratio_feed_thread']:.2f}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--baseline-node" in argv:
        return _baseline_main("--lean" in argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    print_table(run(progress=lambda s: print(f"[bench] {s}", file=sys.stderr, flush=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
