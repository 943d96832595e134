"""The MRILC learner's state and its per-cycle bookkeeping, free of ROS.

:class:`MrilcLearner` holds the feedforward profile u2 (samples x joints) and learns it from one
cycle's reference r_s and measured output y (seed 000, see :mod:`.mrilc`), with a divergence
guard: when RMS(e) has grown for ``patience`` iterations in a row, it stops learning and rolls
back to the profile that gave the smallest RMS(e) (held until resumed).

:class:`MrilcSession` turns the streams a learner sees (joint states, the applied reference,
cycle events) into whole cycles on the sample grid, rejecting cycles with missing, stale or
non-finite samples, and calls the learner. The learner node and offline replays share it.

:data:`DEFAULTS` and :func:`model_from_params` build the model and the learner's settings from
the learner node's ``mrilc.*`` parameters (names, defaults and ranges single-sourced here), so
that the node and offline replays configure the learner the same way.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from shaper_nodes.core.cycles import END, START
from shaper_nodes.core.learning.mrilc import model as M

from .model import MrilcError, MrilcModel, rms


@dataclass(frozen=True)
class MrilcUpdate:
    """What one cycle gave: the error and efforts measured, and the profile for the next."""

    iteration: int          # 1-based: the cycle ran with u2 of this iteration
    rms_e: float
    rms_u1: float           # nan when the effort is not measured
    rms_u2: float
    residual: float         # RMS of y - (final reference) from when the reference came to rest to the end
    action: str             # "learn", "hold" or "rollback"
    next_profile: np.ndarray
    e: np.ndarray = field(repr=False)
    u1: np.ndarray | None = field(default=None, repr=False)


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
        self.best: tuple[float, np.ndarray] | None = None
        self.holding = False
        self._grew = 0
        self._last_rms: float | None = None

    def profile_for(self, samples: int) -> np.ndarray:
        """The profile over a cycle of ``samples`` samples (zero where none is learned yet)."""
        if self.profile.shape[0] == 0:
            return np.zeros((samples, self.joints))
        if self.profile.shape[0] != samples:
            raise MrilcError(f"the cycle has {samples} samples but the learned profile {self.profile.shape[0]}:"
                             " the task changed; reset the learner (delete its state) to learn the new one")
        return self.profile

    def learn(self, r_s, y, effort=None) -> MrilcUpdate:
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

    def hold(self) -> np.ndarray:
        """Stop learning; the best profile so far becomes the next one."""
        self.holding = True
        if self.best is not None:
            self.profile = self.best[1].copy()
        return self.profile

    def resume(self) -> None:
        self.holding = False
        self._grew = 0

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict:
        return {"joints": self.joints, "iteration": self.iteration, "holding": self.holding,
                "grew": self._grew, "last_rms": self._last_rms, "profile": self.profile.tolist(),
                "best_rms": None if self.best is None else self.best[0],
                "best_profile": None if self.best is None else self.best[1].tolist(),
                "history": [list(h) for h in self.history]}

    @classmethod
    def from_dict(cls, model: MrilcModel, doc: dict, patience: int = 3, noise_floor: float = 1e-9) -> MrilcLearner:
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


def _matrix(name: str, x, joints: int) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1 and joints == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] != joints:
        raise MrilcError(f"{name} must be samples x {joints} joints, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        k = int(np.argwhere(~np.isfinite(a))[0][0])
        raise MrilcError(f"{name} has a non-finite value at sample {k}")
    return a


# ----------------------------------------------------------------------------- session
@dataclass
class MrilcCycle:
    """One cycle's outcome: the update, or why it was skipped."""

    cycle: int
    start: float
    end: float
    update: MrilcUpdate | None = None
    skipped: str = ""


class _Stream:
    """Samples keyed by stamp (s), kept in order; old ones dropped."""

    def __init__(self, keep: float = 3600.0) -> None:
        self.t: list[float] = []
        self.v: list[np.ndarray] = []
        self.keep = keep

    def add(self, t: float, value: np.ndarray) -> None:
        if self.t and t <= self.t[-1]:
            if t == self.t[-1]:
                self.v[-1] = value  # a repeated stamp: the newest wins
                return
            i = bisect.bisect_left(self.t, t)
            self.t.insert(i, t)
            self.v.insert(i, value)
            return
        self.t.append(t)
        self.v.append(value)

    def latest(self) -> float:
        return self.t[-1] if self.t else -math.inf

    def prune(self, before: float) -> None:
        i = bisect.bisect_left(self.t, before)
        del self.t[:i], self.v[:i]

    def grid(self, t0: float, period: float, n: int, name: str) -> np.ndarray:
        """The samples at t0 + k period, k < n; MrilcError naming the first missing one."""
        i0 = bisect.bisect_left(self.t, t0 - 0.25 * period)
        t = np.asarray(self.t[i0:i0 + n + 1])
        want = t0 + period * np.arange(n)
        if t.size < n:
            missing = n - t.size
            raise MrilcError(f"{missing} of {n} {name} samples missing in the cycle")
        k = np.rint((t[:n] - t0) / period).astype(int)
        if not np.array_equal(k, np.arange(n)) or np.max(np.abs(t[:n] - want)) > 0.25 * period:
            first = int(np.argmax(k != np.arange(n))) if not np.array_equal(k, np.arange(n)) else 0
            raise MrilcError(f"{name} samples are not on the {period:g} s grid from START: first gap or"
                             f" jitter at t = {want[first]:.6f} s (sample {first} of {n})")
        return np.stack(self.v[i0:i0 + n])


