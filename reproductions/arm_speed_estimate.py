"""How well the speed learner's accelerometer test stands for 0.05 mm at the flange (issue 31, item 4).

``python -m reproductions.arm_speed_estimate [--factors 1.0,1.2,1.4,1.6,1.8] [--noise S]``
(``./run exec python -m reproductions.arm_speed_estimate``) runs the pick-and-place cycle's six moves on the
ROS-free arm (:class:`reproductions.arm_learning.Cell`, deterministic), shaped by the modal schedule
(:func:`reproductions.arm_learning.modal_calibration`, the integration tests' schedule), time-scaled by each factor,
and prints per move and factor what the learner node's ``speed_moves`` mode measures (the peak of the flange IMU's
deviation from its mean, from the commanded end plus 0.1 s to 1 s after it, converted at the schedule's lowest
mode at the goal: x = a / (2 pi f)^2) against the flange's true largest distance from where it comes to rest (from
the link angles, which a robot does not measure), their ratio, the move + settle time (0.05 mm) and the largest
joint speed and torque against their limits. Prints a Markdown table; writes nothing.
"""

from __future__ import annotations

import argparse
import math


def rows(factors: list[float], noise: float = 0.0) -> list[dict[str, float | str]]:
    """One row per factor and move (module docstring)."""
    from reproductions.arm_learning import Cell, Context, modal_calibration
    from sim_plant_node.arm.metrics import window_residual
    from sim_plant_node.arm.task import cycle_moves

    ctx = Context(modal_calibration(), noise=noise)
    sched, cell, out = ctx.schedule(), Cell(ctx), []
    for factor in factors:
        for mv in cycle_moves():
            shaper = sched(mv.positions[-1])
            run = cell.run(mv, shaper, factor)
            f = min(m.omega for m in shaper.modes) / (2 * math.pi)
            end = mv.duration / factor + float(shaper.times[-1])  # the commanded motion's end, s from the start
            peak = window_residual(run.times, run.imu, end + 0.1, end + 1.0).peak
            estimate = 1e3 * peak / (2 * math.pi * f) ** 2
            out.append({"factor": factor, "move": mv.name, "f_hz": f, "peak": peak, "estimate_mm": estimate,
                        "flange_mm": run.measures.peak_mm, "ratio": estimate / run.measures.peak_mm,
                        "move_settle_s": run.measures.move_and_settle_s, "velocity": run.velocity_ratio,
                        "torque": run.torque_ratio})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_speed_estimate", description=__doc__.split("\n\n")[0])
    p.add_argument("--factors", default="1.0,1.2,1.4,1.6,1.8", help="time-scaling factors, comma-separated")
    p.add_argument("--noise", type=float, default=0.0, help="accelerometer noise, m/s^2 (default 0)")
    args = p.parse_args(argv)
    got = rows([float(x) for x in args.factors.split(",")], args.noise)
    print("| factor | move | lowest mode Hz | IMU peak m/s^2 | estimate mm | flange mm | estimate / flange |"
          " move + settle s | speed / 180 deg/s | torque / limit |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in got:
        print(f"| {r['factor']:.1f} | {r['move']} | {r['f_hz']:.2f} | {r['peak']:.4f} | {r['estimate_mm']:.4f} |"
              f" {r['flange_mm']:.4f} | {r['ratio']:.2f} | {r['move_settle_s']:.3f} | {r['velocity']:.2f} |"
              f" {r['torque']:.2f} |")
    ratios = [float(r["ratio"]) for r in got]
    print(f"\nestimate / flange: {min(ratios):.2f} to {max(ratios):.2f} over {len(got)} moves")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
