"""A one-joint lockstep sim plant's own cost per step, in one process: the LIST cases' plant without DDS round trips.

Run on its own (not by ``./run bench``): ``python -m benchmarks.plant_step [--model M] [--steps N] [--rounds R]
[--profile]``.

The sim plant node (``plant.model`` M, default ``list_time_varying``: seed 003's case 2; ``mode: lockstep``, 250 Hz,
``lockstep.block`` 25 as ``reproductions.list_cases`` runs it) is made in this process with a long task, and its
lockstep path runs as the shaper's answers drive it (``_step_asked`` with each block's last raw setpoint in every
row: no shaper, no DDS round trip, no executor); its per-step writes go to DDS as in the node. Printed: the
CPU time per step (least of ``--rounds``) and the CPU s per simulated s that gives. With ``--profile``, one more run
under cProfile and its functions with the most own time (cProfile inflates small calls: read the shares).
:mod:`benchmarks.arm_step` is the same for the arm.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from typing import Any

import numpy as np

RATE = 250.0
#: the node's parameters for reproductions/list_cases.py's plant (the paper's m, b, k and task)
PARAMS: dict[str, Any] = {
    "joint_names": ["joint_1"], "rate": RATE, "mode": "lockstep", "lockstep.block": 25, "imu.axes": [0, -1, -1],
    "plant.mass": [1.0], "plant.damping": [1.0], "plant.stiffness": [100.0], "task.start": [0.0], "task.goal": [1.0],
    "task.max_velocity": 1.0, "task.max_acceleration": 2.0, "task.dwell": 3.0, "task.preroll": 0.5,
    "task.cycles": 100000}


def _node(model: str) -> tuple[Any, Any]:
    import rclpy
    from rclpy.parameter import Parameter

    from sim_plant_node.node.sim_plant import SimPlantNode

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    params = {**PARAMS, "plant.model": model}
    node = SimPlantNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    node.exchange.unmatched = lambda answers: ""  # type: ignore[method-assign]  # (no shaper: answers given here)
    ok, why = node._start_task()
    if not ok:
        raise RuntimeError(why)
    return ctx, node


def run_once(node: Any, steps: int, profile: cProfile.Profile | None = None) -> dict[str, float]:
    """``steps`` (rounded up to whole blocks) of ``node``'s lockstep path, each block answered (every row: its last raw
    setpoint, the node's ``_raw``)."""
    done = 0
    if profile is not None:
        profile.enable()
    c0 = time.thread_time()
    while done < steps:
        asked = len(node.exchange.asked)
        node._step_asked(np.zeros((asked, 1)) + node._raw)  # (the block's last raw setpoint: a step's input)
        done += asked
    cpu = time.thread_time() - c0
    if profile is not None:
        profile.disable()
    return {"steps": done, "cpu us per step": 1e6 * cpu / done, "cpu s per sim s": cpu / (done / RATE)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.plant_step", description=__doc__.splitlines()[0])
    p.add_argument("--model", default="list_time_varying", help="plant.model (default list_time_varying)")
    p.add_argument("--steps", type=int, default=5000, help="steps of each run (default 5000: 20 simulated s)")
    p.add_argument("--rounds", type=int, default=3, help="runs; the least CPU per step is reported (default 3)")
    p.add_argument("--profile", action="store_true", help="one more run under cProfile, its top functions printed")
    args = p.parse_args(argv)
    if args.steps < 1 or args.rounds < 1:
        p.error("--steps and --rounds must be >= 1")
    ctx, node = _node(args.model)
    try:
        run_once(node, 500)  # (warm-up)
        runs = [run_once(node, args.steps) for _ in range(args.rounds)]
        for r in runs:
            print(f"{args.model}: {r['steps']} steps, {r['cpu us per step']:.1f} us CPU per step,"
                  f" {r['cpu s per sim s']:.4f} CPU s per simulated s")
        best = min(runs, key=lambda r: r["cpu us per step"])
        print(f"best: {best['cpu us per step']:.1f} us CPU per step, {best['cpu s per sim s']:.4f} CPU s per sim s")
        if args.profile:
            prof = cProfile.Profile()
            run_once(node, args.steps, prof)
            text = io.StringIO()
            pstats.Stats(prof, stream=text).sort_stats("tottime").print_stats(25)
            print(text.getvalue())
    finally:
        node.destroy_node()
        ctx.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