class MrilcSession:
    """Collects joint states (y and effort), the applied reference and cycle events.

    ``on_joint_state(t, positions, efforts)`` and ``on_reference(t, positions)`` take samples
    already ordered as the learner's joints (None for a missing effort). A cycle is learned
    from at its END if the profile the learner sent was installed before its START
    (``profile_ready``), every sample from START to END is there on the grid and finite.
    """

    def __init__(self, learner: MrilcLearner, stale_after: float = 0.1) -> None:
        self.learner = learner
        self.period = learner.model.period
        self.stale_after = float(stale_after)
        self.y, self.ref, self.effort = _Stream(), _Stream(), _Stream()
        self._cycle: int | None = None
        self._start = 0.0
        self._ready_at_start = False
        self.profile_ready = True  # False from sending a profile until it is accepted

    @property
    def latest(self) -> float:
        """The oldest of the newest stamps of y and the reference: how far both have arrived."""
        return min(self.y.latest(), self.ref.latest())

    def on_joint_state(self, t: float, positions, efforts=None) -> None:
        self.y.add(t, np.asarray(positions, dtype=float))
        if efforts is not None:
            self.effort.add(t, np.asarray(efforts, dtype=float))

    def on_reference(self, t: float, positions) -> None:
        self.ref.add(t, np.asarray(positions, dtype=float))

    def on_event(self, kind: int, cycle: int, t: float) -> MrilcCycle | None:
        if kind == START:
            self._cycle, self._start = int(cycle), float(t)
            self._ready_at_start = self.profile_ready
            for s in (self.y, self.ref, self.effort):
                s.prune(t - 1.0)
            return None
        if kind != END:
            return None
        if self._cycle != int(cycle):
            return MrilcCycle(int(cycle), math.nan, t, skipped=f"END of cycle {cycle} without its START")
        out = MrilcCycle(int(cycle), self._start, float(t))
        self._cycle = None
        if not self._ready_at_start:
            out.skipped = "the cycle started before the learner's profile was installed"
            return out
        if self.latest < t - self.stale_after:
            out.skipped = (f"stale data: the newest joint state / reference is {t - self.latest:.3f} s older than"
                           f" END (limit {self.stale_after:g} s)")
            return out
        n = int(round((t - self._start) / self.period)) + 1
        try:
            y = self.y.grid(self._start, self.period, n, "joint state")
            r = self.ref.grid(self._start, self.period, n, "reference")
            try:
                effort = self.effort.grid(self._start, self.period, n, "effort")
            except MrilcError:
                effort = None
            out.update = self.learner.learn(r, y, effort)
        except MrilcError as err:
            out.skipped = str(err)
        return out


# ----------------------------------------------------------------------------- configuration
#: the learner node's MRILC parameters and their defaults (the node declares exactly these)
DEFAULTS: dict[str, object] = {
    "mrilc.rate": 200.0,
    "mrilc.controller.numerator": list(M.PAPER_CONTROLLER[0]),
    "mrilc.controller.denominator": list(M.PAPER_CONTROLLER[1]),
    "mrilc.nominal.omega": M.PAPER_NOMINAL[0],
    "mrilc.nominal.zeta": M.PAPER_NOMINAL[1],
    "mrilc.check.omegas": list(M.PAPER_OMEGAS),
    "mrilc.check.zetas": list(M.PAPER_ZETAS),
    "mrilc.check.min_frequency_hz": 0.1,
    "mrilc.law": "p",
    "mrilc.gamma": 10.0,
    "mrilc.lambda": 0.0,
    "mrilc.robust_gain": 0.7,
    "mrilc.q_cutoff_hz": 0.0,
    "mrilc.q_order": 2,
    "mrilc.injection": "effort",
    "mrilc.injection_target": "/sim_plant",
    "mrilc.shaper_family": "zvd",
    "mrilc.learn": True,
    "mrilc.patience": 3,
    "mrilc.noise_floor": 1e-9,
    "joint_names": [""],
    "topics.joint_states": "/joint_states",
    "topics.reference": "/sim_plant/reference",
    "topics.cycle_events": "/cycle_events",
}
#: numeric parameters: (low, high, integer); the node's descriptors use the same ranges
RANGES: dict[str, tuple[float, float, bool]] = {
    "mrilc.rate": (1.0, 100000.0, False),
    "mrilc.nominal.omega": (1e-3, 1e6, False),
    "mrilc.nominal.zeta": (0.0, 0.999, False),
    "mrilc.check.min_frequency_hz": (1e-4, 1e5, False),
    "mrilc.gamma": (0.0, 1e9, False),
    "mrilc.lambda": (0.0, 1e9, False),
    "mrilc.robust_gain": (0.0, 1.0, False),
    "mrilc.q_cutoff_hz": (0.0, 1e6, False),
    "mrilc.q_order": (1, 8, True),
    "mrilc.patience": (1, 1000, True),
    "mrilc.noise_floor": (0.0, 1e9, False),
}


