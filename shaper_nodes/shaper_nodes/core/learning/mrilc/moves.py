"""MRILC per move: a feedforward correction of each joint's commanded profile, learned cycle by cycle, free of ROS.

Seed 000's structure on a multi-joint robot whose controller takes position setpoints: for one
move, the commanded joint profile q_c(t) (the shaped planned trajectory) gets a correction

    dq_j(t) = sum_i c_ij b_i(t),    dq_j'(t), dq_j''(t) from the same sum,

over cubic B-splines b_i on uniform knots that lie inside the shaped motion [0, T] (so the
correction and its first two derivatives are zero at the move's start and end: the goal pose
and the move's timing do not change). The measured output y is the tool's response (e.g. a
flange accelerometer, stacked samples x axes) and the reference y_m the response of the
reference model (e.g. the rigid arm following q_c). The learning operator is lifted (a matrix):
G maps the coefficients c (basis functions x joints, flattened joint-major) to y, given by the
caller (e.g. the arm linearised at the move's end pose), and every cycle

    c_{j+1} = P( c_j + gamma L e_j ),   e_j = y_m - y_j,   L = (G^T W G + rho I)^-1 G^T W,

P the projection (in the norm of G^T W G + rho I, :func:`~.profile.project`) onto the corrections that keep
the corrected profile inside the joint limits
(:class:`~.profile.JointLimits`: position range, velocity and acceleration bounds; checked on the
profile's sample times); the points sent are the corrected profile clipped into the limits
(:meth:`MoveLearner.corrected`, :func:`~.profile.clip_into`), so that a correction that meets a limit with
equality holds it exactly (:func:`~.profile.profile_excess` 0), not to rounding (the basis, the limits and the
projection: :mod:`.profile`). The work per cycle is bounded: one product with the precomputed L and
a projection of at most :data:`~.profile.PROJECTION_ROUNDS` x 8 sweeps of Hildreth's method over the violated
samples.

Divergence guard: the learner keeps the coefficients that gave the smallest cost
(the weighted RMS(e)); when the cost exceeds ``growth`` times the best (and the noise floor, and :data:`ROUNDING`
times the largest cost seen: rounding) for ``patience`` cycles in a row, it falls back to the best coefficients
and halves gamma; after ``max_fallbacks`` fallbacks it holds the best. The state round-trips through
:meth:`MoveLearner.to_dict` / :meth:`MoveLearner.from_dict` (JSON-compatible, with
:data:`STATE_VERSION`), checked entry by entry before any of it is used; :func:`moves_to_dict`
and :func:`moves_from_dict` do the same for one learner per move.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .model import MrilcError
from .profile import Array, JointLimits, Profile, clip_into, excess, project

#: version of :meth:`MoveLearner.to_dict`'s document
STATE_VERSION = 1
#: cycles the history keeps (the newest)
HISTORY = 200
#: what an update may do
ACTIONS = ("learn", "fallback", "hold")
_KEYS = {"version", "basis", "joints", "outputs", "gain", "cycle", "coefficients", "best_cost", "best_coefficients",
         "grew", "fallbacks", "holding", "history"}
#: entries a state may lack (written by a learner before them): ``peak_cost`` (then the history's largest cost)
_OPTIONAL = {"peak_cost"}
#: the divergence guard's floor relative to the largest cost seen: below it a cost is rounding, never growth (as
#: the seed learner's, :class:`~shaper_nodes.core.learning.mrilc.learner.MrilcLearner`); a learner converged to the
#: rounding of float64 otherwise reads rounding's scatter as growth and falls back
ROUNDING = 1e-9



@dataclass(frozen=True)
class MoveUpdate:
    """One cycle of one move: the cost measured, what was done, the coefficients for the next cycle."""

    cycle: int       # 1-based: the cycle that ran with the coefficients of this cycle
    cost: float      # RMS(e) over the move's samples, the output's unit
    action: str      # "learn", "fallback" or "hold"
    gain: float      # gamma after this update
    coefficients: Array


class MoveLearner:
    """The lifted ILC of one move (module docstring).

    Parameters
    ----------
    operator : (outputs, basis * joints) array
        G: the output's response to each coefficient (coefficient index = joint * basis + i).
    profile : Profile
        The move's commanded profile and the basis at its sample times.
    limits : JointLimits
        The limits the corrected profile must hold.
    gain : float
        gamma in (0, 1].
    regularisation : float
        rho relative to the mean of diag(G^T G) (> 0: bounds the step where G is nearly singular).
    weights : (outputs,) array, optional
        W >= 0 per output sample: L = (G^T W G + rho I)^-1 G^T W and the cost is the weighted RMS(e)
        (default 1).
    patience, growth, noise_floor, max_fallbacks
        The divergence guard: cost > growth x best and > noise_floor (output unit) and > ROUNDING x the largest
        cost seen for ``patience`` cycles in a row -> fall back to the best coefficients, halve gamma; after
        ``max_fallbacks`` falls back: hold.
    """

    def __init__(self, operator: npt.ArrayLike, profile: Profile, limits: JointLimits, gain: float = 0.5,
                 regularisation: float = 1e-3, patience: int = 2, growth: float = 1.2, noise_floor: float = 0.0,
                 max_fallbacks: int = 3, weights: npt.ArrayLike | None = None) -> None:
        g = np.asarray(operator, dtype=float)
        basis, joints = profile.basis[0].shape[1], profile.positions.shape[1]
        if g.ndim != 2 or g.shape[1] != basis * joints or not np.all(np.isfinite(g)):
            raise MrilcError(f"the operator must be finite, outputs x {basis * joints} (basis x joints),"
                             f" got shape {g.shape}")
        if not (0 < gain <= 1) or not regularisation > 0 or patience < 1 or not growth > 1 or noise_floor < 0:
            raise MrilcError("gain must be in (0, 1], regularisation > 0, patience >= 1, growth > 1,"
                             " noise_floor >= 0")
        w = np.ones(g.shape[0]) if weights is None else np.asarray(weights, dtype=float).ravel()
        if w.shape != (g.shape[0],) or not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
            raise MrilcError(f"weights must be {g.shape[0]} finite numbers >= 0, not all zero")
        self.weights = w
        self.operator, self.profile, self.limits = g, profile, limits
        self.basis, self.joints, self.outputs = basis, joints, g.shape[0]
        self.patience, self.growth, self.noise_floor, self.max_fallbacks = patience, growth, noise_floor, max_fallbacks
        gw = g.T * w
        gtg = gw @ g
        rho = regularisation * max(float(np.mean(np.diag(gtg))), 1e-300)
        self._metric = gtg + rho * np.eye(gtg.shape[0])
        self._law = np.linalg.solve(self._metric, gw)
        self.gain = float(gain)
        self.cycle = 1
        self.coefficients = np.zeros((basis, joints))
        self.best: tuple[float, Array] | None = None
        self.grew = 0
        self.fallbacks = 0
        self.holding = False
        self.history: list[tuple[int, float, str]] = []
        self.peak = 0.0  # the largest cost seen

    def correction(self) -> tuple[Array, Array, Array]:
        """The next cycle's dq, dq', dq'' at the profile's samples, (samples, joints) each."""
        return self.profile.correction(self.coefficients)

    def corrected(self) -> tuple[Array, Array, Array]:
        """The next cycle's profile, corrected and its points clipped into the limits (:func:`clip_into`: where the
        correction meets a limit with equality it holds it exactly, not to rounding), (samples, joints) each."""
        p = self.profile
        return clip_into(*p.corrected(self.coefficients), self.limits, (p.positions, p.velocities, p.accelerations))

    def update(self, error: npt.ArrayLike) -> MoveUpdate:
        """One cycle: ``error`` = y_m - y (outputs,) measured with the present coefficients."""
        e = np.asarray(error, dtype=float).ravel()
        if e.size != self.outputs or not np.all(np.isfinite(e)):
            raise MrilcError(f"the error must be {self.outputs} finite samples, got {e.size}"
                             + ("" if e.size != self.outputs else " with a non-finite value"))
        cost = float(np.sqrt(np.sum(self.weights * e**2) / np.sum(self.weights)))
        self.peak = max(self.peak, cost)
        if self.best is None or cost < self.best[0]:
            self.best = (cost, self.coefficients.copy())
            self.grew = 0
        elif cost > self.growth * self.best[0] and cost > max(self.noise_floor, ROUNDING * self.peak):
            self.grew += 1
        else:
            self.grew = 0
        if self.holding:
            action, nxt = "hold", self.best[1].copy()
        elif self.grew >= self.patience:
            self.fallbacks += 1
            self.gain *= 0.5
            self.grew = 0
            self.holding = self.fallbacks >= self.max_fallbacks
            action, nxt = ("hold" if self.holding else "fallback"), self.best[1].copy()
        else:
            step = (self._law @ e).reshape(self.joints, self.basis).T
            nxt = project(self.coefficients + self.gain * step, self.profile, self.limits, self.coefficients,
                          self._metric)
            action = "learn"
        self.history.append((self.cycle, cost, action))
        del self.history[:-HISTORY]
        self.coefficients = nxt
        self.cycle += 1
        return MoveUpdate(self.cycle - 1, cost, action, self.gain, nxt.copy())

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """The state as a JSON-compatible dictionary (the operator and profile are the caller's: not saved)."""
        return {"version": STATE_VERSION, "basis": self.basis, "joints": self.joints, "outputs": self.outputs,
                "gain": self.gain, "cycle": self.cycle, "coefficients": self.coefficients.tolist(),
                "best_cost": None if self.best is None else self.best[0],
                "best_coefficients": None if self.best is None else self.best[1].tolist(),
                "grew": self.grew, "fallbacks": self.fallbacks, "holding": self.holding,
                "history": [list(h) for h in self.history], "peak_cost": self.peak}

    @classmethod
    def from_dict(cls, doc: Any, operator: npt.ArrayLike, profile: Profile, limits: JointLimits,
                  **settings: Any) -> MoveLearner:
        """Restore :meth:`to_dict`'s state for this operator and profile, every entry checked before use.

        Raises MrilcError ``inconsistent per-move MRILC state: ...`` naming the entry (missing or unknown
        entries, another version, sizes that do not match the operator, a wrong type, a non-finite value,
        coefficients outside the limits).
        """
        try:
            return cls._from_dict(doc, operator, profile, limits, settings)
        except MrilcError as err:
            raise MrilcError(f"inconsistent per-move MRILC state: {err}") from None

    @classmethod
    def _from_dict(cls, doc: Any, operator: npt.ArrayLike, profile: Profile, limits: JointLimits,
                   settings: dict[str, Any]) -> MoveLearner:
        if not isinstance(doc, dict):
            raise MrilcError(f"the state must be a dictionary, got {type(doc).__name__}")
        missing, unknown = _KEYS - set(doc), set(doc) - _KEYS - _OPTIONAL
        if missing or unknown:
            raise MrilcError(f"entries missing {sorted(missing)}, unknown {sorted(unknown)}")
        if doc["version"] != STATE_VERSION:
            raise MrilcError(f"version {doc['version']!r}, this learner reads {STATE_VERSION}")
        gain = _number("gain", doc["gain"])
        if not 0 < gain <= 1:
            raise MrilcError(f"gain must be in (0, 1], got {gain}")
        learner = cls(operator, profile, limits, **{**settings, "gain": gain})
        for key, have in (("basis", learner.basis), ("joints", learner.joints), ("outputs", learner.outputs)):
            if _integer(key, doc[key], 1) != have:
                raise MrilcError(f"{key} is {doc[key]}, the move's operator has {have}")
        learner.cycle = _integer("cycle", doc["cycle"], 1)
        learner.grew = _integer("grew", doc["grew"], 0)
        learner.fallbacks = _integer("fallbacks", doc["fallbacks"], 0)
        if not isinstance(doc["holding"], bool):
            raise MrilcError(f"holding must be true or false, got {doc['holding']!r}")
        learner.holding = doc["holding"]
        shape = (learner.basis, learner.joints)
        learner.coefficients = _coefficients("coefficients", doc["coefficients"], shape, profile, limits)
        if (doc["best_cost"] is None) != (doc["best_coefficients"] is None) or (doc["best_cost"] is None) != (
                learner.cycle == 1):
            raise MrilcError("best_cost and best_coefficients must be given exactly when a cycle has been learned")
        if doc["best_cost"] is not None:
            cost = _number("best_cost", doc["best_cost"])
            if cost < 0:
                raise MrilcError(f"best_cost must be >= 0, got {cost}")
            learner.best = (cost, _coefficients("best_coefficients", doc["best_coefficients"], shape, profile, limits))
        hist = doc["history"]
        if not isinstance(hist, list) or not all(
                isinstance(h, list) and len(h) == 3 and isinstance(h[0], int) and h[2] in ACTIONS for h in hist):
            raise MrilcError("history must be a list of [cycle, cost, action]")
        learner.history = [(int(h[0]), _number(f"history cost of cycle {h[0]}", h[1]), str(h[2])) for h in hist]
        if hist and [h[0] for h in hist] != list(range(learner.cycle - len(hist), learner.cycle)):
            raise MrilcError(f"history cycles must run consecutively up to {learner.cycle - 1}")
        peak = _number("peak_cost", doc["peak_cost"]) if "peak_cost" in doc else max(
            [h[1] for h in learner.history] + [learner.best[0] if learner.best else 0.0])
        if peak < 0:
            raise MrilcError(f"peak_cost must be >= 0, got {peak}")
        learner.peak = peak
        return learner


