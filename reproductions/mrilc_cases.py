"""Seed 000 (MRILC) through the ROS graph: sim plant, shaper and learner as separate processes.

The sim plant runs the paper's loop (``plant.model`` mck_pid: the m-c-k plant of eq. 12 in the
loop of the PID of eq. 13) in lockstep; the learner (``mode`` mrilc) designs the ZVD shaper on
the reference model's mode, sends it to the shaper node, and after every cycle installs the
new feedforward profile u2 at the plant. Every cycle is one iteration: a unit step of the
reference and back (``task.round_trip``), each followed by a dwell, from rest (the plant is
put at rest at the start pose before every cycle, the paper's repeated initial condition).
The driver runs one cycle at a time and waits for the learner's report before the next.

``python -m reproductions.mrilc_cases`` regenerates docs/results/mrilc_results.md and
docs/results/img/mrilc_learning.png (see --help); the integration test calls :func:`run_learning`
and :func:`run_shaper_only`.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from reproductions.common import (
    LOCKSTEP_LEARNER,
    LOCKSTEP_TIMEOUT,
    LearnerDriver,
    action,
    docs_option,
    lockstep_block,
    logs_folder,
    metric,
)
from sim_plant_node.models.plants import mck_from_mode

if TYPE_CHECKING:
    from sim_plant_node.clients.conductor import StartNode

#: sample rate of the graph runs, Hz (see docs/design/mrilc.md: why not 1 kHz)
RATE = 200.0
JOINT = ["joint_1"]
NOMINAL = (10.0, 0.3)
PERTURBED = (5.0, 0.15)
DWELL = 0.4  # s after the step and after the step back
TASK = {"task.start": [0.0], "task.goal": [1.0], "task.profile": "step", "task.round_trip": True,
        "task.dwell": DWELL, "task.preroll": 1.0 / RATE}
#: the sim plant's ``lockstep.block`` in a run without lockstep readers: a whole cycle's setpoints (the preroll
#: sample, the step and back with their dwells) in one exchange with the shaper instead of eight of 0.1 s. The
#: command path is feedforward (the shaper is set once, before the first cycle; u2 is installed at the plant
#: between cycles, at rest), so a run in blocks is the run one setpoint at a time (tests/test_lockstep_blocks.py);
#: checked: 100 iterations in blocks of 20, 80 and 161 end at the same iteration 100 to the last digit. A run with
#: readers (a recorder) keeps lockstep_block's 0.1 s, inside the plant's ``lockstep.lead``.
CYCLE_BLOCK = int(round(2 * DWELL * RATE)) + 1


@dataclass(frozen=True)
class Iteration:
    iteration: int
    rms_e: float
    rms_u1: float
    rms_u2: float
    action: str
    residual: float          # RMS of y - r after the shaped return step has come to rest (learner's)


def plant_params(mode: tuple[float, float]) -> dict:
    """Sim plant parameters of the paper's loop around the plant (omega, zeta)."""
    m, c, k = mck_from_mode(*mode)
    return {"plant.model": "mck_pid", "plant.mass": [m], "plant.damping": [c], "plant.stiffness": [k]}


def _nodes(start: StartNode, plant_mode: tuple[float, float], plant: dict | None = None) -> None:
    block = lockstep_block(RATE) if (plant or {}).get("lockstep.readers") else CYCLE_BLOCK
    start("sim_plant_node", "sim_plant", {"joint_names": JOINT, "rate": RATE, "mode": "lockstep",
                                          "lockstep.block": block,
                                          "lockstep_timeout": LOCKSTEP_TIMEOUT, "imu.axes": [0, -1, -1],
                                          **plant_params(plant_mode), **TASK, **(plant or {})})
    start("shaper_nodes", "shaper_node", {"joint_names": JOINT, "command_rate": RATE, "use_sim_time": True})


def run_learning(plant_mode: tuple[float, float], iterations: int, start: StartNode, ctx, learner: dict | None = None,
                 progress: Callable[[Iteration], None] | None = None, measure: bool = False,
                 plant: dict | None = None, before: Callable[[Any], None] | None = None,
                 after: Callable[[Any, list[Any]], None] | None = None) -> list[Iteration]:
    """``iterations`` cycles with the MRILC learner on the plant (omega, zeta); one Iteration each.

    The driver reads only the learner's reports: with ``measure`` False (the default) it takes no accelerometer
    or joint state samples (:class:`~reproductions.common.LearnerDriver`) and starts the next cycle as soon as
    the report is in; ``measure`` True paces the cycles as before, each also measured by the driver (a
    recorder that is no lockstep reader then has the time it had). ``plant`` adds sim plant parameters (e.g.
    ``lockstep.readers``); ``before(conductor)`` runs once the nodes are ready, before the first cycle, and
    ``after(conductor, reports)`` after the last report (e.g. to wait for a recorder)."""
    _nodes(start, plant_mode, plant)
    start("shaper_nodes", "learner", {"mode": "mrilc", "mrilc.rate": RATE, "use_sim_time": True,
                                      "joint_names": JOINT, **LOCKSTEP_LEARNER, **(learner or {})})
    driver = LearnerDriver(ctx, measure=measure)
    out: list[Iteration] = []
    try:
        driver.wait_ready({"/shaper/commands": 1, "/forward_position_controller/commands": 1,
                           "/joint_states": 2 if measure else 1, "/sim_plant/reference": 1, "/cycle_events": 2},
                          "the learner's shaper")
        if before is not None:
            before(driver.conductor)
        for k in range(iterations):
            r = driver.report_of_cycle(k)
            done = action(r)
            it = Iteration(int(metric(r, "iteration")) if done != "skipped" else -1, metric(r, "rms_e"),
                           metric(r, "rms_u1"), metric(r, "rms_u2"), done, metric(r, "residual"))
            out.append(it)
            if progress:
                progress(it)
        if after is not None:
            after(driver.conductor, driver.reports)
    finally:
        driver.close()
    return out


