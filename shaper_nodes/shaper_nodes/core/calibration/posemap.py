"""The pose map: modes identified at each calibrated pose, checked across repeats, and what it feeds.

At each pose every excitation leaves a free decay (the accelerometer from the end of the
commanded motion for ``decay`` s). Each decay is identified on its own
(:func:`shaper_nodes.core.identification.identify`, all axes jointly, with uncertainties robust
to a residual that is not white and widened by the spread over analysis variants: record start
and model order); the repeats are combined by :func:`combine_modes` (a mode kept if found in at
least half of them), its uncertainty the larger of the per-record one-sigma and the spread
between repeats widened for their number (Student's t, :func:`_expanded`). Quality flags:

``identification_failed``
    a repeat gave no mode (the reason is kept);
``mode_not_in_every_repeat``
    a combined mode was missed by some repeat;
``repeats_disagree``
    a mode's frequencies over the repeats spread by more than ``agreement`` (relative, largest
    deviation from their mean), or its damping ratios by more than 10 times that;
``no_mode``
    nothing identified at the pose.

From the map (:func:`rule_base_spec`): the scheduler's rule base over the grid joints along
which the modes change by more than ``premise_threshold`` (the others are averaged out), with
a triangular partition per premise peaking at the grid values (their product is bilinear
interpolation of the modes) and, per rule, the pose's modes sorted by frequency. Every rule
carries the same number of modes (the scheduler interpolates k-th with k-th): a pose missing
one takes it from the nearest pose that has it, and says so. The fallback (:func:`fallback`)
is the family's shaper on the home pose's modes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from shaper_nodes.core.shaping import Mode, Shaper, design
from shaper_nodes.core.shaping.vibration import percentage_vibration

from .plan import Plan, PlanError, grid_axis

if TYPE_CHECKING:  # the identification (scipy) is imported where it runs: the recording process needs none of it
    from shaper_nodes.core.identification import ModeFit

#: analysis variants of a decay: (record start after the commanded motion ends, s; modes fitted
#: beyond max_modes). The first is the estimate; all give its model-error spread.
VARIANTS = ((0.05, 1), (0.02, 0), (0.1, 0), (0.4, 0))
#: where the spectrum of a pose's first decay starts, s
DECAY_START = VARIANTS[0][0]


@dataclass(frozen=True)
class Decay:
    """One free decay: times from the commanded motion's end (s) and the signal (N, k)."""

    pose: int
    repeat: int
    times: np.ndarray
    signal: np.ndarray


@dataclass(frozen=True)
class IdentifySettings:
    """How each decay is identified and how repeats must agree."""

    method: str = "fit"
    max_modes: int = 4
    band_hz: tuple[float, float] | None = (2.0, 45.0)  # where modes are looked for, Hz
    agreement: float = 0.02
    max_damping: float = 0.15


@dataclass
class PoseResult:
    """The modes at one pose, per repeat and combined, with quality flags."""

    index: int
    name: str
    positions: np.ndarray
    grid_index: tuple[int, ...] | None
    modes: list[ModeFit]
    repeats: list[list[ModeFit]]
    flags: list[str] = field(default_factory=list)
    spectrum: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def ok(self) -> bool:
        return bool(self.modes) and not any(f.startswith(("identification_failed", "repeats_disagree", "no_mode"))
                                            for f in self.flags)


