"""The pooled-pole rule per move: a factor on the position loop's pole found in pooled reference windows, and its
trial judged at that pole.

Over a schedule with accelerometer noise one reference window's components (:func:`.payback.components`) often give
nothing to put a factor on. The rule (the reproduction's ``scheduled_list_factor``, ``reproductions.arm_learning``,
and the learner node's payback mode, ``nodes/learner_payback.py``, use this one copy):

- a move with no factor kept whose reference finds no factor predicted to pay runs its reference again, up to
  :data:`POOL_CYCLES` cycles; the windows, aligned at the commanded end, are pooled (:class:`.loop_pole.Pool`);
- :func:`pole_pick`: in the pooled mean the modes that ring are identified, the loop's pole searched beside them
  (:func:`.loop_pole.loop_pole`), and :func:`.payback.paying_factor` chooses a factor on it by the one-sample time
  rule; the pole's amplitude with the poles fixed (:func:`.loop_pole.fixed_pole_fit`) is the reference's;
- :func:`judge_pole`: the trial's windows pooled the same way, its response at the same poles measured; kept when
  lower by :data:`.loop_pole.LOWER` standard errors of the change (:func:`.loop_pole.change_at_pole`: the
  pole's cosine and sine coefficients on every axis, whitened; with a reference saved before session 13, its
  amplitude alone: :func:`.loop_pole.lower_at_pole`), tried again when lower but not by that much (up to
  :data:`POOL_CYCLES` windows), withdrawn otherwise.

:class:`PoleState` is one move's state between cycles (the node saves it): the pool (the references' while they are
pooled, the trial's while it is judged: one at a time, a running sum, so its size does not grow with the count), the
poles and the reference's amplitude and response the trial is judged at, and whether the move's references are pooled
from the start (its factor from one window did not pay).

ROS-free.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .loop_pole import LOWER, Pool, change_at_pole, fixed_pole_fit, loop_pole, lower_at_pole
from .params import ListError, ListParams
from .payback import Component, PaybackChoice, components, paying_factor

__all__ = ["POOL_CYCLES", "PolePick", "PoleState", "judge_pole", "pole_pick"]

#: most reference cycles pooled before a move gives up on the loop's pole, and most trial windows pooled to judge it.
#: 5 since session 13 (3 before): over DDS home->rotated's servo part (0.0014 m/s^2, 8 % of the noise floor) shows
#: no pole in 3 windows and one in 5; a move whose pole shows earlier spends no more cycles
POOL_CYCLES = 5

#: a response at a pole: its cosine and sine coefficients per axis ((2, k), m/s^2) and their covariance per axis
Response = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class PolePick:
    """What :func:`pole_pick` found: the factor chosen (:class:`.payback.PaybackChoice`), the loop's component and
    the standard error of its amplitude (m/s^2), the poles a trial is judged at (the modes that ring, then the
    loop's), the reference's (amplitude, standard error) at the loop's pole (m/s^2, with those poles fixed), how
    many modes ring and the reference's response at the loop's pole (:attr:`.loop_pole.PoleFit.response`)."""

    choice: PaybackChoice
    loop: Component
    error: float
    poles: tuple[complex, ...]
    reference: tuple[float, float]
    ringing: int
    response: Response | None = None


def pole_pick(times: np.ndarray, signal: np.ndarray, cost: Callable[[ListParams], float], tolerance_s: float,
              servo_zeta: float, band: float) -> PolePick | None:
    """A factor on the loop's pole in a pooled reference (times from the commanded end, s; the mean signal, m/s^2):
    the modes that ring identified (damping below ``servo_zeta``), the loop's pole searched beside them, and
    :func:`.payback.paying_factor` on it alone (the factor is for it: in the 1 s RMS the modes that ring, left as
    they are, would hide what it takes off) with ``cost`` within ``tolerance_s`` s and T2 within ``band``. None if
    no pole stands above the noise or no factor on it is predicted to pay."""
    ringing = [x for x in components(times, signal, 0.0, servo_zeta) if x.zeta < servo_zeta]
    found = loop_pole(times, signal, 0.0, ringing)
    if found is None:
        return None
    loop, err = found
    pick = paying_factor([loop], cost, tolerance_s, band=band)
    if pick is None:
        return None
    poles = (*(x.pole for x in ringing), loop.pole)
    fit = fixed_pole_fit(times, signal, 0.0, poles)
    return PolePick(pick, loop, err, poles, (fit.amplitudes[-1], fit.errors[-1]), len(ringing), fit.response)


def judge_pole(times: np.ndarray, signal: np.ndarray, poles: tuple[complex, ...], reference: tuple[float, float],
               windows: int, in_time: bool = True, max_windows: int = POOL_CYCLES,
               response: Response | None = None) -> tuple[str, tuple[float, float], float]:
    """A trial judged at the loop's pole: its response there (least squares with ``poles`` fixed, on its
    ``windows`` windows pooled: times from the commanded end, s; the mean, m/s^2) against the pooled reference's
    ``response`` (:func:`.loop_pole.change_at_pole`; None, a reference saved before it: the (amplitude, standard
    error) ``reference``, :func:`.loop_pole.lower_at_pole`). ``"learn"`` (kept) when ``in_time`` (its move + settle
    within the time rule, where measured) and lower by :data:`.loop_pole.LOWER` standard errors of the change;
    ``"again"`` when in time, lower but not by that much and fewer than ``max_windows`` windows pooled; else
    ``"base"`` (withdrawn). Also returns the trial's (amplitude, error) and the change in standard errors (NaN on
    the amplitude's rule)."""
    fit = fixed_pole_fit(times, signal, 0.0, poles)
    trial = (fit.amplitudes[-1], fit.errors[-1])
    if response is not None and fit.response is not None:
        change = change_at_pole(response, fit.response)
        lower, resolved = change > 0.0, change > LOWER
    else:
        change, lower, resolved = math.nan, trial[0] < reference[0], lower_at_pole(reference, trial)
    paid = in_time and resolved
    again = in_time and not paid and lower and windows < max_windows
    return ("learn" if paid else "again" if again else "base"), trial, change


