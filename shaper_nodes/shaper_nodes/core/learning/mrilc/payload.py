"""The payload worked out from a drifted mode, free of ROS (issue 31 item 5 with MRILC per move).

When the drift watch warns, it has measured the arm's mode at a pose (the move's goal). The arm model the learner's
operator is built from gives its modes at that pose for any payload mass; :func:`payload_from_modes` finds the mass
whose model mode matches the measured one, by a 1-D search over the mass in a stated range:

1. the model's modes (Hz, lowest first) on a grid of masses over the range; the k-th lowest mode is a continuous
   function of the mass (a branch);
2. on every branch, every grid interval where the branch crosses the measured frequency is bisected to the mass
   where it equals it (each a candidate; candidates closer than ``separation`` kg are one);
3. each candidate is scored by the other modes measured in the same cycle (if any): how many of them the model has
   at that mass within ``match`` (relative). The candidate with the most wins; a tie between candidates further
   apart than ``separation`` is ambiguous and refused (on the simulated arm at the rotated pose, 8.54 Hz is the
   lowest mode at 4.5 kg and the second at 7.4 kg: the mode alone cannot tell them apart, the other modes can).

A frequency that is not finite and positive (NaN, a negative value, above :data:`MAX_HZ`), a model that fails or
gives no finite mode, or no mass in the range whose model mode matches, is refused with :class:`PayloadRefused`,
whose message says why: the caller keeps what it had (the learner: the payload it was told, or the provider's own).
The work is bounded: ``grid`` model evaluations, then at most :data:`BISECTIONS` per crossing, and one per candidate.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .model import MrilcError

#: the highest frequency taken as a mode, Hz (above it: refused, not searched)
MAX_HZ = 1e4
#: the default range of the search, kg: 0 to twice the UR5e's rated 5 kg
MASS_RANGE = (0.0, 10.0)
#: model evaluations on the grid of masses (every 0.25 kg over the default range)
GRID = 41
#: bisection steps per crossing (the grid's interval halved to below 1e-9 of it)
BISECTIONS = 32
#: a measured mode matches a model mode within this fraction of its frequency
MATCH = 0.03
#: candidate masses closer than this are one, kg
SEPARATION = 0.5
#: the most measured modes looked at (the first is the rated one)
MAX_MODES = 16

ModesAt = Callable[[float], Sequence[float]]


class PayloadRefused(MrilcError):
    """No payload could be worked out from the mode (the message says why)."""


@dataclass(frozen=True)
class PayloadEstimate:
    """A payload worked out from a measured mode.

    Attributes
    ----------
    mass : float
        The payload, kg.
    mode_hz : float
        The measured mode it was worked out from, Hz.
    model_hz : float
        The model's mode at ``mass`` on the matching branch, Hz.
    branch : int
        Which of the model's modes matched (0: the lowest).
    support : int
        How many of the other measured modes the model has at ``mass`` (within :data:`MATCH`).
    others : tuple of float
        The other candidate masses (less supported), kg.
    """

    mass: float
    mode_hz: float
    model_hz: float
    branch: int
    support: int
    others: tuple[float, ...] = ()

    def describe(self) -> str:
        """One line: the mass, the mode and the branch, the support."""
        nth = ("lowest", "second", "third")[self.branch] if self.branch < 3 else f"{self.branch + 1}th"
        text = (f"payload {self.mass:.3g} kg: the model's {nth} mode there is {self.model_hz:.4g} Hz, the measured"
                f" {self.mode_hz:.4g} Hz")
        if self.others:
            text += (f" ({self.support} other measured mode(s) match it; not "
                     + ", ".join(f"{m:.3g} kg" for m in self.others) + ")")
        return text


def _frequency(value: object) -> float | None:
    try:
        f = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) and 0.0 < f <= MAX_HZ else None


def _modes(modes_at: ModesAt, mass: float) -> list[float]:
    """The model's finite positive modes at ``mass``, lowest first. Raises PayloadRefused if it fails."""
    try:
        got = [float(x) for x in modes_at(mass)]
    except (ArithmeticError, ValueError, TypeError, LookupError) as err:
        raise PayloadRefused(f"the model's modes at {mass:.6g} kg failed: {err}") from None
    out = sorted(f for f in got if math.isfinite(f) and f > 0.0)
    if not out:
        raise PayloadRefused(f"the model gives no mode at {mass:.6g} kg")
    return out


def _crossing(modes_at: ModesAt, branch: int, target: float, lo: float, hi: float, flo: float) -> tuple[float, float]:
    """The mass in [lo, hi] where the branch's mode equals ``target`` (it crosses it there), and the mode there."""
    f = flo
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        modes = _modes(modes_at, mid)
        if branch >= len(modes):
            break
        f = modes[branch]
        if (f - target) * (flo - target) > 0.0:
            lo, flo = mid, f
        else:
            hi = mid
    mass = 0.5 * (lo + hi)
    modes = _modes(modes_at, mass)
    return mass, modes[branch] if branch < len(modes) else f


