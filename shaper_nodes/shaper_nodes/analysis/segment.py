"""Cycles of a recording: from its cycle events, or from the motion of its commands.

With cycle events (shaper_msgs/CycleEvent) a cycle runs from START to END, its motion ending at
MOTION_END, as the task runner marked them. Without them (a robot's own recorder), cycles are
found in a position signal (the commands, else the joint states): a sample moves when some
joint's speed exceeds ``threshold`` (default 1 % of the recording's top speed, the 99.5th
percentile of the per-sample speeds); runs of moving samples closer than ``min_rest`` s are one
move; a cycle runs from the start of a move to the start of the next (the last to the end of
the recording), and its motion ends when the move does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START

from .streams import Events, Signal

#: fraction of the top speed above which a sample counts as moving
MOTION_FRACTION = 0.01
#: moves closer than this (s) are one move
MIN_REST = 0.05
#: a step longer than this many median steps is a gap in the data, not a move
GAP_FACTOR = 5.0
#: moves whose largest joint displacement is below this fraction of the largest move's are noise
MIN_MOVE_FRACTION = 0.01


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


def from_events(events: Events) -> tuple[list[CycleSpan], list[str]]:
    """Cycles from the events in recording order; notes on events that do not pair up."""
    spans: list[CycleSpan] = []
    notes: list[str] = []
    order = np.argsort(np.asarray(events.seq), kind="stable")
    current: dict | None = None
    for i in order:
        kind, cyc, t, seq = events.kind[i], events.cycle[i], events.t[i], events.seq[i]
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
        Speed (rad/s or m/s) above which a sample moves.
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
    speed = np.zeros(dt.size)
    speed[ok] = np.nanmax(np.abs(np.diff(p, axis=0)[ok]) / dt[ok, None], axis=1)
    top = float(np.nanpercentile(speed[ok], 99.5)) if ok.any() else 0.0
    thr = float(threshold) if threshold is not None else MOTION_FRACTION * top
    if not top > 0.0 or not np.isfinite(thr):
        return [], [f"{signal.topic}: the positions never change: no moves"]
    moving = speed > thr  # sample i -> i+1 moves
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return [], [f"{signal.topic}: no sample moves faster than {thr:.3g}/s"]
    # runs of moving steps; step i spans t[i]..t[i+1]
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    stops = np.concatenate([idx[breaks], [idx[-1]]]) + 1  # sample index where the run is at rest
    # widen each run over its slow start and end (below the threshold, above the resting noise)
    still = speed[ok & ~moving]
    floor = 2.0 * float(np.median(still)) if still.size else 0.0
    for k in range(starts.size):
        lo = stops[k - 1] if k else 0
        while starts[k] > lo and speed[starts[k] - 1] > floor:
            starts[k] -= 1
        hi = starts[k + 1] if k + 1 < starts.size else speed.size
        while stops[k] < hi and speed[stops[k]] > floor:
            stops[k] += 1
    moves: list[list[int]] = []
    for a, b in zip(starts, stops, strict=True):
        if moves and t[a] - t[moves[-1][1]] < min_rest:
            moves[-1][1] = int(b)
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
    if spans:
        notes.append(f"cycles from the motion of {signal.topic}: {len(spans)} move(s) faster than {thr:.3g}/s;"
                     " the last cycle ends with the recording")
    return spans, notes
