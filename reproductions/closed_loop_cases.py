"""Seeds 001 and 002 closed loops through the ROS graph: sim plant and shaper as processes, lockstep.

Seed 001: the time-delay feedback controller (``plant.model: delay_loop``, w_A = 3 rad/s,
T = pi / (3 w_A) rounded to the 1 kHz loop grid) around undamped plants w_R^2 / (s^2 + w_R^2), one
joint per w_R: the paper's 3, 4 and 2.9 rad/s and 3 % inside and outside both edges of the
stable interval that ``loop_design tdf-interval`` prints; unit step (``task.profile: step``),
shaper 'none' (the filter is inside the loop).

Seed 002: the eight corner plants as eight joints at 1 kHz (loop at 10 kHz), a unit step shaped by
the shaper node with ZV (or ZVD) designed on the nominal plant (w_n = 40 pi rad/s, zeta = 0.1);
``qft_ffb``, ``qft_fb`` and the open loop ``qft_open``; then a unit-step plant-output disturbance
and a unit-step measurement noise, 0.5 s after the step.

``python -m reproductions.closed_loop_cases`` regenerates docs/results/closed_loop_results.md and
docs/results/img/closed_loop_*.png; the integration tests call :func:`run_seed001` and :func:`run_seed002`.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import pathlib
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from reproductions.closed_loop_measures import (
    DWELL_002,
    EVENT_TIME,
    Traces,
    dominant_oscillation,
    event_effect,
    growth,
    noise_effect,
    residual,
    settle_time,
    settled_window,
    shaper_duration,
    shaper_floor,
    vibration,
)
from reproductions.common import docs_option, lockstep_block, logs_folder

if TYPE_CHECKING:
    from sim_plant_node.clients.conductor import StartNode

# ------------------------------------------------------------------ seed 001
OMEGA_A = 3.0
DELAY = math.pi / (3 * OMEGA_A)
RATE_001 = 100.0
SUBSTEPS_001 = 10  # loop at 1 kHz
DELAY_USED = round(DELAY * RATE_001 * SUBSTEPS_001) / (RATE_001 * SUBSTEPS_001)
EDGE = 0.03  # "just inside / outside": 3 % of the edge
DWELL_001 = 30.0
# ------------------------------------------------------------------ seed 002
RATE_002 = 1000.0
SUBSTEPS_002 = 10  # loop at 10 kHz (at 1 kHz the zero-order-hold controller's sample of delay destabilises it)
WHITE_NOISE = 1e-3  # white measurement noise, m (one sigma per loop sample)
# ------------------------------------------------------------------ the record
RECORD_DEPTH = 1000  # the recorder's ~/loop_state history (samples waiting for this process's executor)
ATTEMPTS = 3  # runs of a case whose record lost samples before the reproduction gives up


def tdf_interval_from_cli(omega_a: float = OMEGA_A, delay: float = DELAY_USED) -> tuple[float, float]:
    """The stable interval as the design CLI prints it (``loop_design tdf-interval --json``)."""
    out = subprocess.run([sys.executable, "-m", "shaper_nodes.cli.loop_design", "tdf-interval", "--omega-a",
                          repr(omega_a), "--delay", repr(delay), "--json"], check=True, capture_output=True, text=True)
    lo, hi = json.loads(out.stdout)["stable_interval"]
    return float(lo), float(hi)


def seed001_plants(interval: tuple[float, float]) -> dict[str, float]:
    lo, hi = interval
    return {"w_R = 3 (= w_A)": 3.0, "w_R = 4": 4.0, "w_R = 2.9": 2.9,
            f"lower edge +3 % ({lo * (1 + EDGE):.4g})": lo * (1 + EDGE),
            f"lower edge -3 % ({lo * (1 - EDGE):.4g})": lo * (1 - EDGE),
            f"upper edge -3 % ({hi * (1 - EDGE):.4g})": hi * (1 - EDGE),
            f"upper edge +3 % ({hi * (1 + EDGE):.4g})": hi * (1 + EDGE)}


class _Recorder:
    def __init__(self, joints: int) -> None:
        self.joints = joints
        self.rows: list[np.ndarray] = []
        self.times: list[float] = []
        self.ends = 0  # END events seen: the plant's task is over (it takes the next start)

    def __call__(self, msg) -> None:
        from shaper_nodes.ros.conversions import time_to_sec

        self.times.append(time_to_sec(msg.header.stamp))
        self.rows.append(np.asarray(msg.position, dtype=float))

    def on_event(self, msg) -> None:
        from shaper_msgs.msg import CycleEvent

        self.ends += msg.event == CycleEvent.END

    def traces(self, start: float) -> Traces:
        t = np.asarray(self.times) - start
        a = np.vstack(self.rows).reshape(len(self.rows), 4, self.joints)
        keep = t >= -1e-9
        return Traces(t[keep], *(a[keep, i, :] for i in range(4)))

    def lost(self, start: float, end: float, rate: float) -> int:
        """How many of the run's loop samples (one a step, ``start`` to ``end`` s of the plant's time) did not
        arrive: the plant's ~/loop_state writer keeps 10 samples (KEEP_LAST), so a sample lost in transport
        while this process was descheduled is gone once the lockstep plant has written 10 more."""
        k = np.rint((np.asarray(self.times) - start) * rate)
        want = np.arange(int(round((end - start) * rate)) + 1)
        return int(want.size - np.intersect1d(k, want).size)


def _session(start: StartNode, ctx, joints: list[str], rate: float, plant: dict):
    from sensor_msgs.msg import JointState

    from shaper_msgs.msg import CycleEvent
    from sim_plant_node.clients.conductor import Conductor

    # a generous lockstep timeout: on a loaded machine the plant waits for the shaper instead of holding
    start("sim_plant_node", "sim_plant", {"joint_names": joints, "rate": rate, "mode": "lockstep",
                                          "lockstep_timeout": 60.0, "lockstep.block": lockstep_block(rate),
                                          "imu.axes": [0, -1, -1], **plant})
    # 'exact': the shaper's impulses on the 1 ms grid meet the ZV / ZVD conditions at the nominal mode exactly,
    # as the paper's continuous shapers do (no discretisation floor on a plant equal to P0)
    start("shaper_nodes", "shaper_node", {"joint_names": joints, "command_rate": rate, "use_sim_time": True,
                                          "discretization": "exact"})
    conductor = Conductor(context=ctx)
    rec = _Recorder(len(joints))
    conductor.create_subscription(JointState, "/sim_plant/loop_state", rec, RECORD_DEPTH)
    conductor.create_subscription(CycleEvent, "/cycle_events", rec.on_event, 100)
    conductor.wait_ready(60.0, {"/shaper/commands": 1, "/forward_position_controller/commands": 1,
                                "/sim_plant/loop_state": 1})
    return conductor, rec


def _record(conductor, rec: _Recorder, rate: float, timeout: float) -> tuple[Traces | None, str]:
    """One run of the case as the plant was prepared: its traces, or None and what was lost."""
    rec.rows, rec.times = [], []
    ends = rec.ends
    result = conductor.run_cycles(1, timeout=timeout)[0]
    conductor.spin_until(lambda: rec.ends > ends, 60.0, "the run's END event")  # (the plant takes a next start)
    end = result.residual.window_end
    with contextlib.suppress(TimeoutError):  # the last loop_state samples may trail the END event
        conductor.spin_until(lambda: bool(rec.times) and rec.times[-1] >= end - 1e-6, 30.0, "the last loop samples")
    lost = rec.lost(result.start, end, rate)
    if lost:
        return None, f"{lost} loop samples of {round((end - result.start) * rate) + 1}"
    return rec.traces(result.start), ""


def _run(conductor, rec: _Recorder, rate: float, prepare: Callable[[], None], timeout: float = 600.0) -> Traces:
    """One run with every loop sample recorded: ``prepare`` (the run's parameters and shaper) then the run,
    again (up to :data:`ATTEMPTS` times) while samples were lost on the way to the recorder. The plant's
    run is the same each time (the model is rebuilt by ``prepare`` or rests exactly at the preroll's end),
    a record with a gap is not: the metrics of a trace that misses samples are not the run's."""
    for attempt in range(1, ATTEMPTS + 1):
        prepare()
        traces, lost = _record(conductor, rec, rate, timeout)
        if traces is not None:
            return traces
        print(f"closed_loop_cases: {lost} lost on the way to the recorder (attempt {attempt} of {ATTEMPTS});"
              " running the case again", file=sys.stderr, flush=True)
    raise RuntimeError(f"loop samples lost in each of {ATTEMPTS} runs of the case")


def run_seed001(start: StartNode, ctx, interval: tuple[float, float],
                dwell: float = DWELL_001) -> tuple[dict[str, float], Traces]:
    """One lockstep run of every seed 001 case (one joint each); returns the cases and traces."""
    cases = seed001_plants(interval)
    joints = [f"j{i}" for i in range(len(cases))]
    w = np.array(list(cases.values()))
    plant = {"plant.model": "delay_loop", "plant.mass": [1.0], "plant.damping": [0.0],
             "plant.stiffness": (w**2).tolist(), "loop.substeps": SUBSTEPS_001, "loop.assumed_frequency": OMEGA_A,
             "loop.delay": DELAY_USED, "task.start": [0.0], "task.goal": [1.0], "task.profile": "step",
             "task.dwell": dwell, "task.preroll": 0.1, "task.cycles": 1}
    conductor, rec = _session(start, ctx, joints, RATE_001, plant)
    try:
        return cases, _run(conductor, rec, RATE_001, lambda: conductor.set_shaper("none"))
    finally:
        conductor.close()


# ------------------------------------------------------------------ seed 002
@dataclass(frozen=True)
class Run002:
    name: str
    model: str
    shaper: str
    loop: dict


RUNS_002 = (
    Run002("ZV + feedforward-feedback", "qft_ffb", "zv", {}),
    Run002("ZV + feedback", "qft_fb", "zv", {}),
    Run002("open loop, ZV", "qft_open", "zv", {}),
    Run002("open loop, ZVD", "qft_open", "zvd", {}),
    Run002("disturbance, open loop ZV", "qft_open", "zv", {"loop.disturbance_step": 1.0}),
    Run002("disturbance, ZV + feedforward-feedback", "qft_ffb", "zv", {"loop.disturbance_step": 1.0}),
    Run002("noise, open loop ZV", "qft_open", "zv", {"loop.noise_step": 1.0}),
    Run002("noise, ZV + feedforward-feedback", "qft_ffb", "zv", {"loop.noise_step": 1.0}),
    Run002("white noise, open loop ZV", "qft_open", "zv", {"loop.noise_stddev": WHITE_NOISE}),
    Run002("white noise, ZV + feedforward-feedback", "qft_ffb", "zv", {"loop.noise_stddev": WHITE_NOISE}),
)


def run_seed002(start: StartNode, ctx, runs=RUNS_002,
                progress: Callable[[str], None] | None = None) -> dict[str, Traces]:
    """Every seed 002 run on the eight corner plants (one joint each), processes started once."""
    from shaper_nodes.core.closed_loop import corners, nominal

    cs = corners()
    joints = [f"corner{i}" for i in range(len(cs))]
    plant = {"plant.model": "qft_open", "plant.mass": [c.m for c in cs], "plant.damping": [c.c for c in cs],
             "plant.stiffness": [c.k for c in cs], "loop.substeps": SUBSTEPS_002, "task.start": [0.0],
             "task.goal": [1.0], "task.profile": "step", "task.dwell": DWELL_002, "task.preroll": 0.1,
             "task.cycles": 1, "loop.disturbance_time": EVENT_TIME, "loop.noise_time": EVENT_TIME}
    conductor, rec = _session(start, ctx, joints, RATE_002, plant)
    p0 = nominal()
    out: dict[str, Traces] = {}
    try:
        for run in runs:
            params = {"plant.model": run.model, "loop.disturbance_step": 0.0, "loop.noise_step": 0.0,
                      "loop.noise_stddev": 0.0, **run.loop}

            def prepare(params: dict = params, run: Run002 = run) -> None:  # (the model rebuilt: a fresh noise seed)
                conductor.set_plant(**{k.replace(".", "__"): v for k, v in params.items()})
                conductor.set_shaper(run.shaper, p0.omega_n, p0.zeta)

            out[run.name] = _run(conductor, rec, RATE_002, prepare)
            if progress:
                progress(run.name)
    finally:
        conductor.close()
    return out


# ------------------------------------------------------------------ report
def _plot001(path: pathlib.Path, cases: dict[str, float], tr: Traces) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    for j, name in enumerate(cases):
        if j < 3:
            axes[0].plot(tr.t, tr.output[:, j], label=name)
        axes[1].semilogy(tr.t, np.abs(tr.output[:, j] - 1.0) + 1e-16, lw=0.8, label=name)
    axes[0].set_xlim(0, 15)
    axes[0].set_ylim(-0.5, 2.5)
    axes[0].set_title(f"seed 001 Figs. 7-9: unit step, w_A = 3 rad/s, T = {DELAY_USED:g} s", fontsize=9)
    axes[1].set_title("|y - 1| (log): edges of the stable interval +-3 %", fontsize=9)
    axes[1].set_ylim(1e-8, 1e3)
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot002(path: pathlib.Path, traces: dict[str, Traces], names: list[str], title: str,
             signals: tuple[str, ...] = ("output",)) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(signals), len(names), figsize=(4 * len(names), 3.6 * len(signals)), sharey=True,
                             squeeze=False)
    for row, signal in zip(axes, signals, strict=True):
        for ax, name in zip(row, names, strict=True):
            tr = traces[name]
            ax.plot(tr.t, getattr(tr, signal), lw=0.8)
            ax.plot(tr.t, tr.reference[:, 0], "k--", lw=1, label="shaped reference")
            ax.set_title(f"{name}: {'true output y' if signal == 'output' else 'measured y + n'}", fontsize=8)
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
        row[0].set_ylabel("x2, m")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def report001(cases: dict[str, float], tr: Traces, interval: tuple[float, float]) -> str:
    from shaper_nodes.core.closed_loop import ppusmd_gains

    a0, a1, _ = ppusmd_gains(OMEGA_A, DELAY_USED)
    lines = [f"## Seed 001: time-delay feedback controller, w_A = {OMEGA_A:g} rad/s, T = pi/(3 w_A) ="
             f" {DELAY:.6f} s, on the 1 kHz loop grid {DELAY_USED:g} s (gains A0 = A2 = {a0:.6g}, A1 = {a1:.6g})", "",
             f"`loop_design tdf-interval --omega-a 3 --delay {DELAY_USED:g}` prints the stable interval"
             f" {interval[0]:.5g} <= w_R <= {interval[1]:.5g} rad/s.", "",
             "| plant | overshoot (%) | settled to 1e-6 at (s) | peak abs(y - 1) in 25-30 s over 5-10 s | verdict |",
             "|---|---|---|---|---|"]
    for j, name in enumerate(cases):
        g = growth(tr, j)
        st = settle_time(tr, j)
        at_rest = np.abs(tr.output[tr.t >= 5.0, j] - 1.0).max() < 1e-9
        verdict = "at rest" if at_rest else ("decays" if g < 1 else "grows")
        lines.append(f"| {name} | {100 * (tr.output[:, j].max() - 1):.2f} | "
                     f"{'never' if math.isinf(st) else f'{st:.3f}'} | {'-' if at_rest else f'{g:.3g}'} | {verdict} |")
    from shaper_nodes.core.closed_loop import exact_step_response

    ex_paper, ex_grid = (exact_step_response(OMEGA_A, d, 4.0) for d in (DELAY, DELAY_USED))
    lines += ["", f"2T = {2 * DELAY_USED:g} s. ![seed 001](img/closed_loop_001.png)", "",
              "Exact overshoot of the continuous loop at w_R = 4 (method of steps, `time_delay.exact_step_response`,"
              f" no discretisation): {100 * ex_paper.overshoot:.4f} % at t = {ex_paper.peak_time:.4f} s for"
              f" T = pi/9, {100 * ex_grid.overshoot:.4f} % for T = {DELAY_USED:g} s (the loop's grid);"
              " the sim plant's zero-order-hold loop converges to it at first order in the loop step.", ""]
    return "\n".join(lines)


def report002(traces: dict[str, Traces]) -> str:
    from shaper_nodes.core.closed_loop import corners

    cs = corners()
    runs = (("ZV + feedforward-feedback", "zv"), ("ZV + feedback", "zv"), ("open loop, ZV", "zv"),
            ("open loop, ZVD", "zvd"))
    rows = {n: residual(traces[n], f)[0] for n, f in runs}
    peaks = {n: residual(traces[n], f)[1] for n, f in runs}
    lines = ["## Seed 002: ZV + QFT loops against open-loop ZV and ZVD, eight corner plants", "",
             "Metric 1, RMS of x2 - 1: RMS (peak) of x2 - 1 from the end of the shaped step"
             f" (ZV {1e3 * shaper_duration('zv'):.1f} ms, ZVD {1e3 * shaper_duration('zvd'):.1f} ms) to"
             f" {DWELL_002:g} s, mm. It counts a loop's slow non-oscillatory settling as vibration.", "",
             "| plant (m, c, k) | " + " | ".join(rows) + " | FFB / open ZV | FFB / open ZVD |",
             "|---|" + "---|" * (len(rows) + 2)]
    ffb, ozv, ozvd = rows["ZV + feedforward-feedback"], rows["open loop, ZV"], rows["open loop, ZVD"]
    for i, c in enumerate(cs):
        lines.append(f"| {c.m:g}, {c.c:g}, {c.k:g} | " + " | ".join(
            f"{1e3 * rows[n][i]:.3g} ({1e3 * peaks[n][i]:.3g})" for n in rows)
            + f" | {ffb[i] / ozv[i]:.3g} | {ffb[i] / ozvd[i]:.3g} |")
    vib = {n: vibration(traces[n]) for n, _ in runs}
    ffb, ozv, ozvd = (vib[n][0] for n in ("ZV + feedforward-feedback", "open loop, ZV", "open loop, ZVD"))
    tr = traces["ZV + feedforward-feedback"]
    w = settled_window(tr)
    dom = [dominant_oscillation(tr.output[w, j] - 1.0, float(np.median(np.diff(tr.t)))) for j in range(len(cs))]
    lines += ["", "Metric 2, residual vibration = the oscillatory part of x2 - 1 (`vibration`: the free response"
              " after the shaped reference has reached 1 split by its poles with a matrix pencil; complex poles"
              " are vibration, real poles the loop's settling), RMS from the first sample with the final"
              f" reference to {DWELL_002:g} s, mm; in brackets the RMS of the non-oscillatory part. Last column:"
              " the feedforward-feedback loop's strongest oscillation (natural frequency rad/s, damping ratio).",
              "", "| plant (m, c, k) | " + " | ".join(rows) + " | FFB / open ZV | FFB / open ZVD | FFB oscillation |",
              "|---|" + "---|" * (len(rows) + 3)]
    for i, c in enumerate(cs):
        lines.append(f"| {c.m:g}, {c.c:g}, {c.k:g} | " + " | ".join(
            f"{1e3 * vib[n][0][i]:.3g} ({1e3 * vib[n][1][i]:.2g})" for n in rows)
            + f" | {ffb[i] / ozv[i]:.3g} | {ffb[i] / ozvd[i]:.3g} | {dom[i][0]:.1f}, {dom[i][1]:.3f} |")
    fzv, fzvd = shaper_floor(traces["open loop, ZV"]), shaper_floor(traces["open loop, ZVD"])
    lines += ["", "Floor on a plant equal to P0 (`shaper_floor`: P0's own residual after the reference the shaper"
              f" node sent, discretised `exact` onto the 1 ms command grid): ZV {1e3 * fzv:.2g} mm, ZVD"
              f" {1e3 * fzvd:.2g} mm RMS (`split` leaves 0.050 and 0.0063 mm). The corners whose parameters are all"
              " 0.65 or all 1.35 times nominal equal P0 to the issue's five digits: what every scheme leaves there"
              " comes from that rounding (about 1e-5 of the parameters) and is below 0.002 mm."]
    lines += ["", "![steps](img/closed_loop_002_step.png)", "",
              f"Unit-step plant-output disturbance and unit-step measurement noise at {EVENT_TIME:g} s: RMS of"
              f" the output minus 1 over the {0.5:g} s after the step (true output y = x2 + d_o; measured y + n), mm.",
              f" White measurement noise of {1e3 * WHITE_NOISE:g} mm per loop sample: RMS of the deviation of the true"
              " output from the same run without noise, over 0.5-1 s, mm.",
              "", "| plant (m, c, k) | disturbance, open | disturbance, FFB | noise step, open: true (measured) |"
              " noise step, FFB: true (measured) | white noise, open | white noise, FFB |",
              "|---|---|---|---|---|---|---|"]
    wo = noise_effect(traces["white noise, open loop ZV"], traces["open loop, ZV"])
    wf = noise_effect(traces["white noise, ZV + feedforward-feedback"], traces["ZV + feedforward-feedback"])
    do = event_effect(traces["disturbance, open loop ZV"])
    df = event_effect(traces["disturbance, ZV + feedforward-feedback"])
    no, nf = event_effect(traces["noise, open loop ZV"]), event_effect(traces["noise, ZV + feedforward-feedback"])
    nom = event_effect(traces["noise, open loop ZV"], "measured")
    nfm = event_effect(traces["noise, ZV + feedforward-feedback"], "measured")
    for i, c in enumerate(cs):
        lines.append(f"| {c.m:g}, {c.c:g}, {c.k:g} | {1e3 * do[i]:.4g} | {1e3 * df[i]:.4g} |"
                     f" {1e3 * no[i]:.4g} ({1e3 * nom[i]:.4g}) | {1e3 * nf[i]:.4g} ({1e3 * nfm[i]:.4g}) |"
                     f" {1e3 * wo[i]:.3g} | {1e3 * wf[i]:.3g} |")
    lines += ["", "![disturbance and noise](img/closed_loop_002_disturbance.png)", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="closed_loop_cases", description=__doc__.split("\n\n")[0])
    docs_option(p, "closed_loop_results.md and img/closed_loop_*.png")
    p.add_argument("--seeds", default="001,002", help="which seeds to run (default 001,002)")
    args = p.parse_args(argv)
    logs = logs_folder("closed_loop_cases")
    from sim_plant_node.clients.conductor import node_session

    (args.docs / "img").mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    text = ["# Closed-loop input shaping through the ROS graph (generated)", "",
            "Regenerate with `./run exec python -m reproductions.closed_loop_cases` (sim plant and shaper as"
            " separate processes, lockstep). See [closed_loop.md](../design/closed_loop.md) for the methods.", ""]
    for seed in args.seeds.split(","):
        with node_session(logs, seed) as (start, ctx):
            if seed == "001":
                interval = tdf_interval_from_cli()
                cases, tr = run_seed001(start, ctx, interval)
                text.append(report001(cases, tr, interval))
                _plot001(args.docs / "img" / "closed_loop_001.png", cases, tr)
            else:
                traces = run_seed002(start, ctx, progress=lambda n: print(f"  {n}", flush=True))
                text.append(report002(traces))
                _plot002(args.docs / "img" / "closed_loop_002_step.png", traces,
                         ["ZV + feedforward-feedback", "ZV + feedback", "open loop, ZV", "open loop, ZVD"],
                         "seed 002 Fig. 9: x2 of the eight corner plants after a unit step")
                _plot002(args.docs / "img" / "closed_loop_002_disturbance.png", traces,
                         ["disturbance, open loop ZV", "noise, open loop ZV", "disturbance, ZV + feedforward-feedback",
                          "noise, ZV + feedforward-feedback"],
                         f"seed 002 Fig. 10: unit-step output disturbance / measurement noise at {EVENT_TIME:g} s",
                         ("output", "measured"))
            print(f"seed {seed} done ({time.monotonic() - t0:.0f} s)", flush=True)
    (args.docs / "closed_loop_results.md").write_text("\n".join(text))
    print(f"wrote {args.docs / 'closed_loop_results.md'} ({time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
