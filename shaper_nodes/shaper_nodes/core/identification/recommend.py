"""The shaper recommendation: a shaper that leaves no vibration at the identified mode, robust over
its uncertainty, unless another is materially shorter.

For identified modes with one-sigma uncertainties (:mod:`.modes`), every family of the registry
(except ``none``, ``custom`` and ``zvdn``) is designed on the modes and its percentage vibration
V evaluated at the modes (nominal) and over their uncertainty box (worst case). The rule trades
delay (the shaper's duration) against residual vibration:

1. the default is the shortest candidate that leaves (near) zero vibration at the identified
   modes (nominal V <= :data:`ZERO_VIBRATION`) and keeps the worst case over the box within the
   target: ZV for a well-known mode, ZVD or ZVDD as the uncertainty grows;
2. another candidate (EI, SI, MZV, ... which leave up to their tolerance at the mode) replaces it
   only if it is at least ``min_saving`` (:data:`MIN_SAVING`, 20 %) shorter while its worst case
   also stays within the target;
3. if no zero-residual candidate meets the target, the shortest candidate that does.

Before the rule, when asked (``max_damping``, ``noise``), the modes that do not ring are set aside
(:func:`split_ringing`): reported in :attr:`Recommendation.not_ringing` with why, but neither
designed on nor used to choose. A mode does not ring when its damping ratio exceeds
``max_damping`` (:data:`MAX_RINGING_DAMPING`, 0.3: a free decay's envelope falls by
exp(-2 pi zeta / sqrt(1 - zeta^2)) per damped period, to 14 % after one period and 1.9 % after two
at 0.3, to 2.7 % after one at 0.5; such a "mode" is mostly the fit of a transient or of the noise's
spectrum, and a shaper designed on it only adds delay), or when its initial amplitude is at the
measured noise floor (at most ``noise_sigmas`` (:data:`NOISE_FLOOR_SIGMAS`, 1) times the sensor's
noise standard deviation ``noise``). When no mode rings, nothing is recommended
(``best`` None) and the rule says :data:`NO_SHAPER_NEEDED`.

The rule and the figures of the decision are stated in :attr:`Recommendation.rule`.
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
#: nominal V (fraction) at or below which a shaper leaves no residual vibration at the mode
ZERO_VIBRATION = 0.005
#: fraction of the default's duration another shaper must save to be recommended instead
MIN_SAVING = 0.2
#: damping ratio above which an identified mode does not ring (see the module docstring)
MAX_RINGING_DAMPING = 0.3
#: a mode whose initial amplitude is at most this many noise standard deviations is at the noise floor
NOISE_FLOOR_SIGMAS = 1.0
#: the rule's verdict when no identified mode rings
NO_SHAPER_NEEDED = "no residual vibration above the noise: no shaper needed (keep the shaper in use)"


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
    """Candidates shortest first, the one recommended (``best``) and the rule that chose it.

    ``rule`` states the rule with its numbers and the decision (which default, which alternative
    and how much delay it would save); ``default`` is the zero-residual candidate of the rule
    (None if none meets the target).
    """

    target: float
    modes: tuple[ModeFit, ...]
    candidates: tuple[Candidate, ...]
    best: Candidate | None
    notes: tuple[str, ...] = ()
    rule: str = ""
    default: Candidate | None = None
    not_ringing: tuple[tuple[ModeFit, str], ...] = ()  # modes set aside, with why (:func:`split_ringing`)


def ringing_issue(mode: ModeFit, max_damping: float | None = MAX_RINGING_DAMPING, noise: float = 0.0,
                  noise_sigmas: float = NOISE_FLOOR_SIGMAS) -> str:
    """Why ``mode`` does not ring ("" if it does): damping ratio above ``max_damping`` (None: no
    limit), or initial amplitude at most ``noise_sigmas`` times ``noise`` (the sensor's noise
    standard deviation, in the amplitude's units, e.g. m/s^2 per axis; 0: not checked)."""
    if max_damping is not None and mode.zeta > max_damping:
        return f"does not ring: damping {mode.zeta:.3g} > {max_damping:g}"
    if noise > 0.0 and mode.amplitude <= noise_sigmas * noise:
        return f"at the noise floor: amplitude {mode.amplitude:.2g} <= {noise_sigmas:g} x the noise {noise:.2g}"
    return ""


def split_ringing(modes: Sequence[ModeFit], max_damping: float | None = MAX_RINGING_DAMPING, noise: float = 0.0,
                  noise_sigmas: float = NOISE_FLOOR_SIGMAS
                  ) -> tuple[list[ModeFit], list[tuple[ModeFit, str]]]:
    """(the modes that ring, [(mode, why not) for the others]) by :func:`ringing_issue`, in the given order.

    Raises
    ------
    IdentificationError
        ``max_damping`` not in (0, 1], ``noise`` negative or ``noise_sigmas`` negative.
    """
    if max_damping is not None and not (math.isfinite(max_damping) and 0.0 < max_damping <= 1.0):
        raise IdentificationError(f"max_damping (the damping ratio above which a mode does not ring) must be in"
                                  f" (0, 1], got {max_damping!r}")
    if not (math.isfinite(noise) and noise >= 0.0 and math.isfinite(noise_sigmas) and noise_sigmas >= 0.0):
        raise IdentificationError(f"noise and noise_sigmas must be finite and >= 0, got {noise!r}, {noise_sigmas!r}")
    ringing: list[ModeFit] = []
    left: list[tuple[ModeFit, str]] = []
    for mf in modes:
        why = ringing_issue(mf, max_damping, noise, noise_sigmas)
        if why:
            left.append((mf, why))
        else:
            ringing.append(mf)
    return ringing, left


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
    min_saving: float = MIN_SAVING,
    max_damping: float | None = None,
    noise: float = 0.0,
    noise_sigmas: float = NOISE_FLOOR_SIGMAS,
) -> Recommendation:
    """Design candidate shapers on the identified modes and pick one by the rule of the module.

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
    min_saving : float
        Fraction of the zero-residual default's duration (0..1) another candidate must save to be
        recommended instead (default :data:`MIN_SAVING`).
    max_damping : float, optional
        Modes with a larger damping ratio do not ring and are set aside (:func:`split_ringing`;
        :data:`MAX_RINGING_DAMPING` is the bag analysis' default). None (default): every mode is used.
    noise : float
        The sensor's noise standard deviation in the modes' amplitude units (e.g. m/s^2 per axis);
        modes of initial amplitude <= ``noise_sigmas`` times it are at the noise floor and set aside.
        0 (default): not checked.
    noise_sigmas : float
        See ``noise`` (default :data:`NOISE_FLOOR_SIGMAS`).

    Returns
    -------
    Recommendation
        ``best`` is chosen by the rule of the module (None if no candidate's worst-case V <=
        target, or if no mode rings: then ``rule`` is :data:`NO_SHAPER_NEEDED` and
        ``not_ringing`` names every mode), ``rule`` says how. Families that cannot be designed are
        left out and named in ``notes``; modes set aside are in ``not_ringing`` and ``notes``.
    """
    modes = list(modes)
    if not modes:
        raise IdentificationError("no modes to design a shaper for")
    modes, not_ringing = split_ringing(modes, max_damping, noise, noise_sigmas)
    aside = [f"{mf.hz:.4g} Hz ({why}) not used for the shaper" for mf, why in not_ringing]
    if not modes:
        return Recommendation(float(target), (), (), None, tuple(aside),
                              f"rule: {NO_SHAPER_NEEDED}; " + "; ".join(aside), None, tuple(not_ringing))
    target = float(target)
    if not (math.isfinite(target) and 0.0 < target < 1.0):
        raise IdentificationError(f"target vibration must be in (0, 1), got {target!r}")
    sigmas = float(sigmas)
    if not (math.isfinite(sigmas) and sigmas >= 0.0):
        raise IdentificationError(f"sigmas must be finite and >= 0, got {sigmas!r}")
    min_saving = float(min_saving)
    if not (math.isfinite(min_saving) and 0.0 <= min_saving <= 1.0):
        raise IdentificationError(f"min_saving must be in [0, 1], got {min_saving!r}")
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
    best, default, rule = choose(candidates, target, sigmas, min_saving)
    if best is None:
        notes.append(f"no candidate keeps the worst-case vibration under {100 * target:.3g} %")
    if aside:
        rule += " (set aside: " + "; ".join(aside) + ")"
    return Recommendation(target, shaped, tuple(candidates), best, tuple(aside + notes), rule, default,
                          tuple(not_ringing))


