"""What the learner records of a cycle: the update it reports, its trials and steps.

:class:`ListUpdate` is the outcome of one cycle as the learner reports it (the action, one of
:data:`ACTIONS`, and why). A :class:`Trial` is one measured shaped cycle as the learner ranks
it: the estimate r of the residual factor R (for ``zvd3`` the square root of rho nearest the
LTI prediction, continued from the previous trial), the signed errors of T2 (Im r) and A1
(Re r), and its score (M for the paper rule, the coherent M_c = M_ref |rho| for the components
rule). A :class:`Step` is a proposed move of one parameter. :func:`m_search` is the
one-dimensional minimisation of M the learner falls back on where phi's relation fails
(strongly nonlinear or saturating plants).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from typing import Any

from shaper_nodes.core.checks import finite

from .measure import Measurement, Reference
from .params import ListConfig, ListError, ListParams, lti_factor

#: the actions a ListUpdate reports
ACTIONS = ("reference", "first_step", "secant", "weighted", "search", "switch", "rollback", "rejected", "hold")
#: a residual with |rho| below this many standard errors is at the noise floor: nothing to learn
NOISE_SIGMAS = 3.0
#: relative tolerance when comparing the parameters a cycle ran with to those proposed
SAME_PARAMS_TOL = 1e-9

_TRIAL_KEYS = {"a1", "t2", "m", "rho", "r", "e_t2", "e_a1", "score", "floor"}


@dataclass(frozen=True)
class ListUpdate:
    """The outcome of one cycle.

    Attributes
    ----------
    iteration : int
        Cycles seen by the learner, this one included (rejected ones too).
    m : float
        M of the cycle (for the reference: its M over the learning window); NaN if rejected.
    phi : float
        phi of the cycle, rad (0 for the reference; NaN if rejected).
    used : ListParams or None
        The parameters the cycle ran with (None: unshaped).
    next : ListParams or None
        The parameters to apply next (None only before any initial guess).
    parameter : str
        The parameter being varied, ``t2`` or ``a1``; ``none`` for reference, hold and
        rejected cycles, and for a rollback the phase that restarts.
    action : str
        One of :data:`ACTIONS`.
    reason : str
        Why, in words (bounds and step limits that clipped the step are named).
    rho : complex
        The measured complex ratio (NaN if none).
    best_m : float
        The best M so far (NaN if none).
    """

    iteration: int
    m: float
    phi: float
    used: ListParams | None
    next: ListParams | None
    parameter: str
    action: str
    reason: str
    rho: complex = complex(math.nan, math.nan)
    best_m: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (NaN as None)."""
        f = _json_float
        return {"iteration": self.iteration, "m": f(self.m), "phi": f(self.phi),
                "used": None if self.used is None else self.used.as_dict(),
                "next": None if self.next is None else self.next.as_dict(),
                "parameter": self.parameter, "action": self.action, "reason": self.reason,
                "rho": [f(self.rho.real), f(self.rho.imag)], "best_m": f(self.best_m)}


@dataclass(frozen=True)
class Trial:
    """One measured shaped cycle: parameters, M, rho, the R estimate r, the signed errors, and
    the score that ranks trials (M for the paper rule, the coherent M_c = M_ref |rho| for the
    components rule)."""

    params: ListParams
    m: float
    rho: complex
    r: complex
    e_t2: float
    e_a1: float
    score: float
    floor: bool = False  # |rho| below NOISE_SIGMAS standard errors: the residual is noise

    def p(self, name: str) -> float:
        return self.params.t2 if name == "t2" else self.params.a1

    def e(self, name: str) -> float:
        return self.e_t2 if name == "t2" else self.e_a1

    def as_dict(self) -> dict[str, Any]:
        return {"a1": self.params.a1, "t2": self.params.t2, "m": self.m, "rho": [self.rho.real, self.rho.imag],
                "r": [self.r.real, self.r.imag], "e_t2": self.e_t2, "e_a1": self.e_a1, "score": self.score,
                "floor": self.floor}

    @classmethod
    def from_dict(cls, d: Any) -> Trial:
        if not isinstance(d, dict) or set(d) != _TRIAL_KEYS:
            raise ListError(f"trial must be a dictionary with keys {sorted(_TRIAL_KEYS)}")
        m, score = finite("trial m", d["m"], ListError), finite("trial score", d["score"], ListError)
        if m < 0.0 or score < 0.0:
            raise ListError("trial m and score must be >= 0")
        if not isinstance(d["floor"], bool):
            raise ListError("trial floor must be true or false")
        return cls(params_from_dict({"a1": d["a1"], "t2": d["t2"]}), m, _complex("rho", d["rho"]),
                   _complex("r", d["r"]), finite("e_t2", d["e_t2"], ListError),
                   finite("e_a1", d["e_a1"], ListError), score, d["floor"])


def optional_trial_dict(trial: Trial | None) -> dict[str, Any] | None:
    """:meth:`Trial.as_dict`, None for None."""
    return None if trial is None else trial.as_dict()


@dataclass(frozen=True)
class Step:
    """A proposed step: the parameters, the relative step taken and wanted (before the maximum
    step), whether the maximum step limited it, and a note for the reason."""

    name: str
    params: ListParams
    rel: float
    wanted: float
    limited: bool
    note: str


