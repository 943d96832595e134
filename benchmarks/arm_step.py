"""The lockstep arm node's own cost per 2 ms period, in one process: where the stepping path's time goes.

Run on its own (not by ``./run bench``): ``python -m benchmarks.arm_step [--seconds S] [--rounds N] [--profile]``.

The sim plant node (``plant.model: arm``, ``mode: lockstep``, 500 Hz, two physics steps a period) is made in this
process and its controller handed a trajectory of ``--seconds`` simulated s directly (no action round trip); then
its stepping path runs as the free run does (``_jtc_step`` and ``_publish_clock`` per period) until the trajectory
ends, with no executor and no reader. Its per-step writes go to DDS as in the node (``/joint_states``, two Imu,
``/clock``; the tip state and the reference only to a subscriber, none here). Printed: wall and CPU time per
period (least of ``--rounds``) and the simulated s per wall s that gives: the ceiling of the node's stepping thread
on this machine before any reader or executor. With ``--profile``, one more run under cProfile and its functions
with the most own and cumulative time per period (cProfile inflates small calls: read the shares).
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import sys
import time
from typing import Any

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
RATE = 500.0


def _node() -> tuple[Any, Any]:
    import rclpy
    from rclpy.parameter import Parameter

    from sim_plant_node.node.sim_plant import SimPlantNode

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    params = {"plant.model": "arm", "mode": "lockstep", "rate": RATE, "arm.substeps": 2, "task.start": HOME,
              "joint_states.idle_period": 0.0}
    overrides = [Parameter(k, value=v) for k, v in params.items()]
    return ctx, SimPlantNode(context=ctx, parameter_overrides=overrides)


def _trajectory(node: Any, seconds: float) -> None:
    from sim_plant_node.controller.jtc import RawPoint

    c = node.jtc.controller
    goal = [q + 0.3 for q in HOME]
    c.accept(list(c.joints), [RawPoint(seconds, goal, [0.0] * 6)], 0.0)


def run_once(node: Any, seconds: float, profile: cProfile.Profile | None = None) -> dict[str, float]:
    """Step ``node`` through a ``seconds`` s trajectory as its free run does; wall and CPU s per period."""
    _trajectory(node, seconds)
    steps = 0
    jtc = node.jtc
    if profile is not None:
        profile.enable()
    w0, c0 = time.perf_counter(), time.thread_time()
    while jtc.running:
        node._jtc_step()
        node._publish_clock()
        node._batch.period()  # (the node's writes kept and written together, as its free run does)
        steps += 1
    node._batch.flush()
    wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
    if profile is not None:
        profile.disable()
    return {"periods": steps, "wall us per period": 1e6 * wall / steps, "cpu us per period": 1e6 * cpu / steps,
            "sim s per wall s": steps / RATE / wall}


def measure(seconds: float = 4.0, rounds: int = 3, profile: bool = False, top: int = 25) -> dict[str, Any]:
    ctx, node = _node()
    try:
        runs = [run_once(node, seconds) for _ in range(rounds)]
        best = min(runs, key=lambda r: r["wall us per period"])
        out: dict[str, Any] = {"runs": runs, "best": best}
        if profile:
            prof = cProfile.Profile(time.thread_time)  # (CPU time: wall time would charge other processes here)
            r = run_once(node, seconds, prof)
            text = io.StringIO()
            stats = pstats.Stats(prof, stream=text)
            stats.sort_stats("tottime").print_stats(top)
            stats.sort_stats("cumulative").print_stats(top)
            out["profile"] = text.getvalue()
            out["profiled periods"] = r["periods"]
        return out
    finally:
        node.destroy_node()
        ctx.try_shutdown()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.arm_step", description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=4.0, help="simulated s of each trajectory (default 4)")
    p.add_argument("--rounds", type=int, default=3, help="runs; the least time per period is reported (default 3)")
    p.add_argument("--profile", action="store_true", help="one more run under cProfile, its top functions printed")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args(argv)
    if args.seconds <= 0 or args.rounds < 1:
        p.error("--seconds must be > 0 and --rounds >= 1")
    out = measure(args.seconds, args.rounds, args.profile)
    for r in out["runs"]:
        print(f"{r['periods']} periods: {r['wall us per period']:.1f} us wall, {r['cpu us per period']:.1f} us CPU"
              f" per period; {r['sim s per wall s']:.2f} sim s per wall s")
    b = out["best"]
    print(f"best: {b['wall us per period']:.1f} us wall per period, {b['sim s per wall s']:.2f} sim s per wall s")
    if "profile" in out:
        print(f"\ncProfile, {out['profiled periods']} periods (divide by them for per period)\n{out['profile']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({k: v for k, v in out.items() if k != "profile"}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
