"""Cycles of one recording that see different modes: several plants, payloads or poses.

Rule (:func:`group_cycles`): each cycle's dominant mode (the largest amplitude it identified) is
taken; the cycles are sorted by its frequency and split between two neighbours whose frequencies
differ by more than :data:`GROUP_GAP` (relative) and by more than :data:`GROUP_SIGMAS` times their
combined one-sigma uncertainty. Each group's modes are then combined over its cycles only. One
group is the ordinary case: a recording of one plant in one pose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from shaper_nodes.core.identification import ModeFit, Recommendation

#: neighbouring cycles' dominant frequencies further apart than this (relative) may split a group
GROUP_GAP = 0.05
#: ... if they are also further apart than this many combined standard deviations
GROUP_SIGMAS = 3.0


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
                 sigmas: float = GROUP_SIGMAS) -> list[list[int]]:
    """Groups (lists of the keys given) of cycles whose dominant modes agree (see the module docstring).

    Parameters
    ----------
    per_cycle : sequence of (key, modes)
        Each identified cycle's key (any int, e.g. its row) and modes (not empty).
    gap : float
        Relative frequency gap (fraction) that may split a group.
    sigmas : float
        The gap must also exceed this many combined standard deviations of the two frequencies.

    Returns
    -------
    list of list of int
        Groups in increasing frequency, keys in increasing frequency inside each.
    """
    dominant = sorted(((max(m, key=lambda f: f.amplitude), k) for k, m in per_cycle if m),
                      key=lambda e: e[0].omega)
    groups: list[list[int]] = []
    prev: ModeFit | None = None
    for mf, key in dominant:
        if prev is None or _apart(prev, mf, gap, sigmas):
            groups.append([key])
        else:
            groups[-1].append(key)
        prev = mf
    return groups


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