def _variant_spread(times: np.ndarray, signal: np.ndarray, primary: list[ModeFit], settings: IdentifySettings
                    ) -> list[ModeFit]:
    """The primary fit's modes with the spread over analysis variants (record start, model order)
    added to their uncertainties: sigma^2 = sigma_stat^2 + (sample std over the variants)^2.

    The Jacobian covariance only knows the noise; a mode that unmodelled content (a heavily
    damped mode, the start of the record) pulls shows it by moving between variants."""
    from shaper_nodes.core.identification import IdentificationError, ModeFit, identify

    estimates: list[list[ModeFit]] = [[m] for m in primary]
    for start, extra in VARIANTS[1:]:
        keep = times >= start
        try:
            found = identify(times[keep], signal[keep], method=settings.method,
                             max_modes=min(8, settings.max_modes + extra), band_hz=settings.band_hz)
        except IdentificationError:
            continue
        for est, m in zip(estimates, primary, strict=True):
            near = [f for f in found if abs(f.omega - m.omega) / m.omega < 0.05]
            if near:
                est.append(min(near, key=lambda f: abs(f.omega - m.omega)))
    out = []
    for est, m in zip(estimates, primary, strict=True):
        if len(est) > 1:
            sw = float(np.std([e.omega for e in est], ddof=1))
            sz = float(np.std([e.zeta for e in est], ddof=1))
        else:
            sw = sz = 0.0
        out.append(ModeFit(m.omega, m.zeta, math.hypot(m.omega_std, sw), math.hypot(m.zeta_std, sz), m.amplitude,
                           m.method))
    return out


def identify_decay(d: Decay, settings: IdentifySettings) -> list[ModeFit]:
    """The lightly damped modes of one decay (damping below settings.max_damping), their
    uncertainties including the spread over analysis variants; raises IdentificationError."""
    from shaper_nodes.core.identification import IdentificationError, identify

    start, extra = VARIANTS[0]
    keep = d.times >= start
    primary = identify(d.times[keep], d.signal[keep], method=settings.method,
                       max_modes=min(8, settings.max_modes + extra), band_hz=settings.band_hz, covariance="hac")
    primary = sorted(primary, key=lambda m: -m.amplitude)
    light = [m for m in primary if m.zeta < settings.max_damping][: settings.max_modes]
    if not light:
        raise IdentificationError(f"no lightly damped mode (damping below {settings.max_damping:g}) found")
    return _variant_spread(d.times, d.signal, light, settings)


def _expanded(m: ModeFit, hits: Sequence[ModeFit]) -> ModeFit:
    """The combined mode with its spread between repeats widened for their number (GUM, Annex G): from k
    repeats the sample standard deviation has k - 1 degrees of freedom, so it is multiplied by
    t(0.975, k - 1) / t(0.975, inf) and a two-sigma interval keeps its 95 % coverage with few repeats.
    The per-record uncertainty (the fit's) is kept when it is larger."""
    k = len(hits)
    if k < 2:
        return m
    from scipy.stats import t as student_t  # on first use: scipy.stats is 0.6 s of CPU at a node's start

    from shaper_nodes.core.identification import ModeFit

    factor = float(student_t.ppf(0.975, k - 1) / student_t.ppf(0.975, 1e9))
    rms_w = math.sqrt(float(np.mean([h.omega_std**2 for h in hits])))
    rms_z = math.sqrt(float(np.mean([h.zeta_std**2 for h in hits])))
    sw = factor * float(np.std([h.omega for h in hits], ddof=1))
    sz = factor * float(np.std([h.zeta for h in hits], ddof=1))
    return ModeFit(m.omega, m.zeta, max(rms_w, sw, m.omega_std), max(rms_z, sz, m.zeta_std), m.amplitude, m.method)


