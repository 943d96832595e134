"""Cycles of a recording: from its cycle events, or from the motion of its commands.

With cycle events (shaper_msgs/CycleEvent) a cycle runs from START to END, its motion ending at
MOTION_END, as the task runner marked them. Without them (a robot's own recorder), cycles are
found in a position signal (the commands, else the joint states), with thresholds taken from the
signal's own noise (:func:`position_noise`):

1. the position noise sigma_p of each joint is the robust spread (MAD) of the third difference of
   its positions (zero for any piecewise-quadratic motion, so the moves do not count as noise),
   and at least the quantisation step's sqrt(1/12) when the positions come in steps;
2. the speed is a Savitzky-Golay derivative (quadratic, over :data:`SMOOTH_TIME` s, at least 5
   samples) of the positions; its noise sigma_v follows from sigma_p and the filter's weights;
   noiseless positions (commands) are differenced sample to sample instead;
3. a sample moves when some joint's speed exceeds ``max(MOTION_FRACTION x top speed,
   NOISE_SIGMAS x sigma_v)`` (top speed: the 99.5th percentile of the speeds, so a single spike
   does not set it), or ``threshold`` when given (``--motion-threshold``);
4. each run of moving samples is widened to where the positions leave and reach rest: the last
   sample before it (the first after it) within ``NOISE_SIGMAS x sigma_p`` (or one quantisation
   step) of the rest position next to it, or, where they never get within that band before the
   next move (noise-free positions of elastic joints still ringing from the move, as a simulator
   reports them), within :data:`REST_FRACTION` of the move's size (the note says how many edges took
   this band); runs closer than ``min_rest`` s are one move; moves
   whose largest joint displacement is below :data:`MIN_MOVE_FRACTION` of the largest move's are
   noise;
5. a cycle runs from the start of a move to the start of the next (the last to the end of the
   recording), and its motion ends when the move does.

When no move can be found the notes say why (positions constant, motion within the noise) and
which option to set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START, unseen_window

from .streams import Events, Signal

#: fraction of the top speed above which a sample counts as moving
MOTION_FRACTION = 0.01
#: a speed (position) more than this many noise standard deviations from rest is motion
NOISE_SIGMAS = 6.0
#: the speed is a Savitzky-Golay derivative over this long, s
SMOOTH_TIME = 0.04
#: third differences of white noise have 20 times its variance; MAD -> standard deviation
_MAD_TO_STD = 1.0 / (0.6744897501960817 * np.sqrt(20.0))
#: moves closer than this (s) are one move
MIN_REST = 0.05
#: a step longer than this many median steps is a gap in the data, not a move
GAP_FACTOR = 5.0
#: moves whose largest joint displacement is below this fraction of the largest move's are noise
MIN_MOVE_FRACTION = 0.01
#: where positions never come within their noise band of rest before the next move (an elastic joint
#: ringing in noise-free joint states), a move's edge is where they come within this fraction of its size
REST_FRACTION = 1e-3


@dataclass(frozen=True)
class CycleSpan:
    """One cycle: index, times (s), and its first and last positions in the recording's order.

    ``start_seq``/``motion_end_seq``/``end_seq`` are recording-order indices of the messages that
    mark the boundaries (the events, or the position samples), used to tell which active-shaper
    message was in force and to replay the boundaries into a learner in order.
    """

    cycle: int
    start: float
    motion_end: float
    end: float
    start_seq: int
    motion_end_seq: int
    end_seq: int
    start_positions: tuple[float, ...] = ()
    goal_positions: tuple[float, ...] = ()
    complete: bool = True


def from_events(events: Events, first_sample: float | None = None) -> tuple[list[CycleSpan], list[str]]:
    """Cycles from the events in recording order; notes on events that do not pair up.

    A cycle whose START the recording missed (the recorder's side of the match came late) starts at the stamp its
    MOTION_END or END carries (``start_stamp``), placed at that event in the recording's order, if the recording's
    accelerometer samples (from ``first_sample`` s; None: not checked) reach back to it
    (:class:`~shaper_nodes.core.cycles.MissedStarts`); without the stamp it is left out, as before."""
    spans: list[CycleSpan] = []
    notes: list[str] = []
    order = np.argsort(np.asarray(events.seq), kind="stable")
    current: dict | None = None
    starts = events.start_stamp  # shorter than kind for events decoded with an older definition
    unseen_cycle: int | None = None  # the cycle left out as not seen from its START (its later events too)
    for i in order:
        kind, cyc, t, seq = events.kind[i], events.cycle[i], events.t[i], events.seq[i]
        start = starts[i] if i < len(starts) and np.isfinite(starts[i]) else None
        if kind != START and cyc == unseen_cycle:
            continue
        if kind != START and (current is None or cyc != current["cycle"]) and start is not None:
            unseen = unseen_window(start, first_sample) if first_sample is not None else ""
            if current is not None:
                notes.append(f"cycle {current['cycle']}: no END before the next START; left out")
            current = None
            if unseen:
                notes.append(f"cycle {cyc}: {unseen}; left out")
                unseen_cycle = cyc
                continue
            notes.append(f"cycle {cyc}: START not in the recording; stood in for by the"
                         f" {'END' if kind == END else 'MOTION_END'}'s start stamp ({start:.3f} s)")
            current = {"cycle": cyc, "start": start, "seq": seq, "me": None, "me_seq": seq,
                       "sp": events.start[i], "gp": events.goal[i]}
        if kind == START:
            if current is not None:
                notes.append(f"cycle {current['cycle']}: no END before the next START; left out")
            current = {"cycle": cyc, "start": t, "seq": seq, "me": None, "me_seq": seq,
                       "sp": events.start[i], "gp": events.goal[i]}
        elif current is None or cyc != current["cycle"]:
            notes.append(f"cycle {cyc}: {'END' if kind == END else 'MOTION_END'} without its START; left out")
        elif kind == MOTION_END:
            current["me"], current["me_seq"] = t, seq
        elif kind == END:
            me = current["me"]
            if me is None:
                notes.append(f"cycle {cyc}: no MOTION_END; the residual window starts at START")
                me = current["start"]
            spans.append(CycleSpan(cyc, current["start"], me, t, current["seq"], current["me_seq"], seq,
                                   current["sp"], current["gp"]))
            current = None
    if current is not None:
        notes.append(f"cycle {current['cycle']}: the recording ends before its END; left out")
    return spans, notes


@dataclass(frozen=True)
class PositionNoise:
    """Noise of a position signal, per joint: standard deviation (rad or m) and quantisation step.

    ``sigma`` comes from the third differences (:func:`position_noise`); ``step`` is the smallest
    change between two samples (rad or m; 0 if they never change), ``quantised`` whether the
    positions come in such steps (an encoder's); ``scale`` is the larger of ``sigma`` and, when
    quantised, ``step / sqrt(12)``.
    """

    sigma: np.ndarray
    step: np.ndarray
    quantised: np.ndarray

    @property
    def scale(self) -> np.ndarray:
        return np.maximum(self.sigma, np.where(self.quantised, self.step, 0.0) / np.sqrt(12.0))


def position_noise(values: np.ndarray) -> PositionNoise:
    """Position noise per joint of samples ``values`` (N, J) (rad or m), robust to the motion.

    sigma: median absolute third difference / (0.6745 sqrt(20)) (white noise of standard deviation
    s has third differences of standard deviation s sqrt(20); a piecewise-quadratic motion has none
    except at its switching points). step: the smallest non-zero first difference; quantised: at
    least a fifth of the non-zero first differences are that step (an encoder toggling at rest).
    """
    p = np.asarray(values, dtype=float)
    p = p.reshape(p.shape[0], -1)
    sig = np.zeros(p.shape[1])
    step = np.zeros(p.shape[1])
    quantised = np.zeros(p.shape[1], dtype=bool)
    for j in range(p.shape[1]):
        col = p[:, j][np.isfinite(p[:, j])]
        if col.size >= 8:
            d3 = np.diff(col, 3)
            sig[j] = float(np.median(np.abs(d3 - np.median(d3)))) * _MAD_TO_STD
            d1 = np.abs(np.diff(col))
            scale = max(float(np.max(np.abs(col))), 1e-300)
            nz = d1[d1 > 1e-12 * scale]
            if nz.size:
                step[j] = float(np.min(nz))
                quantised[j] = nz.size >= 8 and bool(np.mean(np.abs(nz - step[j]) < 0.01 * step[j]) >= 0.2)
    return PositionNoise(sig, step, quantised)


def _speed(t: np.ndarray, p: np.ndarray, ok: np.ndarray, noise: PositionNoise
           ) -> tuple[np.ndarray, float, int]:
    """Per-step speed (max over joints, rad/s or m/s), its noise standard deviation and the window.

    Step i spans samples i..i+1. Noiseless positions: differences sample to sample (window 1).
    Otherwise a quadratic Savitzky-Golay derivative over :data:`SMOOTH_TIME` s (odd, >= 5 samples)
    taken at the step's midpoint (average of its two samples' derivatives).
    """
    from scipy.signal import savgol_coeffs, savgol_filter

    dt = np.diff(t)
    med = float(np.median(dt[ok])) if ok.any() else 1.0
    speed = np.zeros(dt.size)
    scale = noise.scale
    if not np.any(scale > 0) or t.size < 7:
        speed[ok] = np.nanmax(np.abs(np.diff(p, axis=0)[ok]) / dt[ok, None], axis=1)
        return speed, 0.0, 1
    n = max(5, int(round(SMOOTH_TIME / med)) | 1)
    n = min(n, (t.size - 1) | 1 if t.size % 2 == 0 else t.size)
    n = n if n % 2 else n - 1
    deriv = savgol_filter(p, n, 2, deriv=1, delta=med, axis=0, mode="interp")
    mid = 0.5 * (np.abs(deriv[:-1]) + np.abs(deriv[1:]))
    speed[ok] = np.nanmax(mid[ok], axis=1)
    gain = float(np.sqrt(np.sum(savgol_coeffs(n, 2, deriv=1, delta=med) ** 2)))
    return speed, float(np.max(scale)) * gain, n


def from_motion(signal: Signal, end_time: float | None = None, threshold: float | None = None,
                min_rest: float = MIN_REST) -> tuple[list[CycleSpan], list[str]]:
    """Cycles from the motion of a position signal (see the module docstring).

    Parameters
    ----------
    signal : Signal
        Positions (rad or m) over time (s), one column per joint.
    end_time : float, optional
        End of the last cycle, s (default: the signal's last sample).
    threshold : float, optional
        Speed (rad/s or m/s) above which a sample moves (default: from the top speed and the noise).
    min_rest : float
        Rests shorter than this (s) do not split a move.
    """
    t, p = signal.t, signal.values
    notes: list[str] = []
    if t.size < 3 or p.shape[1] == 0:
        return [], [f"{signal.topic}: too few position samples to find moves"]
    dt = np.diff(t)
    ok = dt > 0
    ok &= dt <= GAP_FACTOR * float(np.median(dt[ok])) if ok.any() else ok  # a step across a gap is no move
    noise = position_noise(p)
    speed, speed_noise, window = _speed(t, p, ok, noise)
    top = float(np.nanpercentile(speed[ok], 99.5)) if ok.any() else 0.0
    auto = max(MOTION_FRACTION * top, NOISE_SIGMAS * speed_noise)
    thr = float(threshold) if threshold is not None else auto
    how = (f"--motion-threshold {thr:.3g}/s" if threshold is not None else
           f"max({100 * MOTION_FRACTION:g} % of the top speed {top:.3g}/s, {NOISE_SIGMAS:g} x the speed noise"
           f" {speed_noise:.2g}/s from a position noise of {float(np.max(noise.scale)):.2g})")
    if not top > 0.0 or not np.isfinite(thr):
        return [], [f"{signal.topic}: the positions never change: no moves"]
    if threshold is None and top <= NOISE_SIGMAS * speed_noise:
        return [], [f"{signal.topic}: no motion stands out of the noise: the top speed {top:.3g}/s is within"
                    f" {NOISE_SIGMAS:g} x the speed noise {speed_noise:.2g}/s (position noise"
                    f" {float(np.max(noise.scale)):.2g}); if the robot does move, set --motion-threshold SPEED"
                    " (rad/s or m/s) below its moves' speed, or give the cycle events"]
    moving = speed > thr  # step i (t[i]..t[i+1]) moves
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return [], [f"{signal.topic}: no sample moves faster than {thr:.3g}/s ({how}); set --motion-threshold"
                    " SPEED (rad/s or m/s) below the moves' speed"]
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    stops = np.concatenate([idx[breaks], [idx[-1]]]) + 1  # sample index where the run is at rest
    band = np.maximum(NOISE_SIGMAS * noise.sigma, 1.5 * np.where(noise.quantised, noise.step, 0.0))
    floored = _widen(p, speed, starts, stops, window, band)
    if floored:
        notes.append(f"{signal.topic}: {floored} move edge(s) where the positions never came within the noise band"
                     f" ({NOISE_SIGMAS:g} x {float(np.max(noise.sigma)):.2g}) of rest before the next move (joints"
                     f" still ringing in noise-free positions): taken where they come within"
                     f" {100 * REST_FRACTION:g} % of the move's size of rest")
    moves: list[list[int]] = []
    for a, b in zip(starts, stops, strict=True):
        if moves and t[a] - t[moves[-1][1]] < min_rest:
            moves[-1][1] = max(moves[-1][1], int(b))
        else:
            moves.append([int(a), int(b)])
    size = [float(np.nanmax(np.abs(p[b] - p[a]))) for a, b in moves]
    biggest = max(size)
    kept = [m for m, s in zip(moves, size, strict=True) if s >= MIN_MOVE_FRACTION * biggest]
    if len(kept) < len(moves):
        notes.append(f"{len(moves) - len(kept)} move(s) smaller than {100 * MIN_MOVE_FRACTION:g} % of the"
                     " largest ignored")
    last = float(t[-1] if end_time is None else min(end_time, t[-1]))
    spans = []
    for k, (a, b) in enumerate(kept):
        end_i = kept[k + 1][0] if k + 1 < len(kept) else t.size - 1
        end = float(t[end_i]) if k + 1 < len(kept) else last
        spans.append(CycleSpan(k, float(t[a]), float(t[b]), end, int(signal.seq[a]), int(signal.seq[b]),
                               int(signal.seq[end_i]), tuple(p[a].tolist()), tuple(p[b].tolist()),
                               complete=k + 1 < len(kept)))
    if len(spans) == 1 and t[kept[0][1]] - t[kept[0][0]] > 0.8 * (t[-1] - t[0]):
        notes.append(f"{signal.topic}: the whole recording is one move (threshold {thr:.3g}/s, {how}); if it"
                     " holds several, set --motion-threshold SPEED above the speed the robot keeps between them")
    if spans:
        notes.append(f"cycles from the motion of {signal.topic}: {len(spans)} move(s) faster than {thr:.3g}/s"
                     f" ({how}); the last cycle ends with the recording")
    return spans, notes


def _widen(p: np.ndarray, speed: np.ndarray, starts: np.ndarray, stops: np.ndarray, window: int,
           tol: np.ndarray) -> int:
    """Move each run's first sample ``starts`` and stop ``stops`` (in place) out to where the positions
    ``p`` are at rest: noiseless (``window`` 1) while they change at all, else to within ``tol``
    (per joint, rad or m) of the rest next to the run (:func:`_rest_edge`); an edge that finds no rest
    within ``tol`` before the neighbouring run (or the recording's end) is taken within
    :data:`REST_FRACTION` of the run's size instead. Returns how many edges were."""
    floored = 0
    for k in range(starts.size):
        if window == 1:
            lo = stops[k - 1] if k else 0
            while starts[k] > lo and speed[starts[k] - 1] > 0.0:
                starts[k] -= 1
            hi = starts[k + 1] if k + 1 < starts.size else speed.size
            while stops[k] < hi and speed[stops[k]] > 0.0:
                stops[k] += 1
        else:
            lo = stops[k - 1] if k else 0
            hi = starts[k + 1] if k + 1 < starts.size else p.shape[0] - 1
            a, b = int(starts[k]), int(stops[k])
            floor = np.maximum(tol, REST_FRACTION * float(np.nanmax(np.abs(p[b] - p[a]))))
            for edge, bound, inner, direction in ((starts, int(lo), b, -1), (stops, int(hi), None, +1)):
                i = a if direction < 0 else b
                inner_i = inner if inner is not None else int(starts[k])
                j = _rest_edge(p, i, bound, inner_i, window // 2, tol, direction)
                if j == bound and bound != i and np.any(floor > tol):
                    j = _rest_edge(p, i, bound, inner_i, window // 2, floor, direction)
                    floored += 1
                edge[k] = j
    return floored


def _rest_edge(p: np.ndarray, i: int, bound: int, inner: int, half: int, tol: np.ndarray, direction: int) -> int:
    """Index where noisy positions next to a run of moving steps are at rest.

    ``i`` is the run's first sample (``direction`` -1) or the sample where it stops (+1), found on
    the speed smoothed over ``2 half + 1`` samples. The rest position is the median of the
    positions beyond the smoothed edge (``half`` + 1 to ``half`` + 6 samples or more from ``i``,
    not past ``bound``); from there the edge is the last sample before the run (the first after
    it) within ``tol`` (per joint, rad or m) of it, not past ``inner`` (the run's other end): the
    smoothed speed crosses its threshold up to ``half`` samples before the positions leave rest.
    """
    span = max(half, 2) + 5
    step = direction  # towards the rest
    j0 = int(np.clip(i + step * (half + 1), min(i, bound), max(i, bound)))
    far = int(np.clip(j0 + step * span, min(i, bound), max(i, bound)))
    lo, hi = min(j0, far), max(j0, far)
    rest = np.median(p[lo: hi + 1], axis=0)

    def at_rest(k: int) -> bool:
        return bool(np.all(np.abs(p[k] - rest) <= tol))

    j = j0
    while j != bound and not at_rest(j):  # the rest region itself moves: go further out
        j += step
    while j - step != inner and at_rest(j - step):
        j -= step  # towards the run while still at rest
    return int(j)
