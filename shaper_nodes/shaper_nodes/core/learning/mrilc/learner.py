"""The MRILC learner: the feedforward profile u2 and its divergence guard, free of ROS.

:class:`MrilcLearner` holds the feedforward profile u2 (samples x joints) and learns it from one
cycle's reference r_s and measured output y (seed 000, see :mod:`.model`), with a divergence
guard: when RMS(e) has grown for ``patience`` iterations in a row, it stops learning and rolls
back to the profile that gave the smallest RMS(e) (held until resumed). Its state round-trips
through :meth:`MrilcLearner.to_dict` / :meth:`MrilcLearner.from_dict`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .model import MrilcError, MrilcModel, rms

# model_from_params moved to .params; re-exported here only for callers that still import it
# from this module (shaper_nodes/test/test_bag_analysis.py); import it from the package instead.
from .params import model_from_params as model_from_params


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
        floor = max(self.noise_floor, 1e-9 * max([h[1] for h in self.history] + [rms_e]))
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
                "history": [list(h) for h in self.history]}

    @classmethod
    def from_dict(cls, model: MrilcModel, doc: dict[str, Any], patience: int = 3, noise_floor: float = 1e-9
                  ) -> MrilcLearner:
        try:
            learner = cls(model, int(doc["joints"]), patience, noise_floor)
            learner.iteration = int(doc["iteration"])
            learner.holding = bool(doc["holding"])
            learner._grew = int(doc["grew"])
            learner._last_rms = None if doc["last_rms"] is None else float(doc["last_rms"])
            profile = np.asarray(doc["profile"], dtype=float).reshape(-1, learner.joints)
            if doc["best_profile"] is not None:
                learner.best = (float(doc["best_rms"]),
                                np.asarray(doc["best_profile"], dtype=float).reshape(-1, learner.joints))
            learner.history = [(int(h[0]), float(h[1]), float(h[2]), float(h[3]), str(h[4])) for h in doc["history"]]
        except (KeyError, TypeError, ValueError) as err:
            raise MrilcError(f"inconsistent MRILC state: {err}") from None
        if not np.all(np.isfinite(profile)) or learner.iteration < 1:
            raise MrilcError("inconsistent MRILC state: non-finite profile or iteration < 1")
        learner.profile = profile
        return learner


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

