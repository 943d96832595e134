"""The analysis over the bag: the spectrum of the residual windows, the modes of each group of cycles that
see the same plant, which group the modes and the recommendation are for (:func:`main_group`: the unshaped
cycles first), the recommended shaper and its predicted residual, and the headline where the modes change
(:func:`plant_changes`). Split out of :mod:`.analyze`, which runs these steps and re-exports their names.
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

import numpy as np

from shaper_nodes.core.identification import (
    IdentificationError,
    ModeFit,
    Recommendation,
    combine_modes,
    identify,
    recommend_shaper,
    ringing_issue,
)
from shaper_nodes.core.shaping import Shaper, percentage_vibration

from .cycle_rows import CHANGED_DURING, CycleRow
from .groups import GROUP_GAP, GROUP_SIGMAS, MIN_SHARE, ModeGroup, _ranges, group_cycles

if TYPE_CHECKING:
    from .options import Options
    from .outcome import Analysis

#: active shapers that let through at least this V count for the unshaped level
MIN_V_FOR_LEVEL = 0.2
#: fewest samples of a residual window used for the spectrum
MIN_SPECTRUM_SAMPLES = 64

def _unshaped(row: CycleRow) -> bool:
    """The cycle ran with no shaper (family "none" active throughout), so it shows every mode."""
    return row.shaper.split(" ")[0] == "none" and not row.shaper.endswith(CHANGED_DURING)


def main_group(groups: list[ModeGroup], rows: list[CycleRow]) -> tuple[ModeGroup | None, str]:
    """The group whose modes, recommendation and prediction the analysis gives, and a note on the choice.

    A shaper hides the modes it cancels, so the group with the most unshaped cycles (active shaper
    "none") comes first, then the largest, ties the latest: on a recording of one cycle per shaper
    (the demo's) that is the unshaped cycle, not the last shaped one. With cycles that ran shaped
    only (the shaper recorded), the note says the modes are what the shapers let through."""
    if not groups:
        return None, ""
    main = max(reversed(groups), key=lambda g: (sum(_unshaped(rows[i]) for i in g.rows), len(g.rows)))
    largest = max(reversed(groups), key=lambda g: len(g.rows))
    if main is not largest:
        return main, (f"modes and recommendation from the unshaped cycles #{_ranges(main.rows)}, not the"
                      f" {len(largest.rows)} shaped cycle(s) #{_ranges(largest.rows)}: a shaper hides the modes"
                      " it cancels")
    if any(r.shaper != "unknown" for r in rows) and not any(_unshaped(r) for r in rows):
        return main, ("every cycle ran with a shaper, which hides the modes it cancels: the modes are those"
                      " the shapers let through; record a few cycles with the shaper 'none' to see them all")
    return main, ""


def plant_changes(an: Analysis, main: ModeGroup | None) -> list[str]:
    """The headline when the cycles see several plants: where the modes change (groups that follow each
    other in time: a payload, tool or pose change), from which ringing modes to which, and whose modes
    the recommendation is for; when the groups alternate, that the cycles see several plants. Nothing
    for one group. Where the cycles on either side of a change ran with different shapers the line
    says so instead of naming a plant change: a shaper hides the modes it cancels (the arm demo's
    recording: unshaped, then the calibrated ZV, which leaves only the lowest mode)."""
    groups = sorted(an.groups, key=lambda g: g.rows[0])
    if len(groups) < 2:
        return []

    def ringing(g: ModeGroup) -> list[ModeFit]:
        return sorted((m for m in g.modes if not an.ringing_issue(m)), key=lambda m: m.omega) or list(g.modes)

    def hz(modes: list[ModeFit]) -> str:
        return " / ".join(f"{m.hz:.4g}" for m in modes) + " Hz"

    whom = (f"; modes and recommendation below are for cycles #{_ranges(main.rows)} ({hz(ringing(main))})"
            if main is not None else "")
    contiguous = all(g.rows == list(range(g.rows[0], g.rows[-1] + 1)) for g in groups)
    if not contiguous:
        return [f"THE CYCLES SEE {len(groups)} DIFFERENT PLANTS (poses or payloads that alternate): "
                + "; ".join(f"cycles #{_ranges(g.rows)}: {hz(ringing(g))}" for g in groups) + whom]
    out = []
    for a, b in itertools.pairwise(groups):
        ma, mb = ringing(a), ringing(b)
        lo = 100.0 * (mb[0].hz / ma[0].hz - 1.0)
        before, after = an.cycles[a.rows[-1]], an.cycles[b.rows[0]]
        shapers = [r.shaper.removesuffix(CHANGED_DURING) for r in (before, after)]
        what = ("PLANT CHANGE", "(a payload, tool or pose change)")
        if "unknown" not in shapers and shapers[0] != shapers[1]:
            what = ("MODES CHANGE", f"with the shaper ({shapers[0]} -> {shapers[1]}: a shaper hides the modes it"
                    " cancels, so this need not be a payload, tool or pose change)")
        out.append(f"{what[0]} between cycle {before.cycle} and cycle {after.cycle} {what[1]}:"
                   f" modes {hz(ma)} -> {hz(mb)} (lowest {lo:+.1f} %)")
    if out:
        out[-1] += whom
    return out


def _recommend(rows: list[CycleRow], modes: list[ModeFit], opt: Options, notes: list[str], accel_noise: float
               ) -> tuple[Recommendation | None, float, dict]:
    """The recommended shaper, the unshaped level (m/s^2) and the prediction for the identified ``modes``
    (None, NaN and nothing without modes); sets each row's V of its active shaper at the first mode that
    rings (the first mode if none does). ``accel_noise``: per axis, m/s^2."""
    if not modes:
        return None, float("nan"), {}
    recommendation = None
    noise = accel_noise if math.isfinite(accel_noise) else 0.0
    top = next((m for m in modes if not ringing_issue(m, opt.max_damping, noise, opt.noise_sigmas)), modes[0])
    for r in rows:
        if r.shaper_impulses is not None:
            r.v_active = float(percentage_vibration(np.asarray(r.shaper_impulses[0], dtype=float),
                                                    np.asarray(r.shaper_impulses[1], dtype=float), top.omega,
                                                    top.zeta))
    try:
        recommendation = recommend_shaper(modes, opt.target, sigmas=opt.sigmas, min_saving=opt.min_saving,
                                          max_damping=opt.max_damping, noise=noise, noise_sigmas=opt.noise_sigmas)
        notes += list(recommendation.notes)
    except IdentificationError as err:
        notes.append(f"no recommendation: {err}")
    level, predicted = _prediction(rows, modes, recommendation, opt)
    if predicted.get("note"):
        notes.append(predicted["note"])
    return recommendation, level, predicted


def _spectrum(windows: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray] | None:
    from scipy.signal import welch

    usable = [(t, a) for t, a in windows if t.size >= MIN_SPECTRUM_SAMPLES]
    if not usable:
        return None
    dt = float(np.median(np.concatenate([np.diff(t) for t, _ in usable])))
    nper = min(min(t.size for t, _ in usable), 8192)  # the shortest window: one segment of it
    nfft = 1 << int(math.ceil(math.log2(8 * nper)))  # zero-padded, for a smooth curve
    psds = []
    for _, a in usable:
        f, p = welch(a - a.mean(axis=0), fs=1.0 / dt, nperseg=nper, nfft=nfft, axis=0)
        psds.append(p.reshape(p.shape[0], -1).sum(axis=1))
    return f, np.mean(psds, axis=0)


def _identify(windows, rows: list[CycleRow], opt: Options, accel_noise: float = 0.0
              ) -> tuple[list[ModeGroup], list[str]]:
    """The groups of cycles that see the same modes (:func:`~.groups.group_cycles`), each with its modes
    combined over its cycles, and notes; no group when no cycle gives a mode."""
    per_record: list[tuple[int, list[ModeFit]]] = []
    failed = []
    usable = [i for i, (t, _) in enumerate(windows) if t.size]
    notes = []
    if opt.identify_cycles and len(usable) > opt.identify_cycles:
        pick = np.unique(np.round(np.linspace(0, len(usable) - 1, opt.identify_cycles)).astype(int))
        notes.append(f"identification: {pick.size} of {len(usable)} cycles, evenly spread (--identify-cycles)")
        usable = [usable[i] for i in pick]
    for i in usable:
        (t, a), r = windows[i], rows[i]
        try:
            per_record.append((i, identify(t, a, method=opt.method, max_modes=opt.max_modes, band_hz=opt.band_hz)))
        except IdentificationError as err:
            failed.append(f"cycle {r.cycle}: {err}")
    if failed:
        notes.append(f"identification: {len(failed)} of {len(failed) + len(per_record)} cycles give no mode"
                     f" (left out): " + "; ".join(failed[:5]) + (" ..." if len(failed) > 5 else ""))
    if not per_record:
        notes.append("no mode identified in any cycle")
        return [], notes
    found = dict(per_record)
    groups = []
    noise = accel_noise if math.isfinite(accel_noise) else 0.0
    for keys in group_cycles(per_record, max_damping=opt.max_damping, noise=noise, noise_sigmas=opt.noise_sigmas):
        keys = sorted(keys)
        modes = combine_modes([found[k] for k in keys], method=opt.method, max_modes=opt.max_modes)
        groups.append(ModeGroup(keys, [rows[k].cycle for k in keys], modes))
    if len(groups) > 1:
        notes.append(f"the cycles see different modes (several plants, payloads or poses): {len(groups)} groups,"
                     f" a cycle is another's plant when each has every ringing mode of the other (at least"
                     f" {100 * MIN_SHARE:g} % of its strongest) within {100 * GROUP_GAP:g} % or {GROUP_SIGMAS:g}"
                     " combined sigma: "
                     + "; ".join(g.label for g in groups)
                     + ". Modes, recommendation and prediction are one group's (the most unshaped cycles, then the"
                     " largest); each group's are listed")
    for g in groups:
        if not g.modes:
            notes.append(f"group of cycles {g.cycles}: no mode found in at least half of its cycles")
    return [g for g in groups if g.modes], notes


def _group_recommendation(modes: list[ModeFit], opt: Options, accel_noise: float) -> Recommendation | None:
    try:
        return recommend_shaper(modes, opt.target, sigmas=opt.sigmas, min_saving=opt.min_saving,
                                max_damping=opt.max_damping, noise=accel_noise if math.isfinite(accel_noise) else 0.0,
                                noise_sigmas=opt.noise_sigmas)
    except IdentificationError:
        return None


def _prediction(rows: list[CycleRow], modes: list[ModeFit], rec: Recommendation | None, opt: Options
                ) -> tuple[float, dict]:
    rows = [r for r in rows if not r.issue]
    usable = [r.rms / r.v_active for r in rows
              if r.samples and np.isfinite(r.v_active) and r.v_active >= MIN_V_FOR_LEVEL and np.isfinite(r.rms)]
    if not usable:
        assumed = [r.rms for r in rows if r.shaper == "unknown" and r.samples and np.isfinite(r.rms)]
        if not assumed:
            return float("nan"), {"note": "no cycle lets enough vibration through (V >= 0.2) to estimate the"
                                          " unshaped level: no predicted residual vibration"}
        usable = assumed
        note = "the active shaper is not recorded: the cycles are taken as unshaped for the predicted level"
    else:
        note = ""
    level = float(np.median(usable))
    out: dict = {"unshaped_rms": level, "note": note, "cycles_used": len(usable)}
    if rec is not None and rec.best is not None:
        out.update(family=rec.best.family, v_nominal=rec.best.nominal_vibration, v_worst=rec.best.worst_vibration,
                   rms_nominal=level * rec.best.nominal_vibration, rms_worst=level * rec.best.worst_vibration)
    return level, out


def shaper_of(candidate_shaper: Shaper) -> dict:
    """Impulses of a shaper, for reports."""
    return {"family": candidate_shaper.family, "amplitudes": [float(a) for a in candidate_shaper.amplitudes],
            "times": [float(t) for t in candidate_shaper.times], "duration": float(candidate_shaper.duration)}