def moves_to_dict(learners: Mapping[str, MoveLearner]) -> dict[str, Any]:
    """One document for a learner per move (``version`` and ``moves``: name -> :meth:`MoveLearner.to_dict`)."""
    return {"version": STATE_VERSION, "moves": {name: lr.to_dict() for name, lr in learners.items()}}


def moves_from_dict(doc: Any, make: Callable[[str, Any | None], MoveLearner]) -> dict[str, MoveLearner]:
    """The learners of :func:`moves_to_dict`'s document; ``make(name, state)`` builds one (state None: new).

    Raises MrilcError naming the entry or the move whose state is inconsistent.
    """
    if not isinstance(doc, dict) or set(doc) != {"version", "moves"} or not isinstance(doc["moves"], dict):
        raise MrilcError("inconsistent per-move MRILC state: a dictionary with version and moves expected")
    if doc["version"] != STATE_VERSION:
        raise MrilcError(f"inconsistent per-move MRILC state: version {doc['version']!r}, this reads {STATE_VERSION}")
    out = {}
    for name, state in doc["moves"].items():
        try:
            out[name] = make(name, state)
        except MrilcError as err:
            raise MrilcError(f"move {name!r}: {err}") from None
    return out


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MrilcError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _integer(name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise MrilcError(f"{name} must be an integer >= {lo}, got {value!r}")
    return value


def _coefficients(name: str, value: Any, shape: tuple[int, int], profile: Profile, limits: JointLimits) -> Array:
    if (not isinstance(value, list) or len(value) != shape[0]
            or not all(isinstance(r, list) and len(r) == shape[1] for r in value)):
        raise MrilcError(f"{name} must be {shape[0]} rows of {shape[1]} numbers")
    for r in value:
        for x in r:
            _number(name, x)
    c = np.array(value, dtype=float)
    worst = excess(c, profile, limits)
    if worst > 1e-9:
        raise MrilcError(f"{name} take the profile past the joint limits by {worst:.3g}")
    return c
