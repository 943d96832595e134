# Copyright 2026 The shaper_nodes authors
# SPDX-License-Identifier: Apache-2.0
"""MRILC per move (core/learning/mrilc/moves.py): the basis, the lifted learner on a small linear MIMO plant,
the joint limits, the divergence guard and the saved state."""

from __future__ import annotations

import json

import numpy as np
import pytest

from shaper_nodes.core.learning.mrilc.model import MrilcError
from shaper_nodes.core.learning.mrilc.moves import STATE_VERSION, MoveLearner, moves_from_dict, moves_to_dict
from shaper_nodes.core.learning.mrilc.profile import (
    JointLimits,
    Profile,
    clip_into,
    excess,
    profile_excess,
    project,
    spline_basis,
)

PERIOD = 0.01   # s
SPACING = 0.05  # s
COUNT = 16      # B-splines per joint: (16 + 3) x 0.05 = 0.95 s of motion
SAMPLES = 150   # 1.5 s: the motion and half a second after it


def mimo_plant() -> tuple[np.ndarray, np.ndarray]:
    """Two joints, two outputs: each output the acceleration of a damped 3 Hz mode driven by both joints'
    setpoints, the setpoints coupled (a lifted plant G: outputs x (basis x joints)), and the joint profiles'
    basis at the samples."""
    t = PERIOD * np.arange(SAMPLES)
    b0, _, _ = spline_basis(t, SPACING, COUNT)
    w, z = 2 * np.pi * 3.0, 0.05
    tau = t[:, None] - t[None, :]
    h = np.where(tau >= 0, w * np.exp(-z * w * tau) * np.sin(w * np.sqrt(1 - z * z) * tau), 0.0) * PERIOD
    mix = np.array([[1.0, 0.4], [-0.3, 0.8]])
    blocks = [[mix[o, j] * (h @ b0) for j in range(2)] for o in range(2)]
    g = np.zeros((SAMPLES * 2, COUNT * 2))
    for o in range(2):
        for j in range(2):
            g[o::2, j * COUNT:(j + 1) * COUNT] = blocks[o][j]
    return g, t


def profile(t: np.ndarray, peak_velocity: float = 0.5) -> Profile:
    """A smooth move of both joints (sin^2 velocity) over 0.95 s and its basis."""
    end = (COUNT + 3) * SPACING
    s = np.clip(t / end, 0, 1)
    v = peak_velocity * np.sin(np.pi * s) ** 2
    a = np.where(s < 1, peak_velocity * np.pi / end * np.sin(2 * np.pi * s), 0.0)
    q = np.cumsum(v) * PERIOD
    return Profile(np.column_stack([q, -q]), np.column_stack([v, -v]), np.column_stack([a, -a]),
                   spline_basis(t, SPACING, COUNT))


def wide() -> JointLimits:
    return JointLimits(np.full(2, -6.0), np.full(2, 6.0), np.full(2, 10.0), np.full(2, 100.0))


def run(learner: MoveLearner, true_g: np.ndarray, target: np.ndarray, cycles: int) -> list[float]:
    costs = []
    for _ in range(cycles):
        y = true_g @ learner.coefficients.T.ravel()
        costs.append(learner.update(target - y).cost)
    return costs


def test_basis_vanishes_at_the_ends_and_its_derivatives_match():
    t = np.linspace(0, 1.2, 1201)
    b0, b1, b2 = spline_basis(t, 0.1, 5)
    assert np.all(b0[t >= 0.8 - 1e-12] == 0) and np.all(b0[0] == 0)
    assert np.allclose(b0.sum(axis=1)[(t >= 0.3) & (t < 0.5)], 1.0)  # partition of unity where 4 overlap
    assert np.allclose(np.gradient(b0, t, axis=0)[5:-5], b1[5:-5], atol=2e-3)
    assert np.allclose(np.gradient(b1, t, axis=0)[5:-5], b2[5:-5], atol=2.0)  # |b2| up to 100 1/s^2
    with pytest.raises(MrilcError, match="knot spacing"):
        spline_basis(t, 0.0, 3)


