"""Seed 004's three cases through the ROS graph: sim plant, shaper and scheduler as processes.

The sim plant runs the two-mass system (plant.model two_mass, lockstep) through five velocity
steps (two_mass.STEP_LEVELS, x0 at 0.02, 0.19, 0.36, 0.53, 0.70 m); every step is shaped by

(a) fixed   a ZV shaper designed on the first step's mode (m1 = 1.2 kg), set once on the shaper
(b) switch  the scheduler with the paper's two-set switch, eq. (9): crisp rules m1 = 1.2 kg for
            x0 <= 0.35 m, m1 = 8 kg above
(c) fuzzy   the scheduler with the TS rule base of config/scheduler.yaml (eight operating points
            x0 = 0, 0.1, ..., 0.7 m, triangular memberships, interpolated models)

and, with --extra, (c2) the paper's own two-rule base (operating points at the first and fifth
steps, triangular memberships) and (c-modes) case (c) interpolating the mode parameters.
The residual vibration of a step is the largest |x1 - x0| (m) from WINDOW s after the step to
the next step (the longest ZV here lasts 8.9 s).

``python -m reproductions.scheduler_cases`` regenerates docs/results/scheduler_results.md and
docs/results/img/scheduler_*.png (see --help); the integration test calls :func:`run_case`.
"""

from __future__ import annotations

import argparse
import functools
import math
import pathlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from reproductions.common import docs_option, logs_folder
from reproductions.scheduler_rules import (
    FUZZY_POINTS,
    JOINT,
    interpolation_table,
    mode_at,
    rule_base_spec,
    scheduler_parameters,
    switch_spec,
    true_mode_curve,
)
from shaper_nodes.core.cycles import END, START
from sim_plant_node.models.two_mass import STEP_LEVELS, STEP_POSES

if TYPE_CHECKING:
    from sim_plant_node.clients.conductor import StartNode

RATE = 25.0       # Hz, command and simulation rate (the modes are below 0.16 Hz)
DWELL = 30.0      # s per step
WINDOW = 10.0     # s after a step where its residual window starts
PREROLL = 4.0     # s at rest before the first step (the scheduler's first shaper is active before the task starts)
SCHEDULER = "/scheduler"  # the scheduler node, a lockstep reader of the plant
@dataclass(frozen=True)
class Case:
    name: str
    title: str
    scheduler: dict | None = None              # scheduler parameters; None: fixed shaper
    shaper: dict = field(default_factory=dict)  # shaper node parameters


def _cases() -> dict[str, Case]:
    first = mode_at(1.2)
    fuzzy = scheduler_parameters(rule_base_spec(FUZZY_POINTS, JOINT))
    return {
        "a": Case("a", "ZV on the first step's mode (m1 = 1.2 kg), fixed",
                  shaper={"shaper.family": "zv", "shaper.frequency_hz": first.hz, "shaper.damping_ratio": first.zeta}),
        "b": Case("b", "two-set switch of eq. (9): m1 = 8 kg if x0 > 0.35 m, else 1.2 kg",
                  scheduler=scheduler_parameters(switch_spec())),
        "c": Case("c", "TS fuzzy interpolation of the models at x0 = 0, 0.1, ..., 0.7 m (ZV on its mode)",
                  scheduler=fuzzy),
        "c2": Case("c2", "TS fuzzy interpolation, the paper's two rules (steps 1 and 5), triangular",
                   scheduler=scheduler_parameters(rule_base_spec((STEP_POSES[0], STEP_POSES[-1]), JOINT))),
        "c-modes": Case("c-modes", "as (c), interpolating the mode parameters instead of the models",
                        scheduler={**fuzzy, "interpolation": "modes"}),
    }


CASES = _cases()


@dataclass
class Run:
    """What one case recorded (times in s of simulated time)."""

    case: Case
    t: np.ndarray            # joint state times
    x0: np.ndarray           # m
    x1: np.ndarray           # m
    v_shaped: np.ndarray     # m/s, the shaped command applied over the step ending at t
    mode_t: np.ndarray       # scheduler's mode estimates: time, rad/s, -
    mode_omega: np.ndarray
    mode_zeta: np.ndarray
    step_times: np.ndarray   # START of each step
    residual: np.ndarray     # m, per step
    sources: list            # (time, source, family) of every active shaper


