"""Seed 004's rule bases, free of ROS: the TS rule base of one rule per operating point (:func:`rule_base_spec`),
the paper's two-set switch (:func:`switch_spec`), the scheduler node's parameters for either
(:func:`scheduler_parameters`), and how well an interpolated mode follows the plant's (:func:`interpolation_table`,
:func:`true_mode_curve`). :mod:`reproductions.scheduler_cases` runs them through the ROS graph."""

from __future__ import annotations

import math

import numpy as np

from sim_plant_node.models.two_mass import STEP_POSES, m1_of, two_mass_matrices

JOINT = "joint_1"
FUZZY_POINTS = tuple(np.linspace(0.0, 0.7, 8))  # every 0.1 m


def mode_at(m1: float):
    """The two-mass system's mode with m1 kg (eq. (1) linearised there)."""
    from shaper_nodes.core.scheduling import modes_of

    return modes_of(two_mass_matrices(m1)[0])[0]


def rule_base_spec(points, premise: str = "joint_1", membership: str = "triangular",
                   with_models: bool = True, with_modes: bool = True) -> dict:
    """A rule base (the mapping core.scheduling.fuzzy.rule_base_from_dict takes) with one rule per pose x0
    in ``points`` (m): eq. (1) linearised at m1 = 10 x0 + 1 and/or its mode, and triangles
    peaking at each point (shoulders at the ends)."""
    from shaper_nodes.core.scheduling import modes_of, triangular_partition

    rules = {}
    for i, (x, mf) in enumerate(zip(points, triangular_partition(points), strict=True)):
        a, b = two_mass_matrices(float(m1_of(x)))
        rule: dict = {"membership": [membership], "membership_params": [mf.a, mf.b, mf.c]}
        if with_models:
            rule.update(a_matrix=a.ravel().tolist(), b_matrix=b.ravel().tolist())
        if with_modes:
            (mode,) = modes_of(a)
            rule.update(natural_frequency=[mode.omega], damping_ratio=[mode.zeta])
        rules[f"x{i}"] = rule
    return {"premises": [premise], "rules": rules}


def scheduler_parameters(spec: dict) -> dict:
    """The scheduler node's parameters (flat names) for a rule base mapping (see rule_base_spec)."""
    out: dict = {"premises": list(spec["premises"]), "rule_names": list(spec["rules"])}
    if spec.get("range"):
        out["range"] = [float(v) for v in spec["range"]]
    for name, rule in spec["rules"].items():
        for key, value in rule.items():
            if key == "natural_frequency":  # the core's rad/s; the node takes Hz
                key, value = "frequency_hz", [float(w) / (2 * math.pi) for w in value]
            out[f"rules.{name}.{key}"] = [v if isinstance(v, str) else float(v) for v in value]
    return out


def switch_spec() -> dict:
    """Seed 004 eq. (9) as a rule base: crisp sets x0 <= 0.35 (m1 = 1.2) and x0 > 0.35 (m1 = 8)."""
    rules = {}
    for name, (lo, hi), m1 in (("light", (-1e3, 0.35), 1.2), ("heavy", (0.35 + 1e-9, 1e3), 8.0)):
        a, b = two_mass_matrices(m1)
        rules[name] = {"membership": ["trapezoidal"], "membership_params": [lo, lo, hi, hi],
                       "a_matrix": a.ravel().tolist(), "b_matrix": b.ravel().tolist()}
    return {"premises": [JOINT], "rules": rules}


def interpolation_table() -> str:
    """Frequency error of the interpolated mode against the plant's over x0 in [0, 0.7] m, for
    rule bases of several sizes, interpolating the models or the mode parameters (ROS-free)."""
    from shaper_nodes.core.scheduling import rule_base_from_dict

    xs = np.linspace(0.0, 0.7, 281)
    true = np.array([mode_at(float(m1)).omega for m1 in m1_of(xs)])
    mids = [0.5 * (a + b) for a, b in zip((0.0, *STEP_POSES[:-1]), STEP_POSES, strict=True)]
    lines = ["| operating points x0 (m) | interpolating | largest error | error at the steps' midpoints"
             f" x0 = {', '.join(f'{m:.3g}' for m in mids)} m |", "|---|---|---|---|"]
    for label, pts in (("0.02, 0.7 (the paper's two)", STEP_POSES[::4]),
                       ("0, 0.175, ..., 0.7 (5)", np.linspace(0, 0.7, 5)),
                       ("0, 0.1, ..., 0.7 (8, case c)", FUZZY_POINTS)):
        base = rule_base_from_dict(rule_base_spec(pts, JOINT))
        for method in ("model", "modes"):
            err = np.array([base.evaluate([x], method).modes[0].omega for x in xs]) / true - 1
            at = np.interp(mids, xs, err)
            lines.append(f"| {label} | {method} | {100 * np.max(np.abs(err)):.1f} % |"
                         f" {', '.join(f'{100 * e:+.1f}' for e in at)} % |")
    return "\n".join(lines) + "\n"


def true_mode_curve(t: np.ndarray, x0: np.ndarray):
    """The plant's mode (eq. (1) linearised at the present m1) along a run: rad/s and -."""
    out = np.array([[m.omega, m.zeta] for m in (mode_at(float(m1)) for m1 in m1_of(x0))])
    return out[:, 0], out[:, 1]