def _pair(value: Any, what: str) -> tuple[float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise ListError(f"{what} must be two finite numbers, got {value!r}")
    return float(value[0]), float(value[1])


@dataclass
class PoleState:
    """One move's pooled-pole state (module docstring): ``pool`` (the references' windows while pooled, the trial's
    while judged), ``poles`` and ``reference`` (set while a trial is judged at the loop's pole: the poles, 1/s, and
    the pooled reference's (amplitude, standard error), m/s^2), ``pooled_only`` (the move's factor from one window
    did not pay: its references are pooled from the first), ``response`` (while judged: the reference's response at
    the loop's pole, :attr:`.loop_pole.PoleFit.response`; None in a state saved before session 13)."""

    pool: Pool = field(default_factory=Pool)
    poles: tuple[complex, ...] | None = None
    reference: tuple[float, float] | None = None
    pooled_only: bool = False
    response: Response | None = None

    @property
    def judging(self) -> bool:
        """Whether the move's trial is judged at the loop's pole (chosen from pooled references)."""
        return self.poles is not None and self.reference is not None

    def chosen(self, pick: PolePick) -> None:
        """The factor chosen from the pooled references: its trial is judged at ``pick``'s poles; the references'
        pool gives way to the trial's."""
        self.poles, self.reference, self.pool = pick.poles, pick.reference, Pool(self.pool.length)
        self.response = pick.response

    def reset(self) -> None:
        """Nothing pooled or judged (the move's trial was judged, or it learns again)."""
        self.pool, self.poles, self.reference, self.response = Pool(self.pool.length), None, None, None

    def to_dict(self) -> dict[str, Any]:
        out = {"pool": self.pool.to_dict(),
               "poles": None if self.poles is None else [[p.real, p.imag] for p in self.poles],
               "reference": None if self.reference is None else list(self.reference),
               "pooled_only": self.pooled_only}
        if self.response is not None:  # the coefficients (2 x axes) and their covariance (2 x 2)
            out["response"] = {"coefficients": self.response[0].tolist(), "covariance": self.response[1].tolist()}
        return out

    @classmethod
    def from_dict(cls, d: Any) -> PoleState:
        """A state saved by :meth:`to_dict` (``response`` absent in one saved before session 13), checked
        (:class:`ListError` names the problem)."""
        keys = {"pool", "poles", "reference", "pooled_only"}
        if not isinstance(d, Mapping) or not keys <= set(d) <= keys | {"response"}:
            raise ListError(f"a pole state has the entries pool, poles, pooled_only and reference (and response),"
                            f" got {d!r:.200}")
        if not isinstance(d["pooled_only"], bool):
            raise ListError(f"pooled_only must be true or false, got {d['pooled_only']!r}")
        if (d["poles"] is None) != (d["reference"] is None):
            raise ListError("a pole state has both poles and reference, or neither")
        poles = None
        if d["poles"] is not None:
            if not isinstance(d["poles"], list) or not 1 <= len(d["poles"]) <= 8:
                raise ListError(f"poles must be a list of 1 to 8 [real, imaginary] pairs, got {d['poles']!r}")
            poles = tuple(complex(*_pair(p, "a pole")) for p in d["poles"])
        reference = None if d["reference"] is None else _pair(d["reference"], "the reference")
        if reference is not None and (reference[0] < 0 or reference[1] < 0):
            raise ListError(f"the reference's amplitude and error must be >= 0 m/s^2, got {reference!r}")
        return cls(Pool.from_dict(d["pool"]), poles, reference, d["pooled_only"], _response(d.get("response")))


def _response(value: Any) -> Response | None:
    """A saved response at a pole (:meth:`PoleState.to_dict`), checked; None if none."""
    if value is None:
        return None
    if not isinstance(value, Mapping) or set(value) != {"coefficients", "covariance"}:
        raise ListError(f"a response has the entries coefficients and covariance, got {value!r:.200}")
    try:
        coef = np.asarray(value["coefficients"], dtype=float)
        cov = np.asarray(value["covariance"], dtype=float)
    except (TypeError, ValueError) as err:
        raise ListError(f"a response's coefficients and covariance must be numbers: {err}") from None
    if coef.ndim != 2 or coef.shape[0] != 2 or not 1 <= coef.shape[1] <= 16 or cov.shape != (2, 2) or not (
            np.all(np.isfinite(coef)) and np.all(np.isfinite(cov))) or not (
            cov[0, 0] > 0 and cov[1, 1] > 0 and abs(cov[0, 1] - cov[1, 0]) <= 1e-9 * (cov[0, 0] + cov[1, 1])
            and np.linalg.det(cov) > 0):
        raise ListError(f"a response is 2 rows of coefficients (one column per axis) and a 2 x 2 covariance,"
                        f" symmetric and positive definite, got shapes {coef.shape} and {cov.shape}")
    return coef, cov