def choose(candidates: Sequence[Candidate], target: float, sigmas: float, min_saving: float = MIN_SAVING
           ) -> tuple[Candidate | None, Candidate | None, str]:
    """(recommended, zero-residual default, the rule and its decision in words) for ``candidates``
    sorted shortest first (the rule of the module; ``target`` a fraction, ``sigmas`` the box)."""
    meeting = [c for c in candidates if c.meets_target]
    default = next((c for c in meeting if c.nominal_vibration <= ZERO_VIBRATION), None)
    head = (f"rule: the shortest shaper leaving V <= {100 * ZERO_VIBRATION:g} % at the identified mode and"
            f" <= {100 * target:g} % over the mode +- {sigmas:g} sigma; another only if it is at least"
            f" {100 * min_saving:g} % shorter with the same worst case")

    def desc(c: Candidate) -> str:
        return (f"{c.family} ({1e3 * c.duration:.1f} ms, V {100 * c.nominal_vibration:.2g} % at the mode,"
                f" {100 * c.worst_vibration:.2g} % worst case)")

    if not meeting:
        return None, None, f"{head}: no candidate keeps the worst case within {100 * target:g} %"
    shortest = meeting[0]
    if default is None:
        return shortest, None, (f"{head}: no zero-residual shaper keeps the worst case within"
                                f" {100 * target:g} %, so the shortest that does: {desc(shortest)}")
    saving = 1.0 - shortest.duration / default.duration if default.duration > 0 else 0.0
    if shortest is not default and saving >= min_saving:
        return shortest, default, (f"{head}: {desc(shortest)} saves {100 * saving:.3g} % of the delay of"
                                   f" {desc(default)}: taken")
    if shortest is default:
        return default, default, f"{head}: {desc(default)}, also the shortest within the target"
    return default, default, (f"{head}: {desc(default)}; the shortest alternative {desc(shortest)} would save"
                              f" only {100 * saving:.3g} % of the delay")