def residuals(t: np.ndarray, x0: np.ndarray, x1: np.ndarray, step_times: np.ndarray) -> np.ndarray:
    """Largest |x1 - x0| from WINDOW s after each step to the next step (or the end), m."""
    ends = [*step_times[1:], t[-1] + 1e-9]
    out = []
    for ts, te in zip(step_times, ends, strict=True):
        sel = (t >= ts + WINDOW) & (t < te)
        out.append(float(np.max(np.abs(x1[sel] - x0[sel]))) if np.any(sel) else float("nan"))
    return np.array(out)


class _Recorder:
    """What a case's run publishes, as it arrives (times in s of simulated time); the shaped commands only
    with ``commands`` (the plot of the docs shows them; without, ``Run.v_shaped`` is empty)."""

    def __init__(self, node: Any, commands: bool = True) -> None:
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from shaper_msgs.msg import CycleEvent, ModeEstimate
        from shaper_msgs.msg import Shaper as ShaperMsg
        from shaper_nodes.nodes.scheduler_lockstep import MODES_QOS
        from shaper_nodes.ros.conversions import time_to_sec
        from shaper_nodes.ros.qos import LATCHED

        self._sec = time_to_sec
        self.js: list[tuple[float, float]] = []       # time, x0
        self.tip: list[tuple[float, float]] = []      # time, x1
        self.cmd: list[float] = []                    # shaped commands v_s, in order
        self.modes: list[tuple[float, float, float]] = []  # time, rad/s, -
        self.events: list[tuple[int, int, float]] = []     # kind, cycle, time
        self.active: list[tuple[float, str, str]] = []     # time, source, family
        node.create_subscription(JointState, "/joint_states", self._on_js, 1000)
        node.create_subscription(JointState, "/sim_plant/tip_state", self._on_tip, 1000)
        if commands:
            node.create_subscription(Float64MultiArray, "/forward_position_controller/commands", self._on_cmd, 1000)
        node.create_subscription(ModeEstimate, "/scheduler/mode_estimate", self._on_mode, MODES_QOS)  # all of them
        node.create_subscription(CycleEvent, "/cycle_events", self._on_event, 100)
        node.create_subscription(ShaperMsg, "/shaper/active_shaper", self._on_shaper, LATCHED)

    def _on_js(self, m: Any) -> None:
        self.js.append((self._sec(m.header.stamp), m.position[0]))

    def _on_tip(self, m: Any) -> None:
        self.tip.append((self._sec(m.header.stamp), m.position[0]))

    def _on_cmd(self, m: Any) -> None:
        self.cmd.append(m.data[0])

    def _on_mode(self, m: Any) -> None:
        from shaper_nodes.ros.conversions import estimate_modes

        hz, zeta = estimate_modes(m)[0]
        self.modes.append((self._sec(m.header.stamp), 2 * math.pi * hz, zeta))  # rad/s, as the rules

    def _on_event(self, m: Any) -> None:
        self.events.append((int(m.event), int(m.cycle), self._sec(m.header.stamp)))

    def _on_shaper(self, m: Any) -> None:
        self.active.append((self._sec(m.header.stamp), m.source, m.family))

    def ends(self) -> list[float]:
        """Times of the END events so far."""
        return [t for k, _, t in self.events if k == END]

    def complete(self, steps: int) -> bool:
        """Whether ``steps`` steps have ended and the joint and tip states up to the last END are in."""
        ends = self.ends()
        last_end = max(ends, default=math.inf)
        return (len(ends) >= steps and bool(self.js) and self.js[-1][0] >= last_end and bool(self.tip)
                and self.tip[-1][0] >= last_end)

    def run(self, case: Case, steps: int = len(STEP_LEVELS)) -> Run:
        """The recording of the first ``steps`` steps as a :class:`Run`: joint and tip states paired by stamp,
        residuals per step."""
        # a loaded machine may starve this driver and let a few messages go (the plant keeps 10); what
        # arrived is paired by stamp, and a run that lost more than 10 % is an error
        t_js, x0_all = np.array(self.js).T
        t_tip, x1_all = np.array(self.tip).T
        t0, i0, i1 = np.intersect1d(t_js, t_tip, return_indices=True)
        x0, x1 = x0_all[i0], x1_all[i1]
        expected = int(round((PREROLL + steps * DWELL) * RATE))
        if t0.size < 0.9 * expected:
            raise RuntimeError(f"only {t0.size} of {expected} joint and tip states arrived")
        v = np.array(self.cmd)  # the k-th shaped command is integrated over the k-th step (if none was lost)
        step_times = np.array(sorted(t for k, _, t in self.events if k == START))
        m = np.array(self.modes).reshape(-1, 3).T if self.modes else np.zeros((3, 0))
        return Run(case, t0, x0, x1, v, m[0], m[1], m[2], step_times, residuals(t0, x0, x1, step_times),
                   self.active)