def identify_pose(index: int, name: str, positions: np.ndarray, grid_index: tuple[int, ...] | None,
                  decays: Sequence[Decay], settings: IdentifySettings) -> PoseResult:
    """Identify every decay of a pose, combine them and flag what does not agree."""
    from shaper_nodes.core.identification import IdentificationError, combine_modes
    from shaper_nodes.core.identification.record import spectrum

    per: list[list[ModeFit]] = []
    flags: list[str] = []
    for d in decays:
        try:
            per.append(identify_decay(d, settings))
        except IdentificationError as err:
            per.append([])
            flags.append(f"identification_failed: repeat {d.repeat}: {err}")
    found = [p for p in per if p]
    combined = combine_modes(found, method=settings.method, max_modes=settings.max_modes) if found else []
    modes = []
    for m in sorted(combined, key=lambda m: m.omega):
        near = [[r for r in rep if abs(r.omega - m.omega) / m.omega < 0.1] for rep in per]
        hits = [min(rs, key=lambda r: abs(r.omega - m.omega)) for rs in near if rs]
        m = _expanded(m, hits)
        modes.append(m)
        if len(hits) < len(per):
            flags.append(f"mode_not_in_every_repeat: {m.hz:.3f} Hz in {len(hits)} of {len(per)}")
        if len(hits) > 1:
            spread = max(abs(h.omega - m.omega) for h in hits) / m.omega
            zspread = max(abs(h.zeta - m.zeta) for h in hits) / max(m.zeta, 1e-3)
            if spread > settings.agreement or zspread > 10 * settings.agreement:
                flags.append(f"repeats_disagree: {m.hz:.3f} Hz spreads {100 * spread:.2f} % in frequency,"
                             f" {100 * zspread:.1f} % in damping")
    if not modes:
        flags.append("no_mode")
    spec = None
    if decays:
        d = decays[0]
        keep = d.times >= DECAY_START
        t, y = d.times[keep], d.signal[keep]
        if t.size > 8:
            dt = float(np.median(np.diff(t)))
            y = y - y.mean(axis=0)
            f, p = spectrum(y, dt)
            spec = (f, p)
    return PoseResult(index, name, np.asarray(positions, float), grid_index, modes, per, flags, spec)


# --------------------------------------------------------------------------- the rule base
def _aligned_modes(results: Sequence[PoseResult]) -> tuple[list[list[Mode]], list[str]]:
    """Every pose's modes sorted by frequency, all with the same count; notes of what was filled."""
    counts = [len(r.modes) for r in results if r.modes]
    if not counts:
        raise PlanError("no pose of the map was identified: no rule base can be built")
    k = max(set(counts), key=lambda c: (counts.count(c), c))  # the most common count, larger on ties
    full = [r for r in results if len(r.modes) >= k]
    notes: list[str] = []
    out: list[list[Mode]] = []
    for r in results:
        own = [m.mode for m in sorted(r.modes, key=lambda m: m.omega)]
        if len(own) == k:  # a flagged pose keeps what it measured (its flags say how far to trust it)
            out.append(own)
            continue
        donor = min(full, key=lambda f: float(np.max(np.abs(f.positions - r.positions))))
        ref = [m.mode for m in sorted(donor.modes, key=lambda m: m.omega)][:k]
        slots: list[Mode | None] = [None] * k
        for m in own:  # each own mode takes the nearest free slot of the donor's
            free = [i for i in range(k) if slots[i] is None]
            if not free:
                break
            i = min(free, key=lambda i: abs(ref[i].omega - m.omega) / ref[i].omega)
            slots[i] = m
        filled = [i for i in range(k) if slots[i] is None]
        if filled:
            notes.append(f"{r.name}: mode(s) {', '.join(f'{ref[i].omega / (2 * math.pi):.3f} Hz' for i in filled)}"
                         f" taken from {donor.name}")
        out.append(sorted([s if s is not None else ref[i] for i, s in enumerate(slots)], key=lambda m: m.omega))
    return out, notes


def _triangles(values: np.ndarray) -> list[list[float]]:
    if values.size == 1:
        return [[values[0] - 1.0, values[0], values[0] + 1.0]]
    out = []
    for i, x in enumerate(values):
        lo = values[i - 1] if i > 0 else x
        hi = values[i + 1] if i + 1 < values.size else x
        out.append([float(lo), float(x), float(hi)])
    return out