def run_shaper_only(plant_mode: tuple[float, float], cycles: int, start: StartNode, ctx) -> list[Iteration]:
    """``cycles`` cycles with the ZVD shaper on the reference model alone: the learner only
    measures (``mrilc.learn`` false, u2 = 0)."""
    return run_learning(plant_mode, cycles, start, ctx, {"mrilc.learn": False})


def iterations_to(rows: list[Iteration], fraction: float) -> int | None:
    """First iteration whose RMS(e) is at most ``fraction`` of iteration 1's."""
    first = rows[0].rms_e
    return next((r.iteration for r in rows if r.rms_e <= fraction * first), None)


def plot(path: pathlib.Path, runs: dict[str, list[Iteration]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7, 7.5), sharex=True)
    for name, rows in runs.items():
        it = [r.iteration for r in rows]
        axes[0].semilogy(it, [r.rms_e for r in rows], label=name)
        axes[1].plot(it, [r.rms_u1 for r in rows], label=name)
        axes[2].plot(it, [r.rms_u2 for r in rows], label=name)
    for ax, title in zip(axes, ("RMS of e = y_m - y", "RMS of u1 (feedback effort)", "RMS of u2 (ILC effort)"),
                         strict=True):
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[2].set_xlabel("iteration")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="mrilc_cases", description=__doc__.split("\n\n")[0])
    p.add_argument("--iterations", type=int, default=400, help="iterations of the P-type run (default 400)")
    p.add_argument("--robust-iterations", type=int, default=60, help="iterations of the robust-law run (default 60)")
    docs_option(p, "mrilc_results.md and img/mrilc_learning.png")
    args = p.parse_args(argv)
    logs = logs_folder("mrilc_cases")
    from sim_plant_node.clients.conductor import node_session

    t0 = time.monotonic()

    def session(name: str, fn):
        with node_session(logs, name) as (start, ctx):
            return fn(start, ctx)

    def show(r: Iteration) -> None:
        if r.iteration in (1, 2, 5, 10, 25, 50, 100, 200, 300, 400) or r.action != "learn":
            print(f"  iteration {r.iteration:3d}: RMS e {r.rms_e:.4g}  u1 {r.rms_u1:.4g}  u2 {r.rms_u2:.4g}"
                  f"  residual {r.residual:.4g}  {r.action}", flush=True)

    print("nominal plant, ZVD alone", flush=True)
    nominal = session("nominal", lambda s, c: run_shaper_only(NOMINAL, 2, s, c))
    print("perturbed plant, ZVD alone", flush=True)
    perturbed = session("perturbed", lambda s, c: run_shaper_only(PERTURBED, 2, s, c))
    runs = {}
    print("perturbed plant, ZVD + MRILC, P-type gamma 10", flush=True)
    runs["P-type, gamma 10 (paper)"] = session("p", lambda s, c: run_learning(PERTURBED, args.iterations, s, c,
                                                                              progress=show))
    print("perturbed plant, ZVD + MRILC, robust law", flush=True)
    runs["robust (minimax over the nine plants)"] = session(
        "robust", lambda s, c: run_learning(PERTURBED, args.robust_iterations, s, c,
                                            {"mrilc.law": "robust"}, progress=show))
    text = ["# MRILC on seed 000's example (generated)", "",
            f"Regenerate with `./run exec python -m reproductions.mrilc_cases` (sim plant, shaper and learner as"
            f" separate processes in lockstep at {RATE:g} Hz; every cycle a unit step and back, {TASK['task.dwell']} s"
            " each; the perturbed plant w = 5 rad/s, zeta = 0.15; the ZVD shaper designed on the reference model's"
            " mode). See [mrilc.md](../design/mrilc.md) for the method.", "",
            "Residual vibration (RMS of y - r from when the shaped return step has come to rest to the cycle's end;"
            " r, y in units of the unit step):", "",
            "| case | residual |", "|---|---|",
            f"| nominal plant, ZVD alone | {nominal[-1].residual:.4g} |",
            f"| perturbed plant, ZVD alone | {perturbed[-1].residual:.4g} |"]
    for name, rows in runs.items():
        text.append(f"| perturbed plant, ZVD + MRILC {name}, iteration {rows[-1].iteration} |"
                    f" {rows[-1].residual:.4g} |")
    text += ["", "Learning curves:", "", "| law | RMS e it. 1 | iterations to 2 % | RMS e last | ratio last |"
             " RMS u1 first -> last | RMS u2 last |", "|---|---|---|---|---|---|---|"]
    for name, rows in runs.items():
        text.append(f"| {name} | {rows[0].rms_e:.4g} | {iterations_to(rows, 0.02)} | {rows[-1].rms_e:.3g}"
                    f" (it. {rows[-1].iteration}) | {rows[-1].rms_e / rows[0].rms_e:.2e} | {rows[0].rms_u1:.4g} ->"
                    f" {rows[-1].rms_u1:.4g} | {rows[-1].rms_u2:.4g} |")
    text += ["", "![learning curves](img/mrilc_learning.png)", ""]
    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "img").mkdir(exist_ok=True)
    (args.docs / "mrilc_results.md").write_text("\n".join(text))
    plot(args.docs / "img" / "mrilc_learning.png", runs)
    print(f"wrote {args.docs / 'mrilc_results.md'} and {args.docs / 'img' / 'mrilc_learning.png'}"
          f" ({time.monotonic() - t0:.0f} s)")
    return 0 if all(not math.isnan(r[-1].rms_e) for r in runs.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