def _start_nodes(case: Case, start: StartNode, steps: int) -> None:
    # with a scheduler, the plant waits for it as a lockstep reader, one period ahead at most: its retune is
    # answered by the shaper before the plant asks for the next step, whatever the load (scheduler.md)
    readers = {"lockstep.readers": [SCHEDULER], "lockstep.lead": 1.0 / RATE} if case.scheduler is not None else {}
    start("sim_plant_node", "sim_plant", {
        "joint_names": [JOINT], "rate": RATE, "mode": "lockstep", "plant.model": "two_mass",
        "imu.axes": [0, -1, -1], "task.start": [0.0], "task.levels": [float(v) for v in STEP_LEVELS[:steps]],
        "task.dwell": DWELL, "task.preroll": PREROLL, "lockstep_timeout": 10.0, "joint_states.idle_period": 0.1,
        **readers})
    shaper = {"joint_names": [JOINT], "command_rate": RATE, "use_sim_time": True, **case.shaper}
    if case.scheduler is not None:
        shaper["retime_sources"] = ["scheduler"]
        start("shaper_nodes", "scheduler", {"use_sim_time": True, "lockstep": True, **case.scheduler})
    start("shaper_nodes", "shaper_node", shaper)


def _wait_for_nodes(case: Case, node: Any, until: Callable[[Callable[[], bool], float, str], None],
                    rec: _Recorder, start_cli: Any, commands: bool = True) -> None:
    """Wait for the services, the subscribers and the first active shaper, then let discovery settle."""
    from shaper_nodes.ros.lockstep_reader import ack_topic

    until(start_cli.service_is_ready, 60.0, "the sim plant")
    need = {"/shaper/commands": 1, "/forward_position_controller/commands": 2 if commands else 1,
            "/joint_states": 1, "/sim_plant/tip_state": 1}
    if case.scheduler is not None:
        need["/joint_states"] = 2
        from shaper_msgs.srv import GetShaper

        sched = node.create_client(GetShaper, "/scheduler/get_shaper")
        until(sched.service_is_ready, 60.0, "the scheduler")
    if case.scheduler is not None:  # the plant counts the scheduler from its announcement (latched) on
        need[ack_topic(SCHEDULER)] = 1
    for topic, n in need.items():
        until(functools.partial(_has_subscribers, node, topic, n), 60.0, f"{n} subscribers on {topic}")
    until(lambda: bool(rec.active), 60.0, "the shaper's active shaper")
    if case.scheduler is not None:
        # the plant at rest publishes its pose (joint_states.idle_period), so the scheduler sends the
        # shaper of the start pose before the first step, however long its discovery takes
        until(lambda: any(src == "scheduler" for _, src, _ in rec.active), 120.0, "the scheduler's first shaper")
    settle = time.monotonic() + 1.0
    until(lambda: time.monotonic() > settle, 5.0, "discovery to settle")


