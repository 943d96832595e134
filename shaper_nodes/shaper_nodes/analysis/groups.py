"""Cycles of one recording that see different modes: several plants, payloads or poses.

Rule (:func:`group_cycles`): two cycles see the same plant when every **significant** mode of each
(one that rings: damping ratio at most ``max_damping`` and initial amplitude above the noise floor;
and at least :data:`MIN_SHARE` of the cycle's strongest such amplitude) has a counterpart among the
other's ringing modes, i.e. a mode closer than :data:`GROUP_GAP` (relative) or :data:`GROUP_SIGMAS` combined
one-sigma uncertainties. Groups are the connected sets of that relation. Comparing the *sets* of
modes, not each cycle's dominant one, keeps a cycle in which the dominance of two close modes
swaps (another excitation of the same pose) with its plant, and does not let a heavily damped fit
(a transient, not a mode) decide. Each group's modes are then combined over its cycles only. One
group is the ordinary case: a recording of one plant in one pose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from shaper_nodes.core.identification import (
    MAX_RINGING_DAMPING,
    NOISE_FLOOR_SIGMAS,
    ModeFit,
    Recommendation,
    ringing_issue,
)

#: two cycles' modes closer than this (relative) are the same mode
GROUP_GAP = 0.05
#: ... and so are two closer than this many combined standard deviations
GROUP_SIGMAS = 3.0
#: a cycle's modes with at least this fraction of its strongest ringing amplitude must be in the other cycle
MIN_SHARE = 0.25


@dataclass
class ModeGroup:
    """Cycles that see the same modes: their indices in the analysis' rows (the ``#`` of its table),
    their cycle numbers, the modes combined over them and the shaper recommended for them."""

    rows: list[int]
    cycles: list[int]
    modes: list[ModeFit]
    recommendation: Recommendation | None = None

    @property
    def label(self) -> str:
        hz = ", ".join(f"{m.hz:.4g} Hz" for m in self.modes) or "no mode"
        return f"{hz} (cycles #{_ranges(self.rows)})"


def group_cycles(per_cycle: Sequence[tuple[int, Sequence[ModeFit]]], gap: float = GROUP_GAP,
                 sigmas: float = GROUP_SIGMAS, max_damping: float | None = MAX_RINGING_DAMPING, noise: float = 0.0,
                 noise_sigmas: float = NOISE_FLOOR_SIGMAS, share: float = MIN_SHARE) -> list[list[int]]:
    """Groups (lists of the keys given) of cycles that see the same modes (see the module docstring).

    Parameters
    ----------
    per_cycle : sequence of (key, modes)
        Each identified cycle's key (any int, e.g. its row) and modes (not empty).
    gap : float
        Relative frequency difference (fraction) within which two modes are the same.
    sigmas : float
        ... or within this many combined standard deviations of the two frequencies.
    max_damping, noise, noise_sigmas : float
        Which modes ring (:func:`~shaper_nodes.core.identification.ringing_issue`; noise in m/s^2 per axis).
    share : float
        Significant modes have at least this fraction of the cycle's strongest ringing amplitude.

    Returns
    -------
    list of list of int
        Groups in the order of their first key, keys in increasing order inside each.
    """
    items = [(k, list(m)) for k, m in per_cycle if m]
    ringing = [_ringing(m, max_damping, noise, noise_sigmas) for _, m in items]
    significant = [[m for m in r if m.amplitude >= share * max(x.amplitude for x in r)] for r in ringing]
    parent = list(range(len(items)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(len(items)):
        for j in range(i + 1, len(items)):
            if _covers(ringing[j], significant[i], gap, sigmas) and _covers(ringing[i], significant[j], gap, sigmas):
                parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i, (key, _) in enumerate(items):
        groups.setdefault(root(i), []).append(key)
    return sorted((sorted(g) for g in groups.values()), key=lambda g: g[0])


def _ringing(modes: Sequence[ModeFit], max_damping: float | None, noise: float, noise_sigmas: float
             ) -> list[ModeFit]:
    """The modes that ring (all of them when none does: then they are all the cycle has)."""
    out = [m for m in modes if not ringing_issue(m, max_damping, noise, noise_sigmas)]
    return out or list(modes)


def _covers(modes: Sequence[ModeFit], wanted: Sequence[ModeFit], gap: float, sigmas: float) -> bool:
    """Every mode of ``wanted`` has one in ``modes`` that is not apart from it."""
    return all(any(not _apart(w, m, gap, sigmas) for m in modes) for w in wanted)


def _apart(a: ModeFit, b: ModeFit, gap: float, sigmas: float) -> bool:
    d = abs(b.omega - a.omega)
    std = math.hypot(a.omega_std, b.omega_std)
    return d > gap * min(a.omega, b.omega) and (not math.isfinite(std) or d > sigmas * std)


def _ranges(values: Sequence[int]) -> str:
    """'0-2, 5, 7-8' for [0, 1, 2, 5, 7, 8]."""
    vals = sorted(values)
    out: list[str] = []
    i = 0
    while i < len(vals):
        j = i
        while j + 1 < len(vals) and vals[j + 1] == vals[j] + 1:
            j += 1
        out.append(str(vals[i]) if i == j else f"{vals[i]}-{vals[j]}")
        i = j + 1
    return ", ".join(out)