def test_converges_on_a_linear_mimo_plant_with_a_wrong_model():
    g, t = mimo_plant()
    rng = np.random.default_rng(1)
    wanted = rng.normal(0, 1e-3, (COUNT, 2))
    target = g @ wanted.T.ravel()  # reachable: the reference is what some correction gives
    true_g = g * 1.3 + 0.05 * g[:, ::-1]  # the model off by 30 % in gain and coupled otherwise
    learner = MoveLearner(g, profile(t), wide(), gain=0.7, regularisation=1e-6)
    costs = run(learner, true_g, target, 20)
    assert costs[-1] < 1e-3 * costs[0]
    assert all(u.action == "learn" for u in [learner.update(target - true_g @ learner.coefficients.T.ravel())])


def test_limits_hold_and_a_profile_past_a_limit_is_not_taken_further():
    g, t = mimo_plant()
    prof = profile(t)
    limits = JointLimits(np.full(2, -6.0), np.full(2, 6.0), np.full(2, 0.5005), np.full(2, 100.0))
    target = g @ np.full(2 * COUNT, 0.05)  # wants large positive corrections on both joints
    learner = MoveLearner(g, prof, limits, gain=1.0, regularisation=1e-6)
    run(learner, g, target, 5)
    _q, v, _a = prof.corrected(learner.coefficients)
    assert excess(learner.coefficients, prof, limits) <= 1e-12
    assert np.all(np.abs(v) <= 0.5005 + 1e-12)
    assert np.max(np.abs(learner.correction()[0])) > 1e-3  # it still corrects, where the limits leave room
    # a limit the uncorrected profile already breaks (0.49 < its 0.5 rad/s peak): not made worse there
    tight = JointLimits(np.full(2, -6.0), np.full(2, 6.0), np.full(2, 0.49), np.full(2, 100.0))
    c = project(np.full((COUNT, 2), 0.05), prof, tight)
    _, v2, _ = prof.corrected(c)
    assert np.all(np.abs(v2) <= np.maximum(0.49, np.abs(prof.velocities)) + 1e-12)
    assert excess(c, prof, tight) <= 1e-12


def test_the_points_sent_hold_the_limits_exactly_where_the_correction_meets_them():
    g, t = mimo_plant()
    prof = profile(t)
    limits = JointLimits(np.full(2, -6.0), np.full(2, 6.0), np.full(2, 0.5005), np.full(2, 100.0))
    learner = MoveLearner(g, prof, limits, gain=1.0, regularisation=1e-6)
    run(learner, g, g @ np.full(2 * COUNT, 0.05), 5)
    raw = prof.corrected(learner.coefficients)
    sent = learner.corrected()
    base = (prof.positions, prof.velocities, prof.accelerations)
    # the correction meets the velocity limit (within the projection's margin: its sweeps work on the limits
    # tightened by `margin`, 1e-5 relative, and end on the tightened bound or, where rows stay violated, on the limit,
    # by the machine's rounding) and the points sent hold every limit exactly
    assert 0.5005 * (1 - 1e-5) - 1e-12 <= np.max(np.abs(raw[1])) <= 0.5005 + 1e-12
    assert profile_excess(*sent, limits, base) == 0.0
    assert np.max(np.abs(sent[1])) <= 0.5005
    for r, c in zip(raw, sent, strict=True):  # clipping moves the points by rounding only
        assert np.max(np.abs(r - c)) <= 1e-12
    # a point past a limit is clipped onto it; where the uncorrected profile is past it, onto the profile's value
    v = prof.velocities.copy()
    v[5, 0] = 0.6
    q2, v2, a2 = clip_into(prof.positions, v, prof.accelerations, limits)
    assert v2[5, 0] == 0.5005 and profile_excess(q2, v2, a2, limits) == 0.0
    assert profile_excess(prof.positions, v, prof.accelerations, limits) == pytest.approx(0.0995)
    past = (prof.positions, v, prof.accelerations)
    v3 = v.copy()
    v3[5, 0] = 0.7
    _, v4, _ = clip_into(prof.positions, v3, prof.accelerations, limits, past)
    assert v4[5, 0] == 0.6 and profile_excess(prof.positions, v4, prof.accelerations, limits, past) == 0.0


