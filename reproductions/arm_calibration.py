"""Calibration of the arm, checked against modal analysis, and the schedule it gives against fixed shapers.

``python -m reproductions.arm_calibration [--calibration DIR]`` (``./run exec python -m
reproductions.arm_calibration``) takes a calibration (``DIR``, the ``calibrate`` node's output, e.g.
the demo's ``out/demo-arm-*/calibration``; without it the plan of config/calibrate.yaml is run
here on the same arm without ROS, :mod:`sim_plant_node.arm.offline`, accelerometer noise 0.01
m/s^2, through the same analysis) and

1. compares every identified mode with the modal analysis of the linearised arm
   (:func:`sim_plant_node.arm.modal.modes`) and with the modes of the arm as simulated
   (:func:`sim_plant_node.arm.modal.simulated_modes`, the true values of what is identified):
   frequency and damping errors, and whether the truth lies within the reported two sigma;
2. runs the demo's pick-and-place cycle (noise-free, without ROS: the shaper node's core
   shaping of each whole goal, the controller emulation, the arm) unshaped, with every fixed
   ZV the calibration offers (the ZV on each calibrated pose's modes; the home pose's is the
   fallback) and with the calibrated schedule (each goal shaped for the modes at its final pose,
   as the shaper node's ``action.scheduler`` does), and compares the residual vibration summed
   over the cycle's moves with the best fixed ZV's, move by move.

Writes docs/results/calibration_results.md.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import time
from typing import Any

import numpy as np

from reproductions.common import docs_option

RATE = 500.0
DWELL = 1.5  # s at rest after each move, as in the demo
NOISE = 0.01  # m/s^2, the accelerometer noise of the offline calibration (the demo's)


def _config() -> pathlib.Path:
    return pathlib.Path(__file__).resolve().parents[1] / "shaper_nodes" / "config" / "calibrate.yaml"


def offline_calibration(config: pathlib.Path) -> Any:
    """Run the plan of ``config`` on the offline arm and analyse it as the node does (a Calibration)."""
    import yaml

    from shaper_nodes.analysis.calibration import PoseData, compute, setup_dict
    from shaper_nodes.core.calibration.plan import approach, make_plan, quintic_time
    from shaper_nodes.nodes.calibrate import config_from_values, settings_from_values
    from sim_plant_node.arm.offline import OfflineArm

    v = dict(_flatten(yaml.safe_load(config.read_text())["/**"]["ros__parameters"]))
    for key, default in (("poses", None), ("timeouts.data", 30.0)):
        v.setdefault(key, default)
    cfg = config_from_values(v, None)
    plan = make_plan(cfg)
    setup = setup_dict(plan, settings_from_values(v), str(v["scheduler.family"]),
                       float(v["scheduler.premise_threshold"]))
    arm = OfflineArm(cfg.home_pose, RATE, noise=NOISE)
    poses = []
    here = cfg.home_pose
    for step in plan.steps:
        t_app = quintic_time(step.pose - here, cfg.approach_velocity, cfg.approach_acceleration)
        _run(arm, approach(step.pose, t_app, cfg.settle))
        data = PoseData(step.index)
        for rep in range(step.repeats):
            start = _run(arm, step.excitations[rep])
            end = start + step.excitation_time
            data.events += [(0, rep, start), (1, rep, end), (2, rep, end + step.decay)]
        t = np.asarray(arm.record.imu_t)
        y = np.asarray(arm.record.imu)
        data.imu_t, data.imu = t.tolist(), [tuple(r) for r in y]
        arm.record.imu_t, arm.record.imu = [], []
        poses.append(data)
        here = step.pose
    return compute(setup, poses, workers=2)


def _flatten(tree: dict, prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, val in tree.items():
        out += _flatten(val, f"{prefix}{k}.") if isinstance(val, dict) else [(f"{prefix}{k}", val)]
    return out


def _run(arm: Any, waypoints: Any) -> float:
    pos = np.array([w.positions for w in waypoints])
    return float(arm.run([w.time for w in waypoints], pos, np.zeros_like(pos), np.zeros_like(pos)))


def accuracy(cal: Any) -> list[dict[str, Any]]:
    """Per pose and identified mode: the errors against modal analysis and the simulated arm's modes."""
    from sim_plant_node.arm.dynamics import ArmModel
    from sim_plant_node.arm.modal import modes, simulated_modes

    model = ArmModel()
    rows = []
    for r in cal.results:
        modal = [(m.omega, m.zeta) for m in modes(model, r.positions)]
        sim = simulated_modes(model, r.positions, 1.0 / (RATE * 2), 0.5)
        for m in r.modes:
            wm, zm = min(modal, key=lambda x: abs(x[0] - m.omega))
            ws, zs = min(sim, key=lambda x: abs(x[0] - m.omega))
            rows.append({"pose": r.name, "hz": m.hz, "hz_std": m.omega_std / (2 * math.pi), "zeta": m.zeta,
                         "zeta_std": m.zeta_std, "modal_hz": wm / (2 * math.pi), "modal_zeta": zm,
                         "df_modal": (m.omega - wm) / wm, "dz_modal": (m.zeta - zm) / zm,
                         "in_2sigma_f": abs(m.omega - ws) <= 2 * m.omega_std,
                         "in_2sigma_z": abs(m.zeta - zs) <= 2 * m.zeta_std,
                         "sim_hz": ws / (2 * math.pi), "sim_zeta": zs})
    return rows