def _candidates(modes_at: ModesAt, target: float, masses: list[float], table: list[list[float]],
                branches: int) -> list[tuple[float, int, float]]:
    """Every (mass, branch, model Hz) where a branch of the grid's ``table`` crosses ``target``."""
    found: list[tuple[float, int, float]] = []
    last = len(masses) - 2
    for k in range(branches):
        for i in range(len(masses) - 1):
            a, b = table[i][k] - target, table[i + 1][k] - target
            if a == 0.0:
                found.append((masses[i], k, table[i][k]))
            elif b == 0.0 and i == last:
                found.append((masses[i + 1], k, table[i + 1][k]))
            elif a * b < 0.0:
                mass, hz = _crossing(modes_at, k, target, masses[i], masses[i + 1], table[i][k])
                found.append((mass, k, hz))
    return found


def payload_from_modes(measured_hz: Sequence[float], modes_at: ModesAt, mass_range: tuple[float, float] = MASS_RANGE,
                       grid: int = GRID, match: float = MATCH, separation: float = SEPARATION) -> PayloadEstimate:
    """The payload whose model mode matches the measured one (module docstring).

    Parameters
    ----------
    measured_hz : sequence of float
        The measured modes, Hz: the first is the one the drift watch rated (the one matched); the others (from the
        same cycle) only choose between candidates. Those that are not finite and positive are ignored.
    modes_at : callable
        ``modes_at(mass)``: the model's modes at the pose, Hz, for a payload of ``mass`` kg.
    mass_range : (float, float)
        The masses searched, kg (0 <= low < high).
    grid : int
        Model evaluations on the grid over the range (3 to 1000).
    match : float
        Relative tolerance of an other measured mode's match (0 to 0.5).
    separation : float
        Candidates closer than this are one, kg (> 0).

    Returns
    -------
    PayloadEstimate

    Raises
    ------
    PayloadRefused
        The measured mode is not a frequency, the model fails, no mass in the range matches, or two masses far
        apart match equally well (the message says which).
    """
    lo, hi = (float(x) for x in mass_range)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise PayloadRefused(f"the mass range must be finite with 0 <= low < high, got {mass_range}")
    if not (isinstance(grid, int) and 3 <= grid <= 1000):
        raise PayloadRefused(f"grid must be an integer in [3, 1000], got {grid!r}")
    if not (0.0 < match <= 0.5 and 0.0 < separation < math.inf):
        raise PayloadRefused(f"match must be in (0, 0.5] and separation positive, got {match}, {separation}")
    measured = list(measured_hz)[:MAX_MODES]
    if not measured:
        raise PayloadRefused("no measured mode")
    target = _frequency(measured[0])
    if target is None:
        raise PayloadRefused(f"the measured mode {measured[0]!r} Hz is not a finite frequency in (0, {MAX_HZ:g}] Hz")
    others = [f for f in map(_frequency, measured[1:]) if f is not None]
    masses = [lo + (hi - lo) * i / (grid - 1) for i in range(grid)]
    table = [_modes(modes_at, m) for m in masses]
    branches = min(len(row) for row in table)
    found = _candidates(modes_at, target, masses, table, branches)
    if not found:
        span = ", ".join(f"{min(row[k] for row in table):.4g}-{max(row[k] for row in table):.4g}"
                         for k in range(min(branches, 3)))
        raise PayloadRefused(f"no payload in [{lo:g}, {hi:g}] kg gives a model mode of {target:.6g} Hz at this pose"
                             f" (its lowest modes span {span} Hz over the range)")
    found.sort()
    merged: list[tuple[float, int, float]] = []
    for cand in found:
        if not merged or cand[0] - merged[-1][0] >= separation:
            merged.append(cand)
    scored = []
    for mass, k, model_hz in merged:
        at = _modes(modes_at, mass)
        support = sum(any(abs(f - g) <= match * f for g in at) for f in others)
        scored.append((support, mass, k, model_hz))
    best = max(s[0] for s in scored)
    top = [s for s in scored if s[0] == best]
    if len(top) > 1:
        said = " or ".join(f"{m:.3g} kg (mode {k + 1}, {hz:.4g} Hz)" for _, m, k, hz in top)
        raise PayloadRefused(f"ambiguous: {said} give the measured {target:.4g} Hz and match"
                             f" {best} of the {len(others)} other measured mode(s) alike")
    support, mass, k, model_hz = top[0]
    return PayloadEstimate(mass=mass, mode_hz=target, model_hz=model_hz, branch=k, support=support,
                           others=tuple(m for _, m, _, _ in scored if m != mass))