def test_divergence_falls_back_to_the_best_profile_and_holds():
    g, t = mimo_plant()
    target = g @ np.full(2 * COUNT, 1e-3)
    learner = MoveLearner(g, profile(t), wide(), gain=1.0, regularisation=1e-6, patience=2, max_fallbacks=2)
    true_g = -2.0 * g  # the model has the wrong sign: every step makes it worse
    actions, costs = [], []
    for _ in range(12):
        u = learner.update(target - true_g @ learner.coefficients.T.ravel())
        actions.append(u.action)
        costs.append(u.cost)
    assert "fallback" in actions and actions[-1] == "hold"
    assert learner.holding and learner.gain == pytest.approx(0.25)
    assert np.array_equal(learner.coefficients, np.zeros((COUNT, 2)))  # the best: no correction
    assert costs[-1] == pytest.approx(costs[0])


def test_state_round_trips_and_is_checked_entry_by_entry(tmp_path):
    g, t = mimo_plant()
    prof = profile(t)
    learner = MoveLearner(g, prof, wide(), regularisation=1e-6)
    target = g @ np.full(2 * COUNT, 1e-3)
    run(learner, g, target, 3)
    doc = json.loads(json.dumps(learner.to_dict()))
    again = MoveLearner.from_dict(doc, g, prof, wide(), regularisation=1e-6)
    assert again.to_dict() == learner.to_dict() and doc["version"] == STATE_VERSION
    np.testing.assert_allclose(again.correction()[0], learner.correction()[0], rtol=1e-12, atol=1e-18)
    for change, message in (({"version": 99}, "version 99"), ({"basis": 3}, "basis is 3"),
                            ({"cycle": 0}, "cycle must be an integer"), ({"gain": float("nan")}, "gain"),
                            ({"coefficients": [[1.0, 2.0]]}, "coefficients must be 16 rows"),
                            ({"coefficients": [[100.0, 0.0]] * COUNT}, "past the joint limits"),
                            ({"holding": 1}, "holding"), ({"extra": 1}, "unknown \\['extra'\\]"),
                            ({"history": [[1, 0.1, "jump"]]}, "history")):
        with pytest.raises(MrilcError, match="inconsistent per-move MRILC state: .*" + message):
            MoveLearner.from_dict({**doc, **change}, g, prof, wide())
    missing = dict(doc)
    del missing["best_cost"]
    with pytest.raises(MrilcError, match="missing \\['best_cost'\\]"):
        MoveLearner.from_dict(missing, g, prof, wide())
    many = moves_to_dict({"a->b": learner, "b->a": MoveLearner(g, prof, wide())})
    back = moves_from_dict(json.loads(json.dumps(many)),
                           lambda name, state: MoveLearner.from_dict(state, g, prof, wide()))
    assert set(back) == {"a->b", "b->a"} and back["b->a"].cycle == 1
    many["moves"]["b->a"]["cycle"] = "x"
    with pytest.raises(MrilcError, match="move 'b->a': inconsistent"):
        moves_from_dict(many, lambda name, state: MoveLearner.from_dict(state, g, prof, wide()))


def test_bad_input_is_refused_with_a_message():
    g, t = mimo_plant()
    with pytest.raises(MrilcError, match="operator must be finite, outputs x 32"):
        MoveLearner(g[:, :5], profile(t), wide())
    learner = MoveLearner(g, profile(t), wide())
    with pytest.raises(MrilcError, match="the error must be 300 finite samples, got 3"):
        learner.update(np.zeros(3))
    with pytest.raises(MrilcError, match="velocity and acceleration must be > 0"):
        JointLimits(np.zeros(2), np.ones(2), np.zeros(2), np.ones(2))
    with pytest.raises(MrilcError, match="weights must be 300"):
        MoveLearner(g, profile(t), wide(), weights=np.ones(4))


def test_a_state_written_before_peak_cost_resumes_with_the_historys_largest_cost():
    g, t = mimo_plant()
    learner = MoveLearner(g, profile(t), wide(), gain=0.7, regularisation=1e-6)
    run(learner, g, g @ np.full(2 * COUNT, 1e-3), 4)
    doc = learner.to_dict()
    assert doc["peak_cost"] == max(h[1] for h in learner.history)
    del doc["peak_cost"]  # as a learner before the rounding floor wrote it
    again = MoveLearner.from_dict(doc, g, profile(t), wide(), gain=0.7, regularisation=1e-6)
    assert again.peak == learner.peak
    doc["peak_cost"] = -1.0
    with pytest.raises(MrilcError, match="peak_cost must be >= 0"):
        MoveLearner.from_dict(doc, g, profile(t), wide(), gain=0.7, regularisation=1e-6)
