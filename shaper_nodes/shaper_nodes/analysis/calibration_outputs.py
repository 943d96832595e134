"""What a calibration writes besides its report.md (:mod:`.calibration_report`): report.json
(:func:`report_dict`, numbers to :data:`DIGITS` significant digits, the poses whose accelerometer failed in
:func:`sensor_faults`), the scheduler node's parameters (:func:`scheduler_yaml`) and the shaper node's fallback
(:func:`shaper_yaml`), from a :class:`~.calibration.Calibration`."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

from shaper_nodes.core.calibration import PoseResult
from shaper_nodes.core.calibration.plan import plan_to_dict

from .calibration import SENSOR_FAULT, Calibration

REPORT_FORMAT = "shaper_nodes calibration report 1"
#: significant digits of the numbers in report.json (what "the same report" is compared to)
DIGITS = 6


def _r(x: float, digits: int = DIGITS) -> float:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else x


def _mode_dict(m: Any) -> dict[str, float]:
    return {"frequency_hz": _r(m.hz), "frequency_hz_std": _r(m.omega_std / (2 * math.pi), 3),
            "damping_ratio": _r(m.zeta), "damping_ratio_std": _r(m.zeta_std, 3), "amplitude": _r(m.amplitude, 4)}


def _sensor_fault(r: PoseResult) -> str | None:
    return next((f[len(SENSOR_FAULT) + 2:] for f in r.flags if f.startswith(SENSOR_FAULT + ": ")), None)


def sensor_faults(cal: Calibration | Sequence[PoseResult]) -> list[tuple[int, str, str]]:
    """The poses whose accelerometer failed: (index, name, why) each, in pose order (of a calibration or of
    its poses' results)."""
    results = cal.results if isinstance(cal, Calibration) else cal
    return [(r.index, r.name, why) for r in results if (why := _sensor_fault(r)) is not None]


def report_dict(cal: Calibration) -> dict[str, Any]:
    """report.json: plan, settings, per pose its positions, modes (one-sigma) and flags, the choices."""
    names = list(cal.plan.config.joint_names)
    poses = []
    for r, res in zip(cal.results, cal.residuals, strict=True):
        poses.append({"index": r.index, "name": r.name,
                      "grid_index": None if r.grid_index is None else list(r.grid_index),
                      "positions": {j: _r(float(v)) for j, v in zip(names, r.positions, strict=True)},
                      "modes": [_mode_dict(m) for m in r.modes],
                      "repeats": [[{"frequency_hz": _r(m.hz), "damping_ratio": _r(m.zeta)} for m in rep]
                                  for rep in r.repeats],
                      "flags": list(r.flags), "ok": r.ok and not _sensor_fault(r),
                      "sensor_fault": _sensor_fault(r),
                      "predicted_residual": {k: _r(v, 4) for k, v in res.items()}})
    s = cal.settings
    out: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "complete": len(cal.results) == len(cal.plan.steps),
        "plan": plan_to_dict(cal.plan),
        "identification": {"method": s.method, "max_modes": s.max_modes, "band_hz": s.band_hz,
                           "max_damping": s.max_damping, "agreement": s.agreement,
                           "uncertainty": "one sigma: the Jacobian covariance of each decay's fit with the spread"
                                          " over analysis variants added, and the spread between repeats"},
        "poses": poses,
        "flagged_poses": [r.name for r in cal.results if not r.ok or r.flags],
        "notes": list(cal.notes),
    }
    if cal.rule_base is not None:
        out["scheduler"] = {"premises": cal.rule_base["premises"], "rules": len(cal.rule_base["rules"]),
                            "family": cal.family, "interpolation": "modes"}
    if cal.fallback is not None:
        out["fallback"] = {"family": cal.fallback.family, "pose": "home",
                           "frequencies_hz": [_r(m.omega / (2 * math.pi)) for m in cal.fallback.modes],
                           "damping_ratios": [_r(m.zeta) for m in cal.fallback.modes],
                           "duration_s": _r(cal.fallback.duration)}
    return out


def _floats(values: Sequence[float]) -> str:
    """A YAML flow list of floats that every YAML reader takes as floats (1e-05 alone reads as a string)."""
    def one(x: float) -> str:
        text = repr(_r(float(x)))
        mantissa, _, exponent = text.partition("e")
        return f"{mantissa}.0e{exponent}" if exponent and "." not in mantissa else text
    return "[" + ", ".join(one(x) for x in values) + "]"


