"""The MRILC learner: the feedforward profile u2 and its divergence guard, free of ROS.

:class:`MrilcLearner` holds the feedforward profile u2 (samples x joints) and learns it from one
cycle's reference r_s and measured output y (seed 000, see :mod:`.model`), with a divergence
guard: when RMS(e) has grown for ``patience`` iterations in a row, it stops learning and rolls
back to the profile that gave the smallest RMS(e) (held until resumed). Its state round-trips
through :meth:`MrilcLearner.to_dict` / :meth:`MrilcLearner.from_dict`, which checks a saved state
entry by entry (shapes, types, finiteness, consistency) before any of it is used;
:func:`learner_from_state` does the same for the learner node's whole state document. The
history of updates is kept for the last :data:`HISTORY` iterations only, so the state does not
grow with the number of cycles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.checks import finite

from .model import MrilcError, MrilcModel, rms

# model_from_params moved to .params; re-exported here only for callers that still import it
# from this module (shaper_nodes/test/test_bag_analysis.py); import it from the package instead.
from .params import model_from_params as model_from_params

#: iterations the history keeps (the newest)
HISTORY = 1000
#: what an update may do
ACTIONS = ("learn", "hold", "rollback")
#: the entries of :meth:`MrilcLearner.to_dict` (``max_rms`` may be missing in older states)
_STATE_KEYS = {"joints", "iteration", "holding", "grew", "last_rms", "profile", "best_rms", "best_profile",
               "history", "max_rms"}
#: the entries of the learner node's MRILC state document
_DOC_KEYS = {"version", "mode", "saved_at", "joint_names", "sample_period", "injection", "learner"}


@dataclass(frozen=True)
class MrilcUpdate:
    """What one cycle gave: the error and efforts measured, and the profile for the next."""

    iteration: int          # 1-based: the cycle ran with u2 of this iteration
    rms_e: float
    rms_u1: float           # nan when the effort is not measured
    rms_u2: float
    residual: float         # RMS of y - (final reference) from when the reference came to rest to the end
    action: str             # "learn", "hold" or "rollback"
    next_profile: npt.NDArray[np.float64]
    e: npt.NDArray[np.float64] = field(repr=False)
    u1: npt.NDArray[np.float64] | None = field(default=None, repr=False)


class MrilcLearner:
    """u2_{j+1} = Q [u2_j + L e_j] per joint, with the divergence guard (see the module docstring)."""

    def __init__(self, model: MrilcModel, joints: int, patience: int = 3, noise_floor: float = 1e-9) -> None:
        if joints < 1:
            raise MrilcError("the learner needs at least one joint")
        if patience < 1:
            raise MrilcError(f"patience must be >= 1, got {patience}")
        if not (math.isfinite(noise_floor) and noise_floor >= 0):
            raise MrilcError(f"noise_floor must be finite and >= 0, got {noise_floor!r}")
        self.model, self.joints, self.patience = model, int(joints), int(patience)
        self.noise_floor = float(noise_floor)  # RMS(e) below which growth is not divergence
        self.profile = np.zeros((0, self.joints))   # u2 of the next cycle (empty: zero)
        self.iteration = 1                           # the next cycle's iteration
        self.history: list[tuple[int, float, float, float, str]] = []
        self.best: tuple[float, npt.NDArray[np.float64]] | None = None
        self.holding = False
        self._grew = 0
        self._last_rms: float | None = None
        self._max_rms = 0.0   # the largest RMS(e) seen (the history keeps only the last HISTORY)

    def profile_for(self, samples: int) -> npt.NDArray[np.float64]:
        """The profile over a cycle of ``samples`` samples (zero where none is learned yet)."""
        if self.profile.shape[0] == 0:
            return np.zeros((samples, self.joints))
        if self.profile.shape[0] != samples:
            raise MrilcError(f"the cycle has {samples} samples but the learned profile {self.profile.shape[0]}:"
                             " the task changed; reset the learner (delete its state) to learn the new one")
        return self.profile

    def learn(self, r_s: npt.ArrayLike, y: npt.ArrayLike, effort: npt.ArrayLike | None = None) -> MrilcUpdate:
        """One cycle: r_s and y (samples x joints) on the sample grid from the cycle's START,
        effort (optional, same shape) the total control effort u = u1 + u2 measured."""
        r_s = _matrix("reference", r_s, self.joints)
        y = _matrix("output y", y, self.joints)
        if r_s.shape != y.shape:
            raise MrilcError(f"reference has {r_s.shape[0]} samples but y has {y.shape[0]}")
        if r_s.shape[0] < 4:
            raise MrilcError(f"a cycle needs at least 4 samples, got {r_s.shape[0]}")
        u2 = self.profile_for(r_s.shape[0])
        e = self.model.reference_response(r_s, rest=y[0]) - y  # the cycle starts at rest
        u1 = None
        if effort is not None:
            effort = _matrix("effort", effort, self.joints)
            if effort.shape != y.shape:
                raise MrilcError(f"effort has {effort.shape[0]} samples but y has {y.shape[0]}")
            u1 = effort - u2 if self.model.injection == "effort" else effort
        rms_e, rms_u2 = rms(e), rms(u2)
        moving = np.flatnonzero(np.any(np.abs(np.diff(r_s, axis=0)) > 1e-12, axis=1))
        rest = int(moving[-1]) + 2 if moving.size else 0  # first sample after the last change has acted
        residual = rms(y[rest:] - r_s[-1]) if rest < y.shape[0] else math.nan
        rms_u1 = rms(u1) if u1 is not None else math.nan
        if self.best is None or rms_e < self.best[0]:
            self.best = (rms_e, u2.copy())
        # growth counts only above the numerical floor (a converged error just jitters there)
        self._max_rms = max(self._max_rms, rms_e)
        floor = max(self.noise_floor, 1e-9 * self._max_rms)
        grew = self._last_rms is not None and rms_e > self._last_rms and rms_e > floor
        self._grew = self._grew + 1 if grew else 0
        self._last_rms = rms_e
        if self.holding:
            action, nxt = "hold", self.best[1]
        elif self._grew >= self.patience:
            self.holding = True
            action, nxt = "rollback", self.best[1]
        else:
            action, nxt = "learn", self.model.learning.update(u2, e)
        if not np.all(np.isfinite(nxt)):
            self.holding = True
            action, nxt = "rollback", self.best[1]
        update = MrilcUpdate(self.iteration, rms_e, rms_u1, rms_u2, residual, action, nxt, e, u1)
        self.history.append((self.iteration, rms_e, rms_u1, rms_u2, action))
        del self.history[:-HISTORY]
        self.profile = np.array(nxt, dtype=float)
        self.iteration += 1
        return update

    def hold(self) -> npt.NDArray[np.float64]:
        """Stop learning; the best profile so far becomes the next one."""
        self.holding = True
        if self.best is not None:
            self.profile = self.best[1].copy()
        return self.profile

    def resume(self) -> None:
        self.holding = False
        self._grew = 0

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        return {"joints": self.joints, "iteration": self.iteration, "holding": self.holding,
                "grew": self._grew, "last_rms": self._last_rms, "profile": self.profile.tolist(),
                "best_rms": None if self.best is None else self.best[0],
                "best_profile": None if self.best is None else self.best[1].tolist(),
                "history": [list(h) for h in self.history], "max_rms": self._max_rms}

    @classmethod
    def from_dict(cls, model: MrilcModel, doc: Any, patience: int = 3, noise_floor: float = 1e-9) -> MrilcLearner:
        """Restore :meth:`to_dict`'s state, every entry checked before any is used.

        Raises
        ------
        MrilcError
            ``inconsistent MRILC state: ...`` naming the entry: missing or unknown entries, a value
            of the wrong type, a profile of the wrong shape, a non-finite number, or entries that
            contradict each other (a best profile without history, history not ending at the
            iteration before ``iteration``, ...).
        """
        try:
            return cls._from_dict(model, doc, patience, noise_floor)
        except MrilcError as err:
            raise MrilcError(f"inconsistent MRILC state: {err}") from None

    @classmethod
    def _from_dict(cls, model: MrilcModel, doc: Any, patience: int, noise_floor: float) -> MrilcLearner:
        if not isinstance(doc, dict):
            raise MrilcError(f"the learner state must be a dictionary, got {type(doc).__name__}")
        missing, unknown = _STATE_KEYS - {"max_rms"} - set(doc), set(doc) - _STATE_KEYS
        if missing or unknown:
            raise MrilcError(f"entries missing {sorted(missing)}, unknown {sorted(unknown)}")
        learner = cls(model, _count("joints", doc["joints"], 1), patience, noise_floor)
        learner.iteration = _count("iteration", doc["iteration"], 1)
        learner._grew = _count("grew", doc["grew"], 0)
        if not isinstance(doc["holding"], bool):
            raise MrilcError(f"holding must be true or false, got {doc['holding']!r}")
        learner.holding = doc["holding"]
        learner.history = _history(doc["history"], learner.iteration)
        learner.profile = _profile("profile", doc["profile"], learner.joints)
        learned = bool(learner.history)
        if learner.iteration > 1 and not learned:
            raise MrilcError(f"iteration {learner.iteration} without any history")
        if (doc["last_rms"] is None) == learned or (doc["best_profile"] is None) == learned:
            raise MrilcError("last_rms and best_profile must be given exactly when there is history")
        if learned:
            learner._last_rms = _rms("last_rms", doc["last_rms"])
            best = _profile("best_profile", doc["best_profile"], learner.joints)
            if best.shape != learner.profile.shape or best.shape[0] < 4:
                raise MrilcError(f"best_profile has shape {best.shape}, the profile {learner.profile.shape}"
                                 " (both must be the same, at least 4 samples)")
            learner.best = (_rms("best_rms", doc["best_rms"]), best)
        elif doc["best_rms"] is not None:
            raise MrilcError("best_rms without a best_profile")
        seen = max([h[1] for h in learner.history] + [learner._last_rms or 0.0])
        learner._max_rms = max(_rms("max_rms", doc["max_rms"]), seen) if "max_rms" in doc else seen
        return learner


def learner_from_state(doc: Any, model: MrilcModel, joint_names: list[str] | tuple[str, ...], injection: str,
                       patience: int = 3, noise_floor: float = 1e-9) -> tuple[MrilcLearner, list[str]]:
    """The learner and its joints from the learner node's MRILC state document (``version``,
    ``mode``, ``saved_at``, ``joint_names``, ``sample_period``, ``injection``, ``learner``), every
    entry checked against the node's set-up: ``model``'s sample period, the configured
    ``joint_names`` (empty: any) and ``injection``.

    Raises
    ------
    MrilcError
        An entry missing, unknown, of the wrong type, or saved for another set-up (naming it).
    """
    if not isinstance(doc, dict):
        raise MrilcError(f"the MRILC state must be a dictionary, got {type(doc).__name__}")
    missing, unknown = _DOC_KEYS - {"saved_at"} - set(doc), set(doc) - _DOC_KEYS
    if missing or unknown:
        raise MrilcError(f"MRILC state entries differ: missing {sorted(missing)}, unknown {sorted(unknown)}")
    if "saved_at" in doc:
        finite("saved_at", doc["saved_at"], MrilcError)
    period = finite("sample_period", doc["sample_period"], MrilcError)
    if abs(period - model.period) > 1e-12:
        raise MrilcError(f"saved for a sample period of {period} s, not {model.period} s")
    names = doc["joint_names"]
    if (not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names)
            or len(set(names)) != len(names)):
        raise MrilcError(f"joint_names must be a list of distinct non-empty names, got {names!r}")
    if joint_names and names != list(joint_names):
        raise MrilcError(f"saved for joints {names}, not {list(joint_names)}")
    if doc["injection"] != injection:
        raise MrilcError(f"saved for injection {doc['injection']!r}, not {injection!r}")
    learner = MrilcLearner.from_dict(model, doc["learner"], patience, noise_floor)
    if learner.joints != len(names):
        raise MrilcError(f"inconsistent MRILC state: {learner.joints} joints learned, {len(names)} named")
    return learner, list(names)


def _count(name: str, value: Any, lo: int) -> int:
    """An int (not a bool, not a float) of at least ``lo``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise MrilcError(f"{name} must be an integer >= {lo}, got {value!r}")
    return value


