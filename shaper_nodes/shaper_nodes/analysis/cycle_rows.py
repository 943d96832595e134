"""The analysis per cycle: where its cycles are (cycle events, else the motion), when the positions come to
rest after each move (the residual window's start), and each cycle's figures (:class:`CycleRow`): the residual
vibration, RMS and peak of the tip acceleration from rest until the cycle's end
(:func:`shaper_nodes.core.cycles.evaluate_cycle`), the settling time into a band, the shaper that was active.
Split out of :mod:`.analyze`, which runs these steps and re-exports their names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from shaper_nodes.core.cycles import evaluate_cycle
from shaper_nodes.core.shaping import settle_time, settling_time
from shaper_nodes.recordings import BagError

from .segment import GAP_FACTOR, REST_FRACTION, CycleSpan, from_events, from_motion, position_noise
from .streams import Recording, Signal

if TYPE_CHECKING:
    from .options import Options

#: added to a cycle's shaper label when another shaper became active before its END
CHANGED_DURING = " (changed during the cycle)"
#: with remove_mean "auto", a median acceleration larger than this (m/s^2) is an offset (gravity, bias)
OFFSET_LIMIT = 1.0
#: positions within this many noise standard deviations (or two quantisation steps) of their final
#: value are at rest (the residual window's start), whatever smaller --settle-tolerance says
SETTLE_SIGMAS = 10.0
#: positions within this of their final value are at rest (rad or m), raised to the positions' noise floor
DEFAULT_SETTLE_TOLERANCE = 1e-6
#: the settling band is at least this many accelerometer noise standard deviations (per axis)
BAND_SIGMAS = 6.0


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


def _segment(rec: Recording, opt: Options) -> tuple[list[CycleSpan], str, list[str]]:
    if opt.segmentation not in ("auto", "events", "motion"):
        raise BagError(f"segmentation must be auto, events or motion, got {opt.segmentation!r}")
    if opt.segmentation != "motion" and rec.events.kind:
        spans, notes = from_events(rec.events, float(np.min(rec.accel.t)) if len(rec.accel.t) else None)
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
