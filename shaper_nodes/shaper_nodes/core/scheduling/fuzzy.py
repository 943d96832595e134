"""Takagi-Sugeno fuzzy interpolation of linear models, and the modes of the result (seed 004).

A rule base holds rules of the form

    if z_1 is A_1^j and ... and z_p is A_p^l  then  x' = A_i x + B_i u,

one per operating point (seed 004, section 4.1). For the premise values z (joint positions,
payload, ...) each rule fires with the product of its membership grades, and the weights are
normalised to sum to 1 (seed 004, the fuzzy system's output formula):

    w_i(z) = mu_i(z) / sum_k mu_k(z),   A(z) = sum_i w_i(z) A_i,   B(z) = sum_i w_i(z) B_i.

The modes of the interpolated model are the complex eigenvalue pairs lambda of A(z):
omega_n = |lambda| (rad/s), zeta = -Re(lambda) / |lambda|; "lightly damped" means zeta below a
threshold (real poles and rigid-body poles are not modes to shape for).

The simpler alternative interpolates the mode parameters themselves,
omega(z) = sum_i w_i(z) omega_i and zeta(z) = sum_i w_i(z) zeta_i (rules then carry modes
instead of, or besides, their models); docs/design/scheduler.md compares the two.

Premises outside the rule base's range are clamped to it (never extrapolated) and reported in
the result. A premise value in range where no rule fires is an error that names the value.

Membership functions (from their formulas, as in Passino & Yurkovich, "Fuzzy Control")
---------------------------------------------------------------------------------------
triangular (a, b, c)
    0 outside (a, c), rising linearly to 1 at b, falling linearly to 0 at c. a == b or b == c
    gives a shoulder (1 from the vertical edge on).
trapezoidal (a, b, c, d)
    0 outside (a, d), 1 on [b, c], linear in between. a == b or c == d give vertical edges, so a
    trapezoid can be a crisp set (seed 004 eq. (9) as a rule base).
gaussian (mean, sigma)
    exp(-(z - mean)^2 / (2 sigma^2)).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.checks import finite_values
from shaper_nodes.core.shaping.types import MAX_DAMPING, Mode

#: default largest damping ratio of a "lightly damped" mode
LIGHT_DAMPING = 0.3


class FuzzyError(ValueError):
    """An invalid rule base, membership function or premise value; the message names it."""


@dataclass(frozen=True)
class Triangular:
    """Triangular membership, 0 outside (a, c), 1 at b (a <= b <= c, a < c)."""

    a: float
    b: float
    c: float

    def __post_init__(self) -> None:
        finite_values("triangular parameters", (self.a, self.b, self.c), FuzzyError)
        if not (self.a <= self.b <= self.c and self.a < self.c):
            raise FuzzyError(f"triangular needs a <= b <= c and a < c, got ({self.a}, {self.b}, {self.c})")

    def __call__(self, z: float) -> float:
        if z < self.a or z > self.c:
            return 0.0
        if z <= self.b:
            return 1.0 if self.b == self.a else (z - self.a) / (self.b - self.a)
        return 1.0 if self.c == self.b else (self.c - z) / (self.c - self.b)

    @property
    def peak(self) -> tuple[float, float]:
        """Where the grade is 1 (an interval)."""
        return self.b, self.b

    def slope(self, lo: float, hi: float) -> float:
        """Largest |d grade / dz| for z in [lo, hi], 1/unit (inf: a vertical edge lies inside)."""
        if (self.a == self.b and lo < self.a <= hi) or (self.b == self.c and lo <= self.c < hi):
            return math.inf
        return max(1.0 / (self.b - self.a) if self.b > self.a else 0.0,
                   1.0 / (self.c - self.b) if self.c > self.b else 0.0)


@dataclass(frozen=True)
class Trapezoidal:
    """Trapezoidal membership, 0 outside (a, d), 1 on [b, c] (a <= b <= c <= d)."""

    a: float
    b: float
    c: float
    d: float

    def __post_init__(self) -> None:
        finite_values("trapezoidal parameters", (self.a, self.b, self.c, self.d), FuzzyError)
        if not (self.a <= self.b <= self.c <= self.d):
            raise FuzzyError(f"trapezoidal needs a <= b <= c <= d, got ({self.a}, {self.b}, {self.c}, {self.d})")

    def __call__(self, z: float) -> float:
        if z < self.a or z > self.d:
            return 0.0
        if z < self.b:
            return (z - self.a) / (self.b - self.a)
        if z <= self.c:
            return 1.0
        return (self.d - z) / (self.d - self.c)

    @property
    def peak(self) -> tuple[float, float]:
        return self.b, self.c

    def slope(self, lo: float, hi: float) -> float:
        """Largest |d grade / dz| for z in [lo, hi], 1/unit (inf: a vertical edge lies inside)."""
        if (self.a == self.b and lo < self.a <= hi) or (self.c == self.d and lo <= self.d < hi):
            return math.inf
        return max(1.0 / (self.b - self.a) if self.b > self.a else 0.0,
                   1.0 / (self.d - self.c) if self.d > self.c else 0.0)


@dataclass(frozen=True)
class Gaussian:
    """Gaussian membership exp(-(z - mean)^2 / (2 sigma^2)), sigma > 0."""

    mean: float
    sigma: float

    def __post_init__(self) -> None:
        finite_values("gaussian parameters", (self.mean, self.sigma), FuzzyError)
        if not self.sigma > 0:
            raise FuzzyError(f"gaussian needs sigma > 0, got {self.sigma}")

    def __call__(self, z: float) -> float:
        return math.exp(-0.5 * ((z - self.mean) / self.sigma) ** 2)

    @property
    def peak(self) -> tuple[float, float]:
        return self.mean, self.mean

    def slope(self, lo: float, hi: float) -> float:
        """Largest |d grade / dz| anywhere, 1/unit: 1 / (sigma sqrt(e)), at mean +- sigma."""
        return 1.0 / (self.sigma * math.sqrt(math.e))


Membership = Triangular | Trapezoidal | Gaussian
#: the membership functions by name: the class and its number of parameters
MEMBERSHIPS: dict[str, tuple[Callable[..., Membership], int]] = {
    "triangular": (Triangular, 3), "trapezoidal": (Trapezoidal, 4), "gaussian": (Gaussian, 2)}


def membership(kind: str, params: Sequence[float] | npt.NDArray[np.float64]) -> Membership:
    """A membership function by name ('triangular', 'trapezoidal', 'gaussian') and parameters."""
    key = str(kind).strip().lower()
    if key not in MEMBERSHIPS:
        raise FuzzyError(f"unknown membership function {kind!r}; use one of {', '.join(MEMBERSHIPS)}")
    cls, n = MEMBERSHIPS[key]
    p = finite_values(f"{key} parameters", params, FuzzyError)
    if p.size != n:
        raise FuzzyError(f"{key} needs {n} parameters, got {p.size}")
    return cls(*p.tolist())


def modes_of(a: np.ndarray, max_damping: float = LIGHT_DAMPING) -> list[Mode]:
    """The lightly damped modes of x' = A x: one per complex pair with zeta < max_damping,
    lowest natural frequency first (rad/s, dimensionless)."""
    ev = np.linalg.eigvals(np.asarray(a, dtype=float))
    out = []
    for lam in ev[ev.imag > 1e-12 * max(1.0, float(np.max(np.abs(ev))))]:
        omega = float(abs(lam))
        zeta = float(-lam.real / omega)
        if 0.0 <= zeta < min(max_damping, MAX_DAMPING):
            out.append(Mode(omega, zeta))
    return sorted(out, key=lambda m: m.omega)


@dataclass(frozen=True)
class Rule:
    """One operating point: a membership function per premise and its linear model and/or modes.

    ``a`` (n x n) and ``b`` (n x m) are the model x' = A x + B u; ``modes`` the operating point's
    mode parameters, for direct interpolation (computed from ``a`` when not given).
    """

    memberships: tuple[Membership, ...]
    a: np.ndarray | None = None
    b: np.ndarray | None = None
    modes: tuple[Mode, ...] = ()
    name: str = ""

    def grade(self, z: np.ndarray) -> float:
        """Firing strength: the product of the membership grades (product t-norm)."""
        g = 1.0
        for mf, zi in zip(self.memberships, z, strict=True):
            g *= mf(float(zi))
        return g


@dataclass(frozen=True)
class Interpolation:
    """The result of evaluating a rule base at one premise vector."""

    z: np.ndarray                 # premise values used (after clamping)
    z_in: np.ndarray              # premise values given
    clamped: tuple[bool, ...]     # which premises were outside the range and clamped
    weights: np.ndarray           # normalised rule weights, sum 1
    a: np.ndarray | None          # interpolated A (None when the rules have no models)
    b: np.ndarray | None
    modes: tuple[Mode, ...]       # lightly damped modes (model interpolation) or interpolated modes

    @property
    def dominant(self) -> int:
        """Index of the rule with the largest weight (the operating region)."""
        return int(np.argmax(self.weights))


def _shape(matrix: np.ndarray | None) -> tuple[int, ...] | None:
    return None if matrix is None else matrix.shape


@dataclass
class RuleBase:
    """Rules over ``premises`` (names) with a closed range [lo, hi] per premise.

    Parameters
    ----------
    premises : sequence of str
        Names of the premise variables (for the scheduler node: joint names), p of them.
    rules : sequence of Rule
        Each with p membership functions; all with models of the same sizes, or all with the
        same number of modes, or both.
    ranges : sequence of (lo, hi), optional
        Where the rule base is valid; by default from the lowest to the highest peak of the
        membership functions of each premise.
    max_damping : float
        Modes of the interpolated model with zeta at or above this are not reported.
    """

    premises: tuple[str, ...]
    rules: tuple[Rule, ...]
    ranges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    max_damping: float = LIGHT_DAMPING

    def __post_init__(self) -> None:
        self.premises = tuple(str(p) for p in self.premises)
        self.rules = tuple(self.rules)
        p = len(self.premises)
        if p == 0 or len(set(self.premises)) != p:
            raise FuzzyError(f"premises must be distinct names, at least one; got {list(self.premises)}")
        if not self.rules:
            raise FuzzyError("a rule base needs at least one rule")
        for i, r in enumerate(self.rules):
            if len(r.memberships) != p:
                raise FuzzyError(f"rule {r.name or i} has {len(r.memberships)} membership functions for {p} premises")
        with_model = [r.a is not None for r in self.rules]
        if any(with_model) and not all(with_model):
            raise FuzzyError("either every rule has a model (A, B) or none has")
        if all(with_model):
            a0, b0 = self.rules[0].a, self.rules[0].b
            for r in self.rules:
                if _shape(r.a) != _shape(a0) or r.b is None or _shape(r.b) != _shape(b0):
                    raise FuzzyError(f"rule {r.name}: A and B must have the sizes of the first rule's "
                                     f"{_shape(a0)} and {_shape(b0)}")
        counts = {len(r.modes) for r in self.rules}
        if not all(with_model) and (len(counts) != 1 or 0 in counts):
            raise FuzzyError("rules without models need the same number (>= 1) of modes each")
        if not (0.0 < self.max_damping <= 1.0):
            raise FuzzyError(f"max_damping must be in (0, 1], got {self.max_damping}")
        rng = np.asarray(self.ranges, dtype=float)
        if rng.size == 0:
            rng = np.array([[min(r.memberships[j].peak[0] for r in self.rules),
                             max(r.memberships[j].peak[1] for r in self.rules)] for j in range(p)])
        rng = rng.reshape(-1, 2)
        if rng.shape[0] != p or not np.all(np.isfinite(rng)) or np.any(rng[:, 0] > rng[:, 1]):
            raise FuzzyError(f"ranges must be one finite [lo, hi] with lo <= hi per premise, got {rng.tolist()}")
        self.ranges = rng

    @property
    def has_models(self) -> bool:
        return self.rules[0].a is not None

    def clamp(self, z: Sequence[float]) -> tuple[np.ndarray, np.ndarray, tuple[bool, ...]]:
        """(z given, z clamped to the ranges, which were clamped); raises on bad size or non-finite."""
        zin = np.asarray(z, dtype=float).ravel()
        if zin.size != len(self.premises):
            raise FuzzyError(f"{len(self.premises)} premise values needed ({', '.join(self.premises)}), got {zin.size}")
        if not np.all(np.isfinite(zin)):
            raise FuzzyError(f"premise values must be finite, got {zin.tolist()}")
        zc = np.clip(zin, self.ranges[:, 0], self.ranges[:, 1])
        return zin, zc, tuple(bool(x) for x in zc != zin)

    def premise_tolerance(self, grade: float) -> np.ndarray:
        """Per premise, the largest change (rad or m, within the range) that moves no membership grade
        by more than ``grade``: ``grade`` over the steepest slope of that premise's membership
        functions over the range (0 where a vertical edge lies inside the range)."""
        out = np.empty(len(self.premises))
        for j, (lo, hi) in enumerate(self.ranges):
            steepest = max(r.memberships[j].slope(float(lo), float(hi)) for r in self.rules)
            out[j] = grade / steepest if steepest > 0 else math.inf
        return out

    def weights(self, z: Sequence[float]) -> np.ndarray:
        """Normalised weights at z (clamped to the ranges first)."""
        return self._weights(self.clamp(z)[1])

    def _weights(self, zc: np.ndarray) -> np.ndarray:
        mu = np.array([r.grade(zc) for r in self.rules])
        total = float(mu.sum())
        if not total > 0.0:
            where = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.premises, zc, strict=True))
            raise FuzzyError(f"no rule fires at {where}: the membership functions leave a gap there")
        return mu / total

    def evaluate(self, z: Sequence[float], method: str = "model") -> Interpolation:
        """Interpolate at z: the model and its lightly damped modes (``"model"``), or the modes
        directly (``"modes"``)."""
        zin, zc, clamped = self.clamp(z)
        w = self._weights(zc)
        a = b = None
        if self.has_models:
            # every rule has both (checked at construction)
            a = np.tensordot(w, np.stack([r.a for r in self.rules if r.a is not None]), axes=1)
            b = np.tensordot(w, np.stack([r.b for r in self.rules if r.b is not None]), axes=1)
        if method == "model":
            if a is None:
                raise FuzzyError("method 'model' needs rules with models (A, B)")
            modes = tuple(modes_of(a, self.max_damping))
        elif method == "modes":
            modes = self.interpolate_modes(w)
        else:
            raise FuzzyError(f"method must be 'model' or 'modes', got {method!r}")
        return Interpolation(zc, zin, clamped, w, a, b, modes)

    def rule_modes(self, i: int) -> tuple[Mode, ...]:
        """Mode parameters of rule i: as given, else from its model."""
        r = self.rules[i]
        if r.modes or r.a is None:  # a rule without a model has modes (checked at construction)
            return r.modes
        return tuple(modes_of(r.a, self.max_damping))

    def interpolate_modes(self, w: np.ndarray) -> tuple[Mode, ...]:
        """Weighted mean of the rules' mode parameters (k-th mode with k-th mode)."""
        per_rule = [self.rule_modes(i) for i in range(len(self.rules))]
        n = min(len(m) for m in per_rule)
        if n == 0:
            raise FuzzyError("a rule has no lightly damped mode to interpolate")
        return tuple(Mode(float(sum(wi * m[k].omega for wi, m in zip(w, per_rule, strict=True))),
                          float(sum(wi * m[k].zeta for wi, m in zip(w, per_rule, strict=True)))) for k in range(n))