def _start_task(start_cli: Any, until: Callable[[Callable[[], bool], float, str], None], timeout: float = 60.0
                ) -> None:
    """Ask the plant to start its run; while it waits for its subscribers (its loop through the shaper not yet
    matched on DDS), ask again every 50 ms, up to ``timeout`` s."""
    from std_srvs.srv import Trigger

    from sim_plant_node.node.parameters import WAITING

    end = time.monotonic() + timeout
    while True:
        future = start_cli.call_async(Trigger.Request())
        until(future.done, 30.0, "the task to start")
        answer = future.result()
        if answer.success:
            return
        if not answer.message.startswith(WAITING) or time.monotonic() > end:
            raise RuntimeError(f"sim plant did not start: {answer.message}")
        until(functools.partial(_past, time.monotonic() + 0.05), 5.0, "the next start request")


def _past(t: float) -> bool:
    return time.monotonic() > t


def _has_subscribers(node: Any, topic: str, n: int) -> bool:
    return bool(node.count_subscribers(topic) >= n)


def run_case(case: Case, start: StartNode, ctx: Any, timeout: float = 900.0,
             progress: Callable[[str], None] | None = None, commands: bool = True, steps: int = len(STEP_LEVELS)
             ) -> Run:
    """Run the five steps of ``case`` (the first ``steps`` of them: the plant's task ends after them);
    ``start(package, executable, params)`` starts a node process. ``commands``: also record the shaped commands
    (``Run.v_shaped``, which only the docs' plot shows; a message fewer per step to take without)."""
    if not 1 <= steps <= len(STEP_LEVELS):
        raise ValueError(f"steps must be 1 to {len(STEP_LEVELS)}, got {steps}")
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM
    from std_srvs.srv import Trigger

    from shaper_nodes.ros.qos import NoDefaultQosEvents
    from sim_plant_node.clients.conductor import spin_until

    class Driver(NoDefaultQosEvents, Node):
        pass

    _start_nodes(case, start, steps)
    # no parameter or type description services, no QoS event handlers: rclpy's executor builds its wait set over
    # every entity of the node at each of the run's thousands of wake-ups (as the Conductor's)
    node = Driver("scheduler_cases", context=ctx, start_parameter_services=False,
                  parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    rec = _Recorder(node, commands)
    start_cli = node.create_client(Trigger, "/sim_plant/start_task")
    until = functools.partial(spin_until, ex)
    try:
        _wait_for_nodes(case, node, until, rec, start_cli, commands)
        _start_task(start_cli, until)
        n_steps = steps
        seen = 0

        def finished() -> bool:
            nonlocal seen
            ends = len(rec.ends())
            if progress and ends > seen:
                seen = ends
                progress(f"step {ends} of {n_steps} done")
            return rec.complete(n_steps)

        until(finished, timeout, f"the {n_steps} steps")
        settle = time.monotonic() + 0.5
        until(lambda: time.monotonic() > settle, 5.0, "the last messages")
    finally:
        ex.shutdown()
        node.destroy_node()
    return rec.run(case, steps)


# --------------------------------------------------------------------------------------------- docs
def markdown(runs: dict[str, Run]) -> str:
    names = list(runs)
    lines = ["| step | x0 (m) | " + " | ".join(f"({n}) residual (mm)" for n in names) + " |",
             "|---|---|" + "---|" * len(names)]
    for j, x in enumerate(STEP_POSES):
        lines.append(f"| {j + 1} | {x:.2f} | " + " | ".join(f"{1e3 * runs[n].residual[j]:.3f}" for n in names) + " |")
    lines.append("| sum | | " + " | ".join(f"**{1e3 * runs[n].residual.sum():.3f}**" for n in names) + " |")
    return "\n".join(lines) + "\n"


def plot(docs: pathlib.Path, runs: dict[str, Run]) -> list[pathlib.Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for name, run in runs.items():
        fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
        ax[0].plot(run.t, run.x1, lw=0.9, label="x1")
        ax[0].plot(run.t, run.x0, lw=0.7, ls="--", label="x0")
        ax[0].set_ylabel("position (m)")
        ax[0].legend(fontsize=8, loc="lower right")
        ax[0].set_title(f"({name}) {run.case.title}", fontsize=9)
        ax[1].plot(np.arange(1, run.v_shaped.size + 1) / RATE, run.v_shaped, lw=0.9)
        ax[1].set_ylabel("shaped command v_s (m/s)")
        ax[1].set_xlabel("time (s)")
        for a in ax:
            a.grid(alpha=0.3)
        fig.tight_layout()
        path = docs / "img" / f"scheduler_{name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    ref = next(iter(runs.values()))
    w, z = true_mode_curve(ref.t, ref.x0)
    ax[0].plot(ref.t, w, color="k", lw=1.5, alpha=0.4, label="plant (eq. (1) at the present m1)")
    ax[1].plot(ref.t, z, color="k", lw=1.5, alpha=0.4)
    for name, run in runs.items():
        if run.mode_t.size:
            ax[0].step(run.mode_t, run.mode_omega, where="post", lw=0.9, label=f"({name}) scheduled")
            ax[1].step(run.mode_t, run.mode_zeta, where="post", lw=0.9)
    ax[0].set_ylabel("natural frequency (rad/s)")
    ax[1].set_ylabel("damping ratio")
    ax[1].set_xlabel("time (s)")
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    path = docs / "img" / "scheduler_modes.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return [*paths, path]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="scheduler_cases", description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default="a,b,c", help="cases to run (default a,b,c; also c2, c-modes)")
    p.add_argument("--extra", action="store_true", help="also run c2 and c-modes")
    docs_option(p, "scheduler_results.md and img/scheduler_*.png")
    args = p.parse_args(argv)
    logs = logs_folder("scheduler_cases")
    from sim_plant_node.clients.conductor import node_session

    names = [n.strip() for n in args.cases.split(",")] + (["c2", "c-modes"] if args.extra else [])
    runs: dict[str, Run] = {}
    t_start = time.monotonic()
    for name in dict.fromkeys(names):
        case = CASES[name]
        with node_session(logs, case.name) as (start, ctx):
            print(f"({case.name}) {case.title}", flush=True)
            t_case = time.monotonic()
            runs[name] = run_case(case, start, ctx, progress=lambda s: print("  " + s, flush=True))
        print("  residual (mm): " + ", ".join(f"{1e3 * r:.3f}" for r in runs[name].residual)
              + f" ({time.monotonic() - t_case:.0f} s)", flush=True)
    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "img").mkdir(exist_ok=True)
    paths = plot(args.docs, runs)
    a = runs.get("a")
    ratio = "".join(f" sum(a) / sum({n}) = {a.residual.sum() / r.residual.sum():.1f}."
                    for n, r in runs.items() if a is not None and n != "a")
    text = ["# Seed 004 through the ROS graph: fixed, switched and fuzzy-scheduled ZV (generated)", "",
            "Regenerate with `./run exec python -m reproductions.scheduler_cases` (add `--extra` for the paper's"
            " two-rule base and for interpolating mode parameters). Sim plant (`plant.model: two_mass`, lockstep at"
            f" {RATE:g} Hz), shaper node and scheduler node run as separate processes; five velocity steps of"
            f" {DWELL:g} s each put x0 at {', '.join(f'{x:g}' for x in STEP_POSES)} m. Residual: the largest"
            f" |x1 - x0| from {WINDOW:g} s after a step to the next step."
            " See [scheduler.md](../design/scheduler.md).", "",
            *[f"- ({n}) {r.case.title}" for n, r in runs.items()], "",
            markdown(runs), ratio.strip(), "",
            "Natural frequency of the interpolated mode against the plant's (eq. (1) at m1 = 10 x0 + 1) over"
            " x0 in [0, 0.7] m, triangular memberships (the midpoints are where a step's second impulse is"
            " timed):", "", interpolation_table(),
            *[f"![{p.stem}](img/{p.name})" for p in paths], ""]
    (args.docs / "scheduler_results.md").write_text("\n".join(text))
    print(f"wrote {args.docs / 'scheduler_results.md'} and {len(paths)} plots ({time.monotonic() - t_start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
