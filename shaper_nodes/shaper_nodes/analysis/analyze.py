"""The analysis of a recording: per cycle, over the bag, and what the learners would have done.

Per cycle (:class:`CycleRow`): the residual vibration, RMS and peak of the tip acceleration
magnitude from the time the positions have come to rest after the motion until the cycle's end
(:func:`shaper_nodes.core.cycles.evaluate_cycle`, the measure every component of the suite
uses), the settling time of the acceleration into a band, and the shaper that was active.

Over the bag: the spectrum of the residual windows (Welch, averaged over cycles); the modes,
identified in every cycle's residual window (:func:`~shaper_nodes.core.identification.identify`)
and combined across cycles (cycles in which no mode stands out of the noise, e.g. well shaped
ones, are left out with a note); the recommended shaper
(:func:`~shaper_nodes.core.identification.recommend_shaper`, on the modes that ring only: a mode
damped above ``Options.max_damping`` or at the accelerometer's noise floor is reported but not
designed on, and without a ringing mode the verdict is "no shaper needed") and its predicted residual
vibration: for a linear plant the residual of a cycle is the unshaped residual times the
percentage vibration V of the shaper at the mode, so the unshaped level U is estimated as the
median of RMS / V_active over the cycles whose active shaper lets V >= 0.2 through, and the
prediction is U V_recommended (at the identified mode and at the worst point of its uncertainty
box), on top of which comes the sensor noise.

Learner replays: those of :data:`~.replay.LEARNER_REPLAYS` that the options ask for
(:mod:`.replay`: LIST and MRILC fed the recording as the live nodes are fed).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from shaper_nodes.core.cycles import evaluate_cycle
from shaper_nodes.core.identification import (
    MAX_RINGING_DAMPING,
    NOISE_FLOOR_SIGMAS,
    IdentificationError,
    ModeFit,
    Recommendation,
    combine_modes,
    identify,
    recommend_shaper,
    ringing_issue,
)
from shaper_nodes.core.shaping import Shaper, percentage_vibration, settle_time, settling_time
from shaper_nodes.recordings import BagError

from .groups import GROUP_GAP, GROUP_SIGMAS, MIN_SHARE, ModeGroup, _ranges, group_cycles
from .replay import LEARNER_REPLAYS, LearnerReplay
from .segment import GAP_FACTOR, REST_FRACTION, CycleSpan, from_events, from_motion, position_noise
from .streams import Recording, Signal

if TYPE_CHECKING:
    pass

#: added to a cycle's shaper label when another shaper became active before its END
CHANGED_DURING = " (changed during the cycle)"
#: active shapers that let through at least this V count for the unshaped level
MIN_V_FOR_LEVEL = 0.2
#: with remove_mean "auto", a median acceleration larger than this (m/s^2) is an offset (gravity, bias)
OFFSET_LIMIT = 1.0
#: fewest samples of a residual window used for the spectrum
MIN_SPECTRUM_SAMPLES = 64
#: positions within this many noise standard deviations (or two quantisation steps) of their final
#: value are at rest (the residual window's start), whatever smaller --settle-tolerance says
SETTLE_SIGMAS = 10.0
#: positions within this of their final value are at rest (rad or m), raised to the positions' noise floor
DEFAULT_SETTLE_TOLERANCE = 1e-6
#: the settling band is at least this many accelerometer noise standard deviations (per axis)
BAND_SIGMAS = 6.0


@dataclass(frozen=True)
class Options:
    """What the analysis is asked to do (the CLI's options).

    settle_tolerance : rad or m, positions at rest; band : settling band, m/s^2 (a float) or
    a fraction of the cycle's peak (a string ending in %); remove_mean : "auto", "yes", "no";
    segmentation : "auto", "events", "motion"; method, max_modes, band_hz : identification;
    target, sigmas, min_saving : recommendation (:func:`recommend_shaper`); max_damping : damping ratio
    above which an identified mode does not ring (default :data:`MAX_RINGING_DAMPING`, 0.3), and
    noise_sigmas : a mode whose initial amplitude is at most this many accelerometer noise standard
    deviations (per axis, measured on the recording) is at the noise floor (default
    :data:`NOISE_FLOOR_SIGMAS`, 1): such modes are reported but neither designed on nor used to choose
    the shaper, and a group of cycles with no ringing mode gets "no shaper needed"; identify_cycles : most
    cycles identified (evenly spread over the usable ones; 0 = all); learners : names of
    :data:`LEARNER_REPLAYS` to run; learner_params : parameters as the live learner node takes
    them; motion_threshold : speed (rad/s or m/s) above which a sample moves when the cycles come
    from the motion (default: from the top speed and the measured noise).
    """

    settle_tolerance: float | None = None
    band: str = "5%"
    remove_mean: str = "auto"
    segmentation: str = "auto"
    positions: str = "auto"
    method: str = "fit"
    max_modes: int = 3
    band_hz: tuple[float, float] | None = None
    target: float = 0.05
    sigmas: float = 2.0
    identify_cycles: int = 20
    learners: tuple[str, ...] = ("list", "mrilc")
    learner_params: Mapping[str, object] = field(default_factory=dict)
    motion_threshold: float | None = None
    min_saving: float = 0.2
    max_damping: float = MAX_RINGING_DAMPING
    noise_sigmas: float = NOISE_FLOOR_SIGMAS


@dataclass
class CycleRow:
    """One cycle's figures: times in s, vibration in m/s^2."""

    cycle: int
    start: float
    motion_end: float
    window_start: float
    end: float
    rms: float
    peak: float
    samples: int
    settling_time: float
    shaper: str
    shaper_impulses: tuple[tuple[float, ...], tuple[float, ...]] | None
    complete: bool = True
    v_active: float = float("nan")  # V of the active shaper at the identified mode
    issue: str = ""  # why the cycle is not used over the bag ("" if it is)


@dataclass
class Analysis:
    recording: Recording
    options: Options
    segmentation: str
    cycles: list[CycleRow]
    traces: list[tuple[np.ndarray, np.ndarray]]  # per cycle: time from START (s), acceleration (N, 3)
    spectrum: tuple[np.ndarray, np.ndarray] | None  # Hz, (m/s^2)^2/Hz
    modes: list[ModeFit]
    recommendation: Recommendation | None
    unshaped_level: float
    predicted: dict
    replays: dict[str, LearnerReplay]
    notes: list[str]
    removed_mean: bool
    groups: list[ModeGroup] = field(default_factory=list)  # several when cycles see different modes
    settle_tolerance: float = float("nan")  # positions at rest within this (rad or m), as used
    accel_noise: float = float("nan")  # accelerometer noise per axis, m/s^2 (third differences' MAD)
    headline: list[str] = field(default_factory=list)  # what changed between groups of cycles, first in reports

    def ringing_issue(self, mode: ModeFit) -> str:
        """Why ``mode`` is not used for the shaper ("" if it is): it does not ring (damping ratio above
        ``options.max_damping``) or is at the noise floor (see :class:`Options`)."""
        return ringing_issue(mode, self.options.max_damping, self.accel_noise if math.isfinite(self.accel_noise)
                             else 0.0, self.options.noise_sigmas)

    @property
    def origin(self) -> float:
        """Whole second at or before the first accelerometer sample: reports give times from it, s."""
        return float(math.floor(self.recording.accel.t[0]))


def analyze(rec: Recording, options: Options | None = None) -> Analysis:
    """Analyse an extracted recording (see the module docstring).

    Raises
    ------
    BagError
        No cycle could be found (no events and no motion), or bad options.
    """
    opt = options or Options()
    notes = list(rec.notes)
    spans, segmentation, seg_notes = _segment(rec, opt)
    notes += seg_notes
    if not spans:
        raise BagError(f"{rec.path}: no cycles found ({'; '.join(seg_notes) or 'no cycle events and no motion'})")
    acc = rec.accel
    remove_mean = _remove_mean(acc.values, opt.remove_mean)
    if remove_mean and opt.remove_mean == "auto":
        notes.append(f"the accelerometer has an offset of {np.linalg.norm(np.nanmedian(acc.values, axis=0)):.3g} m/s^2"
                     " (gravity, bias): each window's mean is removed")
    tolerance, accel_noise, noise_notes = _noise(rec, opt)
    notes += noise_notes
    rows, traces, windows = _cycles(rec, spans, opt, remove_mean, tolerance, accel_noise, notes)
    for i, r in enumerate(rows):
        if r.issue:
            notes.append(f"cycle {r.cycle} (#{i}): {r.issue}; left out of the modes and the prediction")
    spectrum = _spectrum(windows)
    groups, id_notes = _identify(windows, rows, opt, accel_noise)
    notes += id_notes
    main, main_note = main_group(groups, rows)
    if main_note:
        notes.append(main_note)
    modes = main.modes if main is not None else []
    if len(groups) > 1:
        for g in groups:
            g.recommendation = _group_recommendation(g.modes, opt, accel_noise)
    recommendation, level, predicted = _recommend(rows if main is None or len(groups) == 1
                                                  else [rows[i] for i in main.rows], modes, opt, notes, accel_noise)
    if main is not None:
        main.recommendation = recommendation
    replays = _replays(rec, spans, segmentation, opt, notes)
    out = Analysis(rec, opt, segmentation, rows, traces, spectrum, modes, recommendation, level, predicted,
                   replays, notes, remove_mean, groups, tolerance, accel_noise)
    out.headline = plant_changes(out, main)
    return out


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


# ------------------------------------------------------------------------------ pieces
def _segment(rec: Recording, opt: Options) -> tuple[list[CycleSpan], str, list[str]]:
    if opt.segmentation not in ("auto", "events", "motion"):
        raise BagError(f"segmentation must be auto, events or motion, got {opt.segmentation!r}")
    if opt.segmentation != "motion" and rec.events.kind:
        spans, notes = from_events(rec.events)
        return spans, f"cycle events ({rec.topics['events']})", notes
    if opt.segmentation == "events":
        raise BagError(f"{rec.path}: no cycle events (shaper_msgs/msg/CycleEvent) to segment by")
    source = rec.commands if rec.commands is not None and len(rec.commands) > 2 else rec.joints
    if source is None:
        return [], "", ["no cycle events, and no commands or joint states to find the moves in"]
    spans, notes = from_motion(source, end_time=float(rec.accel.t[-1]), threshold=opt.motion_threshold)
    kind = "commands" if source is rec.commands else "joint states"
    return spans, f"motion end of the {kind} ({source.topic})", notes


def _positions(rec: Recording, opt: Options) -> Signal | None:
    """Where the time the positions come to rest is taken from: the joint states, else the commands."""
    if opt.positions == "commands" or (opt.positions == "auto" and rec.joints is None):
        return rec.commands
    return rec.joints


def _noise(rec: Recording, opt: Options) -> tuple[float, float, list[str]]:
    """The rest tolerance of the positions (rad or m), the accelerometer noise per axis (m/s^2) and notes.

    The tolerance is ``--settle-tolerance``, raised to :data:`SETTLE_SIGMAS` times the positions'
    measured noise (or two quantisation steps) when they are noisier
    (:func:`~.segment.position_noise`); the accelerometer noise is the same estimate on its axes.
    """
    notes: list[str] = []
    tolerance = DEFAULT_SETTLE_TOLERANCE if opt.settle_tolerance is None else float(opt.settle_tolerance)
    pos = _positions(rec, opt)
    if pos is not None and len(pos) >= 8:
        noise = position_noise(pos.values)
        floor = float(max(np.max(SETTLE_SIGMAS * noise.sigma), np.max(2.0 * noise.step)))
        if floor > tolerance:
            notes.append(f"{pos.topic}: position noise {float(np.max(noise.sigma)):.2g}"
                         + f", smallest step {float(np.max(noise.step)):.2g} (rad or m): positions count as at rest"
                         f" within {floor:.2g} of their final value ({SETTLE_SIGMAS:g} sigma or 2 steps;"
                         f" --settle-tolerance {tolerance:g} is below the noise)")
            tolerance = floor
    acc_noise = float(np.max(position_noise(rec.accel.values).sigma)) if len(rec.accel) >= 8 else 0.0
    if acc_noise > 0:
        notes.append(f"settling band: the larger of --band {opt.band} and {BAND_SIGMAS * acc_noise:.2g} m/s^2"
                     f" ({BAND_SIGMAS:g} x the accelerometer noise {acc_noise:.2g} m/s^2 per axis, from its third"
                     " differences), so that a cycle that reaches the noise floor settles")
    return tolerance, acc_noise, notes


def _cycles(rec: Recording, spans: list[CycleSpan], opt: Options, remove_mean: bool, tolerance: float,
            accel_noise: float, notes: list[str]
            ) -> tuple[list[CycleRow], list[tuple[np.ndarray, np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]:
    """Per cycle: its figures, its trace (time from START in s, acceleration in m/s^2) and its residual
    window (time in s, acceleration in m/s^2; empty for a cycle with an issue). Positions are at rest
    within ``tolerance`` (rad or m); the settling band is at least :data:`BAND_SIGMAS` times
    ``accel_noise`` (m/s^2)."""
    acc = rec.accel
    pos = _positions(rec, opt)
    step = float(np.median(np.diff(acc.t))) if len(acc) > 1 else 0.0
    rows: list[CycleRow] = []
    traces: list[tuple[np.ndarray, np.ndarray]] = []
    windows: list[tuple[np.ndarray, np.ndarray]] = []
    floored: list[int] = []
    for span in spans:
        a0, a1 = np.searchsorted(acc.t, span.start, side="left"), np.searchsorted(acc.t, span.end, side="right")
        at, av = acc.t[a0:a1], acc.values[a0:a1]
        if pos is not None:
            p0, p1 = np.searchsorted(pos.t, span.start, "left"), np.searchsorted(pos.t, span.end, "right")
            pt, pv = pos.t[p0:p1], pos.values[p0:p1]
        else:
            pt, pv = np.zeros(0), np.zeros((0, 1))
        if opt.settle_tolerance is None:  # at rest: within the noise floor, or ringing about the final value
            rest = reached_rest(pt, pv, span.motion_end, tolerance)
            if len(pt) > 1 and rest >= float(pt[-1]):  # never: noise-free positions still creeping (elastic joints)
                size = float(np.nanmax(np.abs(pv[-1] - pv[0])))
                if REST_FRACTION * size > tolerance:
                    rest = reached_rest(pt, pv, span.motion_end, REST_FRACTION * size)
                    floored.append(span.cycle)
            res = evaluate_cycle(span.cycle, span.start, rest, span.end, at, av, np.zeros(0), np.zeros((0, 1)),
                                 tolerance, remove_mean).residual
        else:
            res = evaluate_cycle(span.cycle, span.start, span.motion_end, span.end, at, av, pt, pv,
                                 tolerance, remove_mean).residual
        band = max(_band(opt.band, res.peak), BAND_SIGMAS * accel_noise)
        settle = (settling_time(at, av, res.window_start, res.window_end, band, remove_mean)
                  if res.samples and band > 0 else float("nan"))
        label, impulses = _active_shaper(rec, span)
        issue = _cycle_issue(span, at, res.samples, step)
        rows.append(CycleRow(span.cycle, span.start, span.motion_end, res.window_start, span.end, res.rms,
                             res.peak, res.samples, settle, label, impulses, span.complete, issue=issue))
        traces.append((at - span.start, av))
        inside = (at >= res.window_start) & (at < res.window_end)  # as residual_vibration selects
        windows.append((at[inside], av[inside]) if not issue else (np.zeros(0), np.zeros((0, av.shape[1]))))
    if floored:
        notes.append(f"cycle(s) {', '.join(map(str, floored))}: the positions never came within {tolerance:.2g} of"
                     f" their final value (noise-free joints still creeping): at rest within {100 * REST_FRACTION:g} %"
                     " of the move's size instead (set --settle-tolerance to choose)")
    return rows, traces, windows


def reached_rest(times: np.ndarray, positions: np.ndarray, after: float, tolerance: float) -> float:
    """When the positions are at rest after a move, s: the earlier of (a) the time from which every joint
    stays within ``tolerance`` (rad or m) of its last value (:func:`settle_time`, the suite's rule) and
    (b) the first time by which every joint has come within ``tolerance`` of its last value or crossed it.

    (b) is the rule for positions that ring: an elastic structure pulls on the motors, so measured joint
    positions oscillate about their final value, decaying with the vibration itself, and never stay within
    a tolerance set by their noise until the vibration has gone. Once a joint has reached or crossed its
    final value, what is left of its motion is that ringing, not the move. ``times`` (N,) s,
    ``positions`` (N, J), ``after``: the motion's end, s.
    """
    t = np.asarray(times, dtype=float)
    if t.size == 0:  # no positions in the cycle (a recording without joint states): the motion's end
        return float(after)
    p = np.asarray(positions, dtype=float).reshape(t.size, -1)
    sel = t >= after
    t, p = t[sel], p[sel]
    if t.size == 0:
        return float(after)
    staying = settle_time(t, p, after, tolerance)
    d = p - p[-1]
    reached = (np.abs(d) <= tolerance) | (np.sign(d) != np.sign(d[0]))
    first = [int(np.argmax(col)) if col.any() else t.size - 1 for col in reached.T]
    return float(min(staying, max(float(after), float(t[max(first)]))))


def _cycle_issue(span: CycleSpan, at: np.ndarray, samples: int, step: float) -> str:
    """Why a cycle is left out over the bag ("" if it is not): no sample in its residual window, or a
    gap longer than :data:`GAP_FACTOR` median steps ``step`` (s) in its accelerometer times ``at`` (s)."""
    if samples == 0:
        return "no accelerometer sample in the residual window"
    if step > 0:
        edges = np.concatenate([[span.start], at, [span.end]])
        gap = float(np.max(np.diff(edges)))
        if gap > GAP_FACTOR * step:
            return f"a {gap:.3g} s gap in the accelerometer data"
    return ""


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


def _replays(rec: Recording, spans: list[CycleSpan], segmentation: str, opt: Options, notes: list[str]
             ) -> dict[str, LearnerReplay]:
    """learner name -> its replay, for the learners asked for (unknown ones are noted)."""
    replays: dict[str, LearnerReplay] = {}
    for name in opt.learners:
        fn = LEARNER_REPLAYS.get(name)
        if fn is None:
            notes.append(f"learner replay {name!r}: not available (known: {sorted(LEARNER_REPLAYS)})")
            continue
        replays[name] = fn(rec, spans, segmentation, opt.learner_params)
    return replays


def _remove_mean(values: np.ndarray, mode: str) -> bool:
    if mode in ("yes", "no"):
        return mode == "yes"
    if mode != "auto":
        raise BagError(f"remove_mean must be auto, yes or no, got {mode!r}")
    return bool(np.linalg.norm(np.nanmedian(values, axis=0)) > OFFSET_LIMIT)


def _band(spec: str, peak: float) -> float:
    text = str(spec).strip()
    try:
        if text.endswith("%"):
            return float(text[:-1]) / 100.0 * peak if math.isfinite(peak) else float("nan")
        return float(text)
    except ValueError:
        raise BagError(f"settling band must be a number (m/s^2) or a percentage of the peak, got {spec!r}") from None


def _active_shaper(rec: Recording, span: CycleSpan) -> tuple[str, tuple | None]:
    s = rec.shapers
    if not s.seq:
        return "unknown", None
    # by the time each became active (its stamp): messages logged at the same time (a lockstep
    # simulation's clock stands still between cycles) may come in either order in the recording
    before = [i for i, t in enumerate(s.t) if t <= span.start]
    during = [i for i, t in enumerate(s.t) if span.start < t < span.end]
    if not before:
        return "unknown", None
    i = before[-1]
    amps, times = s.amplitudes[i], s.times[i]
    label = (s.family[i] if len(amps) <= 1 or not times
             else f"{s.family[i]} ({len(amps)} imp., {1e3 * max(times):.1f} ms)")
    if s.source[i] and s.source[i] not in ("parameters", "user"):
        label += f" [{s.source[i]}]"
    if during:
        label += CHANGED_DURING
        return label, None
    return label, (amps, times)


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
                     + ". Modes, recommendation and prediction are the largest group's; each group's are listed")
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


# ------------------------------------------------------------------------------ learner replays
def shaper_of(candidate_shaper: Shaper) -> dict:
    """Impulses of a shaper, for reports."""
    return {"family": candidate_shaper.family, "amplitudes": [float(a) for a in candidate_shaper.amplitudes],
            "times": [float(t) for t in candidate_shaper.times], "duration": float(candidate_shaper.duration)}