#: largest magnitude of a local model's A or B entry: a mechanical mode's A holds omega^2 and 2 zeta omega,
#: so 1e12 admits modes up to 1.6e5 Hz; beyond it a value is a typo or an attack, and the weighted
#: sums of the interpolation would overflow to inf long before 1e308
MAX_MATRIX_ENTRY = 1e12


def _matrix(name: str, what: str, values: Any) -> np.ndarray:
    v = finite_values(f"rule {name} {what}", values, FuzzyError)
    if v.size and float(np.max(np.abs(v))) > MAX_MATRIX_ENTRY:
        k = int(np.argmax(np.abs(v)))
        raise FuzzyError(f"rule {name}: {what}[{k}] = {v[k]:g} is beyond +-{MAX_MATRIX_ENTRY:g} (no physical"
                         " model has such an entry; natural frequencies would be above 1.6e5 Hz)")
    return v


def rule_base_from_dict(spec: Mapping[str, Any]) -> RuleBase:
    """A rule base from a plain mapping (a YAML file, or the scheduler node's parameters).

    ``spec`` holds ``premises`` (list of names), optional ``range`` (flat [lo1, hi1, lo2, hi2...]),
    optional ``max_damping``, and ``rules``: a mapping name -> {``membership``: list of kinds,
    one per premise; ``membership_params``: the parameters of all of them, concatenated;
    ``a_matrix``: n*n values row-major and ``b_matrix``: n*m values (optional; every entry finite and
    within :data:`MAX_MATRIX_ENTRY`); or/and ``frequency_hz`` (Hz; the node's parameters and scheduler.yaml)
    or ``natural_frequency`` (rad/s; the core's own specs) and ``damping_ratio`` lists, one per mode}.
    """
    premises = list(spec.get("premises") or [])
    rules = []
    for name, r in dict(spec.get("rules") or {}).items():
        kinds = [str(k) for k in r.get("membership") or []]
        params = finite_values(f"rule {name} membership_params", r.get("membership_params") or [], FuzzyError)
        mfs, pos = [], 0
        for kind in kinds:
            n = MEMBERSHIPS.get(kind.strip().lower(), (None, 0))[1]
            try:
                mfs.append(membership(kind, params[pos:pos + n]))
            except FuzzyError as err:
                raise FuzzyError(f"rule {name}: {err}") from None
            pos += n
        if pos != params.size:
            raise FuzzyError(f"rule {name}: membership_params has {params.size} values, its functions take {pos}")
        a = b = None
        if len(r.get("a_matrix") or []):
            av = _matrix(name, "a_matrix", r["a_matrix"])
            n = int(round(math.sqrt(av.size)))
            if n * n != av.size:
                raise FuzzyError(f"rule {name}: a_matrix needs n*n values, got {av.size}")
            bv = _matrix(name, "b_matrix", r.get("b_matrix") or [])
            if bv.size == 0 or bv.size % n:
                raise FuzzyError(f"rule {name}: b_matrix needs n*m values (n = {n}), got {bv.size}")
            a, b = av.reshape(n, n), bv.reshape(n, -1)
        if len(r.get("frequency_hz") or []) and len(r.get("natural_frequency") or []):
            raise FuzzyError(f"rule {name}: give frequency_hz (Hz) or natural_frequency (rad/s), not both")
        if len(r.get("frequency_hz") or []):
            freqs = 2 * math.pi * finite_values(f"rule {name} frequency_hz", r["frequency_hz"], FuzzyError)
        else:
            freqs = finite_values(f"rule {name} natural_frequency", r.get("natural_frequency") or [], FuzzyError)
        zetas = finite_values(f"rule {name} damping_ratio", r.get("damping_ratio") or [], FuzzyError)
        if freqs.size != zetas.size:
            raise FuzzyError(f"rule {name}: {freqs.size} natural frequencies but {zetas.size} damping ratios")
        try:
            modes = tuple(Mode(float(f), float(z)) for f, z in zip(freqs, zetas, strict=True))
        except ValueError as err:
            raise FuzzyError(f"rule {name}: {err}") from None
        rules.append(Rule(tuple(mfs), a, b, modes, str(name)))
    rng = spec.get("range")
    kwargs = {"max_damping": float(spec["max_damping"])} if "max_damping" in spec else {}
    return RuleBase(tuple(premises), tuple(rules), np.asarray(rng if rng is not None and len(rng) else [], float),
                    **kwargs)


def triangular_partition(points: Sequence[float]) -> list[Triangular]:
    """Triangles peaking at each of the increasing ``points``, each reaching 0 at its neighbours'
    peaks (shoulders at the ends): grades sum to 1 everywhere between the first and last point."""
    p = finite_values("points", points, FuzzyError)
    if p.size < 1 or np.any(np.diff(p) <= 0):
        raise FuzzyError(f"points must increase strictly, got {p.tolist()}")
    if p.size == 1:
        return [Triangular(p[0] - 1.0, p[0], p[0] + 1.0)]
    out = []
    for i, x in enumerate(p):
        lo = p[i - 1] if i > 0 else x
        hi = p[i + 1] if i + 1 < p.size else x
        out.append(Triangular(float(lo), float(x), float(hi)))
    return out