def _controller_ns(action: str) -> str | None:
    """The controller's namespace of a FollowJointTrajectory action named ``<ns>/follow_joint_trajectory``
    (``/joint_trajectory_controller``), else None."""
    head, _, tail = action.rpartition("/")
    return head if tail == "follow_joint_trajectory" and head.startswith("/") else None


def scheduler_yaml(cal: Calibration, node: str = "/**") -> str:
    """The scheduler node's parameter file for the calibrated rule base (keyed ``/**`` by default: it
    applies whatever the scheduler node is named): the rule base, the joint states topic the calibration
    read and the shaper node the shapers go to."""
    assert cal.rule_base is not None
    spec = cal.rule_base
    w = cal.wiring
    lines = [f"# Scheduler rule base from a calibration ({len(cal.results)} poses): ros2 run shaper_nodes scheduler",
             "# --ros-args --params-file scheduler.yaml. Premises: joint positions, rad; frequency_hz in Hz,",
             "# one per mode (sorted by frequency); damping_ratio dimensionless.",
             f"{node}:", "  ros__parameters:",
             f"    joint_states: {json.dumps(w['joint_states'])}   # the topic the calibration read the pose from",
             f"    shaper: {json.dumps(w['shaper_node'])}   # the shaper node (its set_shaper)",
             f"    premises: {json.dumps(spec['premises'])}",
             f"    range: {_floats(spec['range'])}",
             "    interpolation: modes",
             f"    family: {cal.family}",
             f"    rule_names: {json.dumps(list(spec['rules']))}",
             "    rules:"]
    for name, rule in spec["rules"].items():
        lines += [f"      {name}:",
                  f"        membership: {json.dumps(rule['membership'])}",
                  f"        membership_params: {_floats(rule['membership_params'])}",
                  f"        frequency_hz: {_floats([w / (2 * math.pi) for w in rule['natural_frequency']])}",
                  f"        damping_ratio: {_floats(rule['damping_ratio'])}"]
    return "\n".join(lines) + "\n"


def shaper_yaml(cal: Calibration, node: str = "/**") -> str:
    """The shaper node's parameters (keyed ``/**`` by default: they apply whatever the shaper node is
    named): the calibrated joints; the controller the calibration moved the arm with (its
    FollowJointTrajectory action and, in its namespace, its trajectory topic); with a rule base,
    ``action.scheduler`` (each goal shaped for the modes at its final pose); and the fixed fallback,
    the family's shaper on the home pose's modes, active for streamed commands and for goals when the
    scheduler does not answer."""
    assert cal.fallback is not None
    modes = cal.fallback.modes
    w = cal.wiring
    ns = _controller_ns(w["action"])
    how = (["# shaper.yaml. Each goal to <node>/follow_joint_trajectory is shaped for the modes at its final pose",
            "# (the scheduler's, started with scheduler.yaml; when it does not answer, with the fixed shaper below:",
            "# the home pose's modes) and forwarded to the controller."] if cal.rule_base is not None
           else ["# shaper.yaml. Each goal to <node>/follow_joint_trajectory is shaped with the fixed shaper below",
                 "# (the home pose's modes) and forwarded to the controller."])
    lines = ["# The shaper node from a calibration: ros2 run shaper_nodes shaper_node --ros-args --params-file",
             *how, "# Frequencies Hz, damping ratios dimensionless.",
             f"{node}:", "  ros__parameters:",
             f"    joint_names: {json.dumps(list(cal.plan.config.joint_names))}",
             "    action:",
             f"      controller: {json.dumps(w['action'])}   # the action the calibration moved the arm with"]
    if cal.rule_base is not None:
        lines.append(f"      scheduler: {json.dumps(w['scheduler_node'])}")
    if ns is not None:
        lines += ["    topics:   # the controller's trajectory topic, for trajectories and streams sent to the shaper",
                  f"      trajectory_out: {json.dumps(ns + '/joint_trajectory')}",
                  f"      stream_out: {json.dumps(ns + '/joint_trajectory')}"]
    lines += ["    shaper:",
              f"      family: {cal.fallback.family}",
              f"      frequencies_hz: {_floats([m.omega / (2 * math.pi) for m in modes])}",
              f"      damping_ratios: {_floats([m.zeta for m in modes])}"]
    return "\n".join(lines) + "\n"