def rule_base_spec(plan: Plan, results: Sequence[PoseResult], family: str = "zv",
                   premise_threshold: float = 0.02) -> tuple[dict[str, Any], list[str]]:
    """The scheduler's rule base from the grid's poses (a mapping as rule_base_from_dict takes),
    and notes on what was chosen (premises kept and dropped, modes filled in)."""
    c = plan.config
    if not c.grid_joints:
        raise PlanError("a rule base is built from a grid of poses (grid.joints)")
    grid_res = [r for r in results if r.grid_index is not None]
    aligned, notes = _aligned_modes(grid_res)
    names = list(c.joint_names)
    axes = [grid_axis(lo, hi, int(cnt), float(c.home_pose[names.index(j)]))
            for j, lo, hi, cnt in zip(c.grid_joints, c.grid_lower, c.grid_upper, c.grid_counts, strict=True)]
    counts = [a.size for a in axes]
    k = len(aligned[0])
    omega = np.zeros((*counts, k))
    zeta = np.zeros((*counts, k))
    for r, ms in zip(grid_res, aligned, strict=True):
        assert r.grid_index is not None
        omega[r.grid_index] = [m.omega for m in ms]
        zeta[r.grid_index] = [m.zeta for m in ms]
    keep = []
    for a, joint in enumerate(c.grid_joints):
        if counts[a] < 2:
            notes.append(f"{joint}: one grid value, not a premise")
            continue
        change = float(np.max(np.ptp(omega, axis=a) / np.min(omega, axis=a)))
        if change > premise_threshold:
            keep.append(a)
            notes.append(f"{joint}: modes change by up to {100 * change:.1f} % along it: a premise")
        else:
            notes.append(f"{joint}: modes change by {100 * change:.2f} % (<= {100 * premise_threshold:g} %):"
                         " averaged out, not a premise")
    if not keep:  # the map is flat: one rule on the first grid joint, the mean modes
        keep_axes: list[int] = []
        om, ze = omega.reshape(-1, k).mean(axis=0)[None], zeta.reshape(-1, k).mean(axis=0)[None]
        premises = [c.grid_joints[0]]
        tri = [[_triangles(np.array([float(np.mean(axes[0]))]))[0]]]
        shape: tuple[int, ...] = (1,)
    else:
        keep_axes = keep
        drop = tuple(a for a in range(len(counts)) if a not in keep)
        om = omega.mean(axis=drop) if drop else omega
        ze = zeta.mean(axis=drop) if drop else zeta
        premises = [c.grid_joints[a] for a in keep]
        tri = [_triangles(axes[a]) for a in keep]
        shape = tuple(counts[a] for a in keep)
    rules: dict[str, Any] = {}
    for idx in np.ndindex(*shape):
        name = "r_" + "_".join(str(i) for i in idx)
        params = [v for a, i in enumerate(idx) for v in tri[a][i]]
        rules[name] = {"membership": ["triangular"] * len(premises), "membership_params": params,
                       "natural_frequency": [float(x) for x in om[idx]],
                       "damping_ratio": [float(x) for x in ze[idx]]}
    rng = [v for a in keep_axes for v in (float(axes[a][0]), float(axes[a][-1]))] if keep_axes else []
    spec = {"premises": premises, "rules": rules, "range": rng, "family": family, "interpolation": "modes"}
    return spec, notes


def fallback(results: Sequence[PoseResult], family: str = "zv") -> tuple[Shaper, PoseResult]:
    """The family's shaper on the home pose's modes (the first pose of the plan)."""
    home = results[0] if results else None
    if home is None or not home.modes:
        raise PlanError("the home pose has no identified mode: no fallback shaper")
    return design(family, [m.mode for m in home.modes]), home


def predicted_residual(shaper: Shaper, modes: Sequence[ModeFit]) -> float:
    """Percentage vibration the shaper leaves on the modes, weighted by their amplitudes (fraction)."""
    if not modes:
        return math.nan
    w = np.array([m.amplitude for m in modes])
    v = np.array([float(percentage_vibration(shaper.amplitudes, shaper.times, m.omega, m.zeta)) for m in modes])
    return float(np.sqrt(np.sum((w * v) ** 2) / np.sum(w**2)))


def worst_residual(shaper: Shaper, modes: Sequence[ModeFit], sigmas: float = 2.0) -> float:
    """The largest percentage vibration over the modes' +-sigmas uncertainty box (fraction)."""
    from shaper_nodes.core.identification.recommend import worst_case_vibration

    return worst_case_vibration(shaper, modes, sigmas)[1] if modes else math.nan