def goal_waypoints(move: Any, shaper: Any, rate: float = RATE, dwell: float = DWELL
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The goal the demo sends for ``move`` (:func:`sim_plant_node.arm.task.goal_points`: its start at time 0, its
    waypoints, then ``dwell`` s holding the goal), shaped by ``shaper`` as the shaper node shapes a whole goal (None:
    unshaped), as the controller runs it: without the point at time 0 (the controller starts from the measured
    state). Times (s from the start), positions, velocities, accelerations ((N, 6) each)."""
    from shaper_nodes.core.shaping.fir import discretize
    from shaper_nodes.core.shaping.trajectory import shape_trajectory
    from sim_plant_node.arm.task import goal_points

    times, pos, vel, acc = goal_points(move, dwell)
    if shaper is None:
        return times[1:], pos[1:], vel[1:], acc[1:]
    shaped = shape_trajectory(times, pos, discretize(shaper, rate), rate, vel)
    return shaped.times[1:], shaped.positions[1:], shaped.velocities[1:], shaped.accelerations[1:]


def cycle(shaper_for: Any, from_rest: bool = False) -> list[Any]:
    """The demo's cycle with ``shaper_for(goal_pose)`` (None: unshaped) on the offline arm: per move its measures.
    ``from_rest``: every move starts with the arm at rest (no leftover of the move before)."""
    from sim_plant_node.arm.metrics import measure_move, motion_end
    from sim_plant_node.arm.offline import OfflineArm
    from sim_plant_node.arm.task import HOME, cycle_moves

    arm = OfflineArm(HOME, RATE)
    out = []
    for move in cycle_moves():
        if from_rest:
            arm = OfflineArm(move.positions[0], RATE)
        times, pos, vel, acc = goal_waypoints(move, shaper_for(move.positions[-1]))
        start = arm.run(times, pos, vel, acc)
        end = start + float(times[-1])
        ct, cq = arm.record.window("cmd", start, end)
        it, imu = arm.record.window("imu", start, end)
        lt, link = arm.record.window("link", start, end)
        tool = arm.plant.model.tool_positions(link)
        out.append(measure_move(move.name, start, move.duration, motion_end(ct, cq), end, it, imu, lt, tool))
    return out


def evaluate(cal: Any) -> dict[str, Any]:
    from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict
    from shaper_nodes.core.shaping import design

    sched = Scheduler(rule_base_from_dict(cal.rule_base), "modes", cal.family)
    premises = [list(cal.plan.config.joint_names).index(p) for p in sched.rule_base.premises]
    runs = {"unshaped": cycle(lambda pose: None)}
    fixed = {}
    for r in cal.results:
        if r.modes:
            shaper = design(cal.family, [m.mode for m in r.modes])
            fixed[r.name] = shaper
            runs[f"fixed ZV at {r.name}"] = cycle(lambda pose, s=shaper: s)

    def scheduled(pose: np.ndarray) -> Any:
        return sched.shaper(sched.evaluate(pose[premises].tolist()))

    runs["scheduled"] = cycle(scheduled)
    total = {k: sum(m.residual_rms for m in v) for k, v in runs.items()}
    best = min((k for k in runs if k.startswith("fixed")), key=lambda k: total[k])
    best_shaper = fixed[best.removeprefix("fixed ZV at ")]
    rest = {"best fixed": cycle(lambda pose: best_shaper, True), "scheduled": cycle(scheduled, True)}
    from sim_plant_node.arm.task import cycle_moves

    same = [np.array_equal(scheduled(m.positions[-1]).times, best_shaper.times)
            and np.array_equal(scheduled(m.positions[-1]).amplitudes, best_shaper.amplitudes) for m in cycle_moves()]
    return {"runs": runs, "total": total, "best": best, "fixed": fixed, "rest": rest, "same": same}


def markdown(cal: Any, acc: list[dict[str, Any]], ev: dict[str, Any], source: str, seconds: float) -> str:
    n_f = sum(r["in_2sigma_f"] for r in acc)
    poses_f = {r["pose"] for r in acc}
    cover_f = sum(all(x["in_2sigma_f"] for x in acc if x["pose"] == p) for p in poses_f)
    cover_z = sum(all(x["in_2sigma_z"] for x in acc if x["pose"] == p) for p in poses_f)
    worst_f = max(abs(r["df_modal"]) for r in acc)
    worst_z = max(abs(r["dz_modal"]) for r in acc)
    lines = ["# Calibration of the arm (generated by `python -m reproductions.arm_calibration`)", "",
             f"Calibration: {source}. {len(cal.results)} poses, {sum(len(r.modes) for r in cal.results)} modes"
             " identified.", "",
             "## Accuracy against modal analysis", "",
             f"- largest frequency error against modal analysis: **{100 * worst_f:.2f} %** (bound 2 %); largest"
             f" damping error: **{100 * worst_z:.1f} %** (bound 20 %).",
             f"- the simulated arm's true frequency inside the reported two sigma: {n_f} of {len(acc)} modes, all"
             f" modes of a pose at **{cover_f} of {len(poses_f)} poses**; damping: all modes of a pose at"
             f" {cover_z} of {len(poses_f)} poses.", "",
             "| pose | identified Hz (1 sigma) | modal Hz | sim Hz | df modal | zeta (1 sigma) | modal zeta |"
             " sim zeta | dzeta modal | f in 2 sigma | zeta in 2 sigma |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in acc:
        lines.append(f"| {r['pose']} | {r['hz']:.4f} ({r['hz_std']:.4f}) | {r['modal_hz']:.4f} | {r['sim_hz']:.4f} |"
                     f" {100 * r['df_modal']:+.2f} % | {r['zeta']:.5f} ({r['zeta_std']:.5f}) | {r['modal_zeta']:.5f} |"
                     f" {r['sim_zeta']:.5f} | {100 * r['dz_modal']:+.1f} % | {'yes' if r['in_2sigma_f'] else 'no'} |"
                     f" {'yes' if r['in_2sigma_z'] else 'no'} |")
    runs, total, best = ev["runs"], ev["total"], ev["best"]
    moves = [m.move for m in runs["unshaped"]]
    lines += ["", "## The schedule against fixed shapers on the demo's cycle", "",
              "Residual vibration: RMS of the flange accelerometer's deviation from its mean over 1 s after the"
              " commanded motion ends (noise-free), m/s^2, per move; summed over the cycle's six moves.", "",
              "| shaper | " + " | ".join(moves) + " | sum | % of best fixed |", "|---|" + "---|" * (len(moves) + 2)]
    for k, v in runs.items():
        lines.append(f"| {k}{' (best fixed)' if k == best else ''} | " + " | ".join(f"{m.residual_rms:.4f}" for m in v)
                     + f" | {total[k]:.4f} | {100 * total[k] / total[best]:.1f} |")
    worse = [a.move for a, b in zip(runs["scheduled"], runs[best], strict=True) if a.residual_rms > b.residual_rms]
    same = ev["same"]
    differ = [i for i, s in enumerate(same) if not s]
    s_d = sum(runs["scheduled"][i].residual_rms for i in differ)
    f_d = sum(runs[best][i].residual_rms for i in differ)
    lines += ["", f"Scheduled against the best fixed ZV ({best}): **{100 * total['scheduled'] / total[best]:.1f} %**"
              f" of its summed residual; moves where the schedule leaves more: {', '.join(worse) or 'none'}.", "",
              f"The schedule applies the very same shaper as the best fixed one on {sum(same)} of the {len(same)}"
              f" moves ({', '.join(m for m, s in zip(moves, same, strict=True) if s)}): they end at the home"
              " pose's reach, where that shaper was measured (the base rotation does not move the modes). On the"
              f" moves where the two differ ({', '.join(moves[i] for i in differ)}) the schedule leaves"
              f" **{100 * s_d / f_d:.1f} %** of the fixed shaper's residual.", "",
              "Each move started from rest (no leftover vibration of the move before), to separate what the"
              " shaper does from what the previous move leaves:", "",
              "| shaper | " + " | ".join(moves) + " | sum |", "|---|" + "---|" * (len(moves) + 1)]
    for k, v in ev["rest"].items():
        lines.append(f"| {k} | " + " | ".join(f"{m.residual_rms:.4f}" for m in v)
                     + f" | {sum(m.residual_rms for m in v):.4f} |")
    lines += ["", f"({seconds:.0f} s)"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_calibration", description=__doc__.split("\n\n")[0])
    p.add_argument("--calibration", type=pathlib.Path, default=None,
                   help="a calibrate output folder (its recording is analysed again); default: run the plan offline")
    docs_option(p, "calibration_results.md")
    args = p.parse_args(argv)
    t0 = time.monotonic()
    if args.calibration is not None:
        from shaper_nodes.analysis.calibration import compute, read_recording

        setup, poses = read_recording(args.calibration / "recording")
        cal = compute(setup, poses, workers=2)
        source = f"the recording in {args.calibration} (calibrate node over DDS), analysed again"
    else:
        cal = offline_calibration(_config())
        source = "config/calibrate.yaml's plan run offline (no ROS), accelerometer noise 0.01 m/s^2"
    acc = accuracy(cal)
    ev = evaluate(cal)
    text = markdown(cal, acc, ev, source, time.monotonic() - t0)
    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "calibration_results.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