@dataclass(frozen=True)
class MrilcSettings:
    """The learner's settings besides the model (see :data:`DEFAULTS`)."""

    patience: int
    noise_floor: float
    learn: bool
    joint_names: tuple[str, ...]      # () = those of the first START
    injection_target: str
    shaper_family: str
    topics: dict[str, str]            # joint_states, reference, cycle_events


def _number(name: str, value) -> float:
    low, high, integer = RANGES[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise MrilcError(f"parameter {name} must be a finite number, got {value!r}")
    if integer and float(value) != int(value):
        raise MrilcError(f"parameter {name} must be an integer, got {value!r}")
    if not low <= value <= high:
        raise MrilcError(f"parameter {name} must be in [{low:g}, {high:g}], got {value!r}")
    return int(value) if integer else float(value)


def _numbers(name: str, value) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise MrilcError(f"parameter {name} must be a list of numbers, got {value!r}")
    out = tuple(value)
    if not out or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v))
                      for v in out):
        raise MrilcError(f"parameter {name} must be a non-empty list of finite numbers, got {list(out)!r}")
    return tuple(float(v) for v in out)


def _text(name: str, value) -> str:
    if not isinstance(value, str):
        raise MrilcError(f"parameter {name} must be a string, got {value!r}")
    return value


def model_from_params(params: Mapping[str, object] | None = None, require_convergence: bool = True
                      ) -> tuple[MrilcModel, MrilcSettings]:
    """The MRILC model and settings from the learner node's parameters (:data:`DEFAULTS` for
    those not given; keys not starting with ``mrilc.``, ``topics.`` or ``joint_names`` are ignored,
    so a mixed parameter set can be passed).

    Raises
    ------
    MrilcError
        An unknown ``mrilc.*`` name, a value of the wrong type or out of range, a model that cannot
        be built (unstable reference model, Q cut-off above Nyquist, ...), or, with
        ``require_convergence``, a learning law that fails seed 000's check (naming the worst
        plant and frequency).
    """
    given = dict(params or {})
    unknown = sorted(k for k in given if k.startswith("mrilc.") and k not in DEFAULTS)
    if unknown:
        raise MrilcError(f"unknown MRILC parameter(s) {', '.join(unknown)} (known: "
                         f"{', '.join(k for k in DEFAULTS if k.startswith('mrilc.'))})")
    p = {k: given.get(k, v) for k, v in DEFAULTS.items()}
    num = {k: _number(k, p[k]) for k in RANGES}
    law_name = _text("mrilc.law", p["mrilc.law"])
    if law_name not in M.LAWS:
        raise MrilcError(f"parameter mrilc.law must be one of {', '.join(M.LAWS)}, got {law_name!r}")
    injection = _text("mrilc.injection", p["mrilc.injection"])
    if injection not in M.INJECTIONS:
        raise MrilcError(f"parameter mrilc.injection must be one of {', '.join(M.INJECTIONS)}, got {injection!r}")
    if not isinstance(p["mrilc.learn"], bool):
        raise MrilcError(f"parameter mrilc.learn must be true or false, got {p['mrilc.learn']!r}")
    names = p["joint_names"]
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise MrilcError(f"parameter joint_names must be a list of strings, got {names!r}")
    law = M.LawConfig(law=law_name, gamma=num["mrilc.gamma"], lam=num["mrilc.lambda"], gain=num["mrilc.robust_gain"],
                      q_cutoff_hz=num["mrilc.q_cutoff_hz"], q_order=num["mrilc.q_order"])
    plant_set = M.paper_plant_set(_numbers("mrilc.check.omegas", p["mrilc.check.omegas"]),
                                  _numbers("mrilc.check.zetas", p["mrilc.check.zetas"]))
    model = MrilcModel(
        M.controller(_numbers("mrilc.controller.numerator", p["mrilc.controller.numerator"]),
                     _numbers("mrilc.controller.denominator", p["mrilc.controller.denominator"])),
        M.mck_plant(num["mrilc.nominal.omega"], num["mrilc.nominal.zeta"]), plant_set, 1.0 / num["mrilc.rate"],
        injection, law, omega_min=2 * math.pi * num["mrilc.check.min_frequency_hz"])
    if require_convergence:
        model.require_convergence()
    settings = MrilcSettings(num["mrilc.patience"], num["mrilc.noise_floor"], p["mrilc.learn"],
                             tuple(n for n in names if n), _text("mrilc.injection_target", p["mrilc.injection_target"]),
                             _text("mrilc.shaper_family", p["mrilc.shaper_family"]),
                             {k: _text(f"topics.{k}", p[f"topics.{k}"])
                              for k in ("joint_states", "reference", "cycle_events")})
    return model, settings
