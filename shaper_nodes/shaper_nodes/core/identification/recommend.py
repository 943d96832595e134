"""The shaper recommendation: the shortest shaper robust over the identified modes' uncertainty.

For identified modes with one-sigma uncertainties (:mod:`.modes`), every family of the registry
(except ``none``, ``custom`` and ``zvdn``) is designed on the modes and its percentage vibration
evaluated over the uncertainty box; the shortest candidate whose worst case stays under the
target is recommended, and every candidate is returned, shortest first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.shaping.families import FAMILIES, Shaper, ShaperError, design
from shaper_nodes.core.shaping.vibration import percentage_vibration

from .modes import ModeFit
from .record import IdentificationError

#: fraction of the tolerance used when designing tolerance-based shapers (ei, si, ...)
DESIGN_MARGIN = 0.8
#: families not considered by the recommendation
EXCLUDED_FAMILIES = ("none", "custom", "zvdn")



@dataclass(frozen=True)
class Candidate:
    """A shaper designed on the identified modes and its vibration over their uncertainty.

    Attributes
    ----------
    family : str
        Shaper family.
    shaper : Shaper
        The design.
    duration : float
        Shaper duration, s.
    nominal_vibration : float
        Max over the shaped modes of V at the identified (omega, zeta), fraction.
    worst_vibration : float
        Max over the shaped modes of V over the uncertainty box, fraction.
    meets_target : bool
        ``worst_vibration <= target``.
    """

    family: str
    shaper: Shaper
    duration: float
    nominal_vibration: float
    worst_vibration: float
    meets_target: bool


@dataclass(frozen=True)
class Recommendation:
    """Candidates shortest first, and the shortest that meets the target (``best``)."""

    target: float
    modes: tuple[ModeFit, ...]
    candidates: tuple[Candidate, ...]
    best: Candidate | None
    notes: tuple[str, ...] = ()


def worst_case_vibration(shaper: Shaper, modes: Sequence[ModeFit], sigmas: float = 2.0,
                         points: tuple[int, int] = (61, 9)) -> tuple[float, float]:
    """(nominal, worst) percentage vibration of ``shaper`` over the modes' uncertainty box.

    The box of each mode is omega in [w - sigmas s_w, w + sigmas s_w] and zeta in
    [max(0, z - sigmas s_z), z + sigmas s_z], sampled on a grid of ``points`` (omega, zeta)
    values that includes the nominal point; the result is the maximum over all modes.
    """
    nominal, worst = 0.0, 0.0
    for mf in modes:
        dw, dz = sigmas * mf.omega_std, sigmas * mf.zeta_std
        om = np.linspace(max(mf.omega - dw, 1e-9 * mf.omega), mf.omega + dw, points[0])
        ze = np.linspace(max(mf.zeta - dz, 0.0), min(mf.zeta + dz, 0.99), points[1])
        om = np.append(om, mf.omega)
        ze = np.append(ze, mf.zeta)
        v = percentage_vibration(shaper.amplitudes, shaper.times, om[:, None], ze[None, :])
        nominal = max(nominal, float(v[-1, -1]))
        worst = max(worst, float(v.max()))
    return nominal, worst


def recommend_shaper(
    modes: Sequence[ModeFit],
    target: float = 0.05,
    *,
    sigmas: float = 2.0,
    families: Sequence[str] | None = None,
    min_relative_amplitude: float = 0.1,
) -> Recommendation:
    """Design candidate shapers on the identified modes and pick the shortest robust one.

    Parameters
    ----------
    modes : sequence of ModeFit
        Identified modes; those with amplitude >= ``min_relative_amplitude`` times the
        strongest are shaped (multi-mode designs are convolutions).
    target : float
        Largest acceptable worst-case percentage vibration, fraction (0.05 = 5 %).
    sigmas : float
        Half-width of the uncertainty box in standard deviations.
    families : sequence of str, optional
        Families to consider; default every family of :data:`FAMILIES` except ``none``,
        ``custom`` and ``zvdn``. Tolerance-based families are designed with
        ``vibration_tolerance = DESIGN_MARGIN * target``; ``si`` in addition with the
        insensitivity ``2 sigmas omega_std / omega`` (largest over the shaped modes), which
        covers omega +- sigmas omega_std.
    min_relative_amplitude : float
        See ``modes``.

    Returns
    -------
    Recommendation
        ``best`` is the shortest candidate whose worst-case V <= target, or None. Families
        that cannot be designed are left out and named in ``notes``.
    """
    modes = list(modes)
    if not modes:
        raise IdentificationError("no modes to design a shaper for")
    target = float(target)
    if not (math.isfinite(target) and 0.0 < target < 1.0):
        raise IdentificationError(f"target vibration must be in (0, 1), got {target!r}")
    sigmas = float(sigmas)
    if not (math.isfinite(sigmas) and sigmas >= 0.0):
        raise IdentificationError(f"sigmas must be finite and >= 0, got {sigmas!r}")
    top = max(mf.amplitude for mf in modes)
    shaped = tuple(sorted((mf for mf in modes if mf.amplitude >= min_relative_amplitude * top),
                          key=lambda mf: -mf.amplitude))
    names = [f for f in FAMILIES if f not in EXCLUDED_FAMILIES] if families is None else list(families)
    design_modes = [mf.mode for mf in shaped]
    tolerance = DESIGN_MARGIN * target
    insensitivity = max(2.0 * sigmas * mf.omega_std / mf.omega for mf in shaped)
    candidates: list[Candidate] = []
    notes: list[str] = []
    for fam in names:
        try:
            if fam == "si":
                shaper = design("si", design_modes, vibration_tolerance=tolerance, insensitivity=insensitivity)
            else:
                shaper = design(fam, design_modes, vibration_tolerance=tolerance)
        except ShaperError as exc:
            notes.append(f"{fam}: not designed ({exc})")
            continue
        nominal, worst = worst_case_vibration(shaper, shaped, sigmas)
        candidates.append(Candidate(shaper.family, shaper, shaper.duration, nominal, worst, worst <= target))
    # durations equal to 1 us (far below any command period) tie; the more robust comes first
    candidates.sort(key=lambda c: (round(c.duration, 6), c.worst_vibration))
    best = next((c for c in candidates if c.meets_target), None)
    if best is None:
        notes.append(f"no candidate keeps the worst-case vibration under {100 * target:.3g} %")
    return Recommendation(target, shaped, tuple(candidates), best, tuple(notes))
