"""Arm demo: input shaping on the six-axis arm behind joint_trajectory_controller, over DDS.

Starts the sim plant (``plant.model: arm``, lockstep, with its joint_trajectory_controller
emulation), the shaper node (its FollowJointTrajectory proxy in front of the controller), the
identifier and the recorder as separate processes. The cases that need it first calibrate the
workspace with the ``calibrate`` node (its config/calibrate.yaml: a grid over shoulder_lift and
elbow, three excitations per pose) or reuse a calibration (``--calibration``). A MoveIt-like
client sends the pick-and-place cycle of :mod:`sim_plant_node.arm.task` move by move to the
shaper's action and marks each cycle on ``/cycle_events``. Cases: unshaped; ZV and ZVD designed at
the home pose's lowest mode (modal analysis of the arm); the identifier's recommendation from the
unshaped cycles (applied through its ``~/identify``); LIST learning over the cycles (the learner
node); ``fixed``, the calibration's fallback (``shaper.yaml``: ZV on the home pose's modes);
``scheduled``, the calibrated scheduler (``scheduler.yaml``) with the shaper node's
``action.scheduler``, so each goal is shaped for the modes at its final pose; ``scheduled_list``,
LIST learning on top of the schedule (the learner sends to the scheduler); ``scheduled_list_moves``,
LIST per move on top of the schedule (the learner's ``list.per_move``: every move marked as its own
cycle, each learning its own factor, which the scheduler applies to that move's goals; opt-in, with a
per-move, per-cycle table of its own); ``scheduled_mrilc_moves``, MRILC per move on top of the schedule (the
learner's ``mode: mrilc_moves``: the shaper node's proxy sends each shaped goal to the learner's, which adds the
move's learned joint profile correction and sends it to the controller; opt-in, the same per-move table);
``scheduled_speedup``, the schedule with a time-scaling factor learned per move (the learner's ``mode: speed_moves``
in front of the shaper node's proxy: :mod:`.arm_speed`; opt-in, the same per-move table).
``list_moves``, LIST per move with no calibration (the learner's ``list.per_move`` with ``list.start: identified``,
each move from the mode identified in its unshaped first cycle; a scheduler of family ``none`` only carries the
factors to the shaper node's proxy; opt-in, the same per-move table).
For every move and case it measures (:mod:`sim_plant_node.arm.metrics`) the residual vibration
at the tool, the settling time, the move time plus settling time, the shaper's delay and the
tool-path deviation the shaping causes, and writes them as CSV, Markdown and a PNG plot.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import os
import pathlib
import sys
import time
from typing import Any

import numpy as np

from . import arm_payload
from .arm_cases import (
    CALIBRATED,
    CASES,
    DEFAULT_CASES,
    LEARNING,
    OWN_SCHEDULER,
    PER_MOVE,
    SCHEDULED,
    Session,
    apply_case,
    calibrate_step,
    fallback_request,
    identify,
)
from .arm_client import IMU, JOINTS, RATE, RECORDER, SUBSTEPS, ArmClient, MoveRun, learned_report
from .arm_report import case_rows, losses, per_move_table, plot, sums, table, write_report
from .arm_split import write_csv as write_splits

# the names the tests and scripts/arm_reference_bags.py import from here
__all__ = ["CASES", "DEFAULT_CASES", "ArmClient", "MoveRun", "_learned", "_losses", "_per_move_table", "_sums",
           "_table", "fallback_request", "main", "parse_args", "plot", "sim_plant_params"]
_learned, _losses, _per_move_table, _sums, _table = learned_report, losses, per_move_table, sums, table

RECORDED = ["/joint_states", "/tip_imu", "/cycle_events", "/shaper/active_shaper", "/diagnostics",
            "/learner/reports"]
#: the nodes the sim plant waits for in lockstep (lockstep.readers): calibrate, this demo's client, the
#: identifier and the recorder
READERS = ["/calibrate", "/conductor", "/identifier", RECORDER]
#: the sim plant's imu.seed by default (the default run's table, the README's, is of this noise draw)
IMU_SEED = 1


def sim_plant_params(args: argparse.Namespace) -> dict[str, Any]:
    """The sim plant's parameters for the demo's options ``args`` (the noise and its seed)."""
    from ..arm.task import HOME

    return {"plant.model": "arm", "mode": "lockstep", "rate": RATE, "task.start": HOME.tolist(),
            "imu.noise_stddev": args.noise, "imu.seed": args.seed, "lockstep_timeout": 60.0,
            "arm.substeps": SUBSTEPS, "lockstep.readers": READERS}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="demo [arm]", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=pathlib.Path, default=None,
                   help="output folder (default: out/demo-arm-<date-time> in the current folder)")
    p.add_argument("--cycles", type=int, default=1, help="pick-and-place cycles per fixed-shaper case (default 1;"
                   " the measures are the last cycle's)")
    p.add_argument("--list-cycles", type=int, default=8, help="cycles of LIST learning (default 8)")
    p.add_argument("--cases", default=",".join(DEFAULT_CASES),
                   help=f"cases to run, among {','.join(CASES)} (default {','.join(DEFAULT_CASES)}); those with a"
                   " schedule run last")
    p.add_argument("--calibration", type=pathlib.Path, default=None,
                   help="a calibration folder to use (scheduler.yaml, shaper.yaml) instead of calibrating first")
    p.add_argument("--noise", type=float, default=0.01, help="accelerometer noise, m/s^2 (default 0.01)")
    p.add_argument("--seed", type=int, default=IMU_SEED, help="seed of the accelerometer noise, the sim plant's"
                   f" imu.seed (default {IMU_SEED}): another noise draw of the same run (the calibration's too when"
                   " the demo calibrates first)")
    arm_payload.add_arguments(p)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    from .conductor import interrupted

    try:
        return _main(argv)
    except (TimeoutError, RuntimeError, KeyboardInterrupt) as err:
        if interrupted() or isinstance(err, KeyboardInterrupt):  # Ctrl-C or SIGTERM: the nodes were stopped
            print(f"\ndemo arm: interrupted ({interrupted() or 'SIGINT'}); the nodes were stopped", file=sys.stderr)
            return 130
        print(f"demo arm: {err}", file=sys.stderr)  # a wait that failed, a refused goal: one line, no traceback
        return 1


def _cases(args: argparse.Namespace) -> list[str] | None:
    """The cases to run, those with a schedule last (one shaper restart); None after a one-line error."""
    cases = [c.strip() for c in args.cases.split(",")]
    own = [c for c in cases if c in OWN_SCHEDULER]  # last: the shaper node follows their scheduler from then on
    cases = [c for c in cases if c not in SCHEDULED and c not in own] + [c for c in cases if c in SCHEDULED] + own
    unknown = sorted(set(cases) - set(CASES))
    if unknown or "none" not in cases:
        print(f"demo arm: --cases must include none and be among {', '.join(CASES)}; got {args.cases}", file=sys.stderr)
        return None
    if len(set(cases) & {"list", "scheduled_list", *PER_MOVE}) > 1:
        print(f"demo arm: --cases may name one learning case (list, scheduled_list, {', '.join(PER_MOVE)}: each"
              f" runs its own learner); got {args.cases}", file=sys.stderr)
        return None
    if bad := arm_payload.check_args(args, cases):
        print(f"demo arm: {bad}", file=sys.stderr)
        return None
    return cases


def _main(argv: list[str] | None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from shaper_msgs.srv import Identify

    from ..arm.description import JOINT_NAMES
    from ..arm.dynamics import ArmModel
    from ..arm.modal import lowest
    from ..arm.task import HOME, cycle_moves
    from .conductor import Conductor, node_session

    cases = _cases(args)
    if cases is None:
        return 2
    out = args.out or pathlib.Path("out") / datetime.datetime.now().strftime("demo-arm-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    moves = cycle_moves()
    home_mode = lowest(ArmModel(), HOME)
    print(f"demo arm: UR5e-based elastic arm, home lowest mode {home_mode.hz:.3f} Hz (zeta {home_mode.zeta:.3f});"
          f" {len(moves)} moves a cycle; cases {', '.join(cases)}; output in {out}", flush=True)
    t_wall = time.monotonic()
    rows: list[dict[str, Any]] = []
    traces: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    reference_paths: dict[int, np.ndarray] = {}
    per_move: list[list[tuple[MoveRun, Any, Any]]] = []  # per cycle of the per-move case: (run, measure, report)
    splits: list[tuple[str, int, int, str, Any]] = []  # per case, cycle and move: the sim plant's split (arm_split)
    with node_session(out, "arm") as (start, ctx):
        start("sim_plant_node", "sim_plant", sim_plant_params(args))
        shaper_params = {"joint_names": list(JOINT_NAMES), "command_rate": RATE, "use_sim_time": True,
                         "action.server_timeout": 30.0}
        session = Session(start, start("shaper_nodes", "shaper_node", shaper_params), shaper_params,
                          args.calibration, payload_learner=args.payload_learner)
        if session.calibration is None and any(c in CALIBRATED for c in cases):
            # first, alone with the sim (the other nodes' subscriptions would slow the lockstep down)
            session.calibration = calibrate_step(out, t_wall)
        start("shaper_nodes", "identifier", {"use_sim_time": True, "buffer_cycles": 20, "settle_tolerance": 1e-4,
                                             "max_modes": 3, "topics.imu_reliable": True,
                                             **arm_payload.identifier_params(cases, PER_MOVE)})
        start("shaper_nodes", "recorder", {"output": str(out / "recording"), "topics": RECORDED,
                                           "use_sim_time": True})
        conductor = Conductor(context=ctx)
        client = ArmClient(conductor)
        identifier_cli = conductor.create_client(Identify, "/identifier/identify")
        payload = arm_payload.PayloadWatch(conductor, args, cases)
        try:
            conductor.wait_ready(60.0, {"/cycle_events": 2})
            client.wait_ready(3)  # this node, the identifier and the recorder
            client.wait_recorder([IMU, JOINTS])  # the per-step streams, from the first step on
            cycle_index = 0
            recommended = None
            for case in cases:
                installed = apply_case(case, client, recommended, home_mode, session)
                learning = case in LEARNING
                n = args.list_cycles if learning else args.cycles
                print(f"{case:>10}: {installed}; {n} cycles ", end="", flush=True)
                for k in range(n):
                    payload.before_cycle(case, k, cycle_index)
                    if case in PER_MOVE:  # every move a cycle of the learner's: cycle_index up to its last move's
                        runs = client.run_cycle_per_move(cycle_index, moves, lambda: print(".", end="", flush=True),
                                                         functools.partial(learned_report, client))
                        per_move.append([(run, client.measure(run, reference_paths[run.index])[0],
                                          learned_report(client, cycle_index + run.index)) for run in runs])
                        cycle_index += len(moves) - 1
                    else:
                        runs = client.run_cycle(cycle_index, moves, lambda: print(".", end="", flush=True))
                    client.splits.wait(client.c.spin_until, runs)
                    splits += [(case, k + 1, r.index, r.name, client.splits.of(r.start, r.end)) for r in runs]
                    if learning and case not in PER_MOVE:
                        client.c.spin_until(lambda c=cycle_index: any(r.cycle == c for r in client.reports), 120.0,
                                            "the learner's report")
                    cycle_index += 1
                    last_end = runs[-1].end
                print(f" ({time.monotonic() - t_wall:.0f} s)", flush=True)
                if case == "none" and "identified" in cases:
                    recommended = identify(conductor, identifier_cli, n)
                case_rows(client, case, runs, installed, reference_paths, rows, traces)  # the case's last cycle
            client.wait_recorded(last_end)
        finally:
            arrays: dict[str, Any] = {k: np.asarray(v) for k, v in client.s.__dict__.items()}
            np.savez_compressed(out / "streams.npz", **arrays)
            write_splits(out / "splits.csv", splits)
            conductor.close()
    write_report(out, rows, cases, per_move, traces, [f"{i + 1}. {m.name}" for i, m in enumerate(moves)], args.noise,
                 payload.table(per_move, args.noise))
    print(losses(client))
    print()
    print(f"results:   {out / 'results.csv'}, {out / 'results.md'}")
    print(f"plot:      {out / 'tool_deviation.png'}")
    print(f"recording: {out / 'recording'}  (rosbag2, MCAP storage)")
    print(f"node logs: {out}/*.log   ({time.monotonic() - t_wall:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