def _rms(name: str, value: Any) -> float:
    """A finite number >= 0 (an RMS)."""
    x = finite(name, value, MrilcError)
    if x < 0.0:
        raise MrilcError(f"{name} must be >= 0, got {value!r}")
    return x


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _profile(name: str, value: Any, joints: int) -> npt.NDArray[np.float64]:
    """A list of rows of ``joints`` finite numbers (an empty list: no profile) as (samples, joints)."""
    if not isinstance(value, list) or not all(isinstance(row, list) and len(row) == joints for row in value):
        raise MrilcError(f"{name} must be a list of rows of {joints} numbers")
    if not all(_number(x) for row in value for x in row):
        raise MrilcError(f"{name} must hold numbers only")
    a = np.array(value, dtype=float).reshape(-1, joints)
    if not np.all(np.isfinite(a)):
        raise MrilcError(f"{name} has a non-finite value at sample {int(np.argwhere(~np.isfinite(a))[0][0])}")
    return a


def _history(value: Any, iteration: int) -> list[tuple[int, float, float, float, str]]:
    """The history: at most :data:`HISTORY` entries [iteration, rms_e, rms_u1 (NaN: no effort),
    rms_u2, action], iterations consecutive up to ``iteration - 1``."""
    if not isinstance(value, list):
        raise MrilcError(f"history must be a list, got {type(value).__name__}")
    out = []
    for k, h in enumerate(value):
        if (not isinstance(h, list) or len(h) != 5 or not all(_number(x) for x in h[1:4])
                or h[4] not in ACTIONS):
            raise MrilcError(f"history entry {k} must be [iteration, rms_e, rms_u1, rms_u2, action], got {h!r}")
        u1 = float(h[2])
        if not (math.isnan(u1) or (math.isfinite(u1) and u1 >= 0.0)):
            raise MrilcError(f"history entry {k}: rms_u1 must be >= 0 (or NaN: not measured), got {h[2]!r}")
        out.append((_count(f"history entry {k} iteration", h[0], 1), _rms(f"history entry {k} rms_e", h[1]), u1,
                    _rms(f"history entry {k} rms_u2", h[3]), str(h[4])))
    its = [h[0] for h in out]
    if its and its != list(range(iteration - len(its), iteration)):
        raise MrilcError(f"history iterations {its[0]}..{its[-1]} must run consecutively up to {iteration - 1}")
    return out[-HISTORY:]


def _matrix(name: str, x: npt.ArrayLike, joints: int) -> npt.NDArray[np.float64]:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1 and joints == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] != joints:
        raise MrilcError(f"{name} must be samples x {joints} joints, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        k = int(np.argwhere(~np.isfinite(a))[0][0])
        raise MrilcError(f"{name} has a non-finite value at sample {k}")
    return a