def make_trial(used: ListParams, meas: Measurement, ref: Reference, last: Trial | None, config: ListConfig) -> Trial:
    """The trial of a cycle that ran with ``used`` and measured ``meas`` against ``ref``.

    For ``zvd3`` (rho ~ R^2), r is the square root of rho nearest the LTI prediction of R,
    continued from the ``last`` trial when there is one."""
    n = config.power
    if n == 1:
        r = meas.rho
    else:
        pred = _lti(used, ref) if last is None else last.r + _lti(used, ref) - _lti(last.params, ref)
        s = cmath.sqrt(meas.rho)
        r = s if abs(s - pred) <= abs(s + pred) else -s
    if config.rule == "components":
        e_t2, e_a1, score = r.imag, r.real, meas.m_ref * abs(meas.rho)
    else:
        ratio = meas.m / meas.m_ref
        mag = ratio if n == 1 else math.sqrt(ratio)
        e_t2, e_a1, score = math.copysign(mag, r.imag), math.copysign(mag, r.real), meas.m
    floor = abs(meas.rho) < NOISE_SIGMAS * meas.rho_se
    return Trial(used, meas.m, meas.rho, r, e_t2, e_a1, score, floor)


def _lti(params: ListParams, ref: Reference) -> complex:
    return lti_factor(params, ref.sigma, ref.omega_d)


def m_search(name: str, trials: list[Trial], switch_tol: float) -> tuple[float, Trial, str] | None:
    """The next point of a one-dimensional minimisation of M over the phase's trials (of the
    parameter ``name``), the trial it starts from and how it was found; None when the minimum
    is bracketed within ``switch_tol``.

    Used when phi's model fails (M rose against its prediction, or the error fell as the
    parameter rose). Bracketed (the trial with the least M has trials on both sides): the
    vertex of the parabola through it and its neighbours in M^2 (for an LTI mode M^2 is exactly
    quadratic in each parameter, a constant noise floor included); otherwise a step as long as
    the last one, beyond the least M, away from its neighbour."""
    by_p: dict[float, Trial] = {}
    for tr in trials:  # the latest measurement of a point counts
        by_p[tr.p(name)] = tr
    pts = [by_p[k] for k in sorted(by_p)]
    i = min(range(len(pts)), key=lambda k: pts[k].m)
    b = pts[i]
    pb = b.p(name)
    if len(pts) < 2:
        return None
    if 0 < i < len(pts) - 1:
        lo, hi = pts[i - 1], pts[i + 1]
        pl, ph = lo.p(name), hi.p(name)
        if ph - pl < 2.0 * switch_tol * abs(pb):
            return None
        ml, mb, mh = lo.m**2, b.m**2, hi.m**2
        den = (pl - pb) * (pl - ph) * (pb - ph)
        a = (ph * (mb - ml) + pb * (ml - mh) + pl * (mh - mb)) / den
        bb = (ph**2 * (ml - mb) + pb**2 * (mh - ml) + pl**2 * (mb - mh)) / den
        far = ph if ph - pb >= pb - pl else pl
        x = -bb / (2.0 * a) if a > 0.0 else math.nan
        if not (math.isfinite(x) and pl < x < ph) or abs(x - pb) < 0.05 * min(pb - pl, ph - pb):
            x, how = pb + 0.382 * (far - pb), "golden step into the wider side of the bracket"
        else:
            how = "vertex of the parabola through the bracket in M^2"
        return x, b, how
    nb = pts[1] if i == 0 else pts[-2]
    return pb + (pb - nb.p(name)), b, "step beyond the least M, away from its neighbour"


# ---------------------------------------------------------------------------------------------
# Small helpers on parameters and their dictionaries
# ---------------------------------------------------------------------------------------------


def two_numbers(name: str, v: Any) -> list[Any]:
    """``v`` if it is a list of two items, else :class:`ListError` (the items are checked by the caller)."""
    if not isinstance(v, list) or len(v) != 2:
        raise ListError(f"{name} must be a list of two numbers")
    return v


def _json_float(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _complex(name: str, v: Any) -> complex:
    re, im = (finite(name, x, ListError) for x in two_numbers(name, v))
    return complex(re, im)


def params_from_dict(d: Any) -> ListParams:
    """The checked parameters of :meth:`ListParams.as_dict`."""
    if not isinstance(d, dict) or set(d) != {"a1", "t2"}:
        raise ListError("parameters must be a dictionary with keys a1, t2")
    return ListParams(finite("a1", d["a1"], ListError), finite("t2", d["t2"], ListError)).check()


def other_param(name: str) -> str:
    """The other learned parameter: ``a1`` for ``t2`` and the reverse."""
    return "a1" if name == "t2" else "t2"


def same_params(p: ListParams, q: ListParams) -> bool:
    """Whether ``p`` equals ``q`` within :data:`SAME_PARAMS_TOL` (relative)."""
    return (abs(p.a1 - q.a1) <= SAME_PARAMS_TOL * abs(q.a1)
            and abs(p.t2 - q.t2) <= SAME_PARAMS_TOL * abs(q.t2))


def fmt_params(p: ListParams | None) -> str:
    """``A1 ..., T2 ... s`` (or ``none``) for messages."""
    return "none" if p is None else f"A1 {p.a1:.6g}, T2 {p.t2:.6g} s"
