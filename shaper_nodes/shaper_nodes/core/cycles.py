"""Cycle bookkeeping: buffer one cycle's signals and measure its residual vibration.

Used by every component that reports per-cycle residual vibration (the sim plant, the demo,
tests, bag analysis), so that they all measure the same thing: the RMS and peak of the tip
acceleration magnitude from the time the commanded joint positions have come to rest after
the cycle's MOTION_END (within ``settle_tolerance`` of their final value) until its END.
"""

from __future__ import annotations

import dataclasses
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.shaping.vibration import ResidualVibration, residual_vibration, settle_time
from shaper_nodes.core.stamps import stamp_to_sec

START, MOTION_END, END = 0, 1, 2
#: s of samples a listener keeps between cycles so that a START it missed, stood in for by the cycle's MOTION_END
#: or END (:class:`MissedStarts`), finds its samples: a motion up to this long
STAND_IN_SPAN = 30.0

#: stamped samples (time in s, values) in order of arrival
_Samples = deque[tuple[float, np.ndarray]]


@dataclass(frozen=True)
class CycleResult:
    """One finished cycle: its times (s), residual vibration and its traces."""

    cycle: int
    start: float
    motion_end: float
    residual: ResidualVibration
    accel_times: np.ndarray
    accel: np.ndarray
    position_times: np.ndarray
    positions: np.ndarray
    #: why the cycle, its START missed and stood in for, was not seen from its START ("" if it was:
    #: :func:`unseen_window`); its figures then cover only what was seen
    unseen: str = ""


class CycleMonitor:
    """Collect accelerometer and joint-position samples per cycle, evaluate at END.

    Parameters
    ----------
    settle_tolerance : float
        Band (rad or m) within which the joint positions count as at rest.
    remove_mean : bool
        Remove the window mean of the acceleration (sensor offset, gravity) before the RMS.
    max_samples : int
        Most samples kept per stream in one cycle: a cycle that passes it (its END lost, say) is
        abandoned and its samples dropped, so memory stays bounded; :attr:`abandoned` counts them.
    keep_before : float
        s of samples kept between cycles (0: none), for a START stood in for (:meth:`event` with
        ``stood_in``): its cycle takes the samples kept from its START on, if they reach back to it.
    """

    def __init__(self, settle_tolerance: float = 1e-6, remove_mean: bool = False,
                 max_samples: int = 2_000_000, keep_before: float = 0.0) -> None:
        self.settle_tolerance = float(settle_tolerance)
        self.remove_mean = remove_mean
        self.max_samples = int(max_samples)
        self.keep_before = float(keep_before)
        self.abandoned = 0
        self._before_acc: _Samples = deque()  # samples outside a cycle, the last keep_before s
        self._before_pos: _Samples = deque()
        self._unseen = ""
        self._cycle: int | None = None
        self._start = 0.0
        self._motion_end: float | None = None
        self._acc_t: list[float] = []
        self._acc: list[np.ndarray] = []
        self._pos_t: list[float] = []
        self._pos: list[np.ndarray] = []

    @property
    def in_cycle(self) -> bool:
        return self._cycle is not None

    @property
    def accel_samples(self) -> int:
        """Accelerometer samples collected in the cycle in progress (0 between cycles)."""
        return len(self._acc_t)

    @property
    def held_before(self) -> int:
        """Accelerometer samples kept between cycles (``keep_before``), for a START stood in for."""
        return len(self._before_acc)

    def _in_cycle(self, t: float) -> bool:
        """Whether a sample stamped ``t`` belongs to the cycle in progress: one stamped before its START
        belongs to none (over DDS the samples come on other topics than the events, and a node behind by a
        few samples handles START between them: rclpy's executor takes one message per ready subscription
        at a time)."""
        return self._cycle is not None and t >= self._start

    def add_accel(self, t: float, accel: npt.ArrayLike) -> None:
        """An accelerometer sample (m/s^2, 1 to 3 axes) at time t (s)."""
        if self._in_cycle(t):
            self._acc_t.append(float(t))
            self._acc.append(np.asarray(accel, dtype=float).ravel())
            self._bound(self._acc_t)
        elif self.keep_before > 0.0:
            self._keep(self._before_acc, t, accel)

    def add_positions(self, t: float, positions: npt.ArrayLike) -> None:
        """Joint positions (rad or m) at time t (s)."""
        if self._in_cycle(t):
            self._pos_t.append(float(t))
            self._pos.append(np.asarray(positions, dtype=float).ravel())
            self._bound(self._pos_t)
        elif self.keep_before > 0.0:
            self._keep(self._before_pos, t, positions)

    def _keep(self, buf: _Samples, t: float, values: npt.ArrayLike) -> None:
        buf.append((float(t), np.asarray(values, dtype=float).ravel()))
        while buf and buf[0][0] < t - self.keep_before:
            buf.popleft()

    def _bound(self, stream: list[float]) -> None:
        if len(stream) > self.max_samples:  # a cycle without end: abandoned, its samples dropped
            self._cycle = None
            self._acc_t, self._acc, self._pos_t, self._pos = [], [], [], []
            self.abandoned += 1

    def event(self, kind: int, cycle: int, t: float, stood_in: bool = False) -> CycleResult | None:
        """A cycle event; returns the cycle's result at its END, else None. ``stood_in``: a START missed, stood in
        for by a later event of its cycle (:class:`MissedStarts`): the cycle takes the samples kept from ``t`` on
        (``keep_before``), and its result says if they do not reach back to ``t`` (``unseen``)."""
        if kind == START:
            self._cycle, self._start, self._motion_end = int(cycle), float(t), None
            self._acc_t, self._acc, self._pos_t, self._pos = [], [], [], []
            self._unseen = ""
            if stood_in:
                self._unseen = unseen_window(float(t), self._before_acc[0][0] if self._before_acc else None)
                for buf, add in ((self._before_acc, self.add_accel), (self._before_pos, self.add_positions)):
                    for ts, values in list(buf):
                        add(ts, values)
            self._before_acc.clear()
            self._before_pos.clear()
            return None
        if self._cycle is None or int(cycle) != self._cycle:
            return None
        if kind == MOTION_END:
            self._motion_end = float(t)
            return None
        if kind != END:
            return None
        cycle, self._cycle = self._cycle, None  # the cycle is over whatever its data
        motion_end = self._motion_end if self._motion_end is not None else self._start
        acc = np.vstack(self._acc) if self._acc else np.zeros((0, 3))
        pos = np.vstack(self._pos) if self._pos else np.zeros((0, 1))
        result = evaluate_cycle(cycle, self._start, motion_end, float(t), np.asarray(self._acc_t), acc,
                                np.asarray(self._pos_t), pos, self.settle_tolerance, self.remove_mean)
        return dataclasses.replace(result, unseen=self._unseen) if self._unseen else result


@dataclass(frozen=True)
class Event:
    """A cycle event as a listener handles it: kind, cycle, stamp (s); ``stood_in``: a START the listener never
    received, stood in for by a later event's start stamp (:class:`MissedStarts`)."""

    kind: int
    cycle: int
    t: float
    stood_in: bool = False


class MissedStarts:
    """One listener's rule for a START it missed: a later event of the cycle stands in for it.

    Over DDS a volatile reader whose side of the match comes after a START went out never gets it
    (``send_goal --cycle`` makes a publisher per goal: session 13's walk lost 3 STARTs in 34 goals).
    Every event of a cycle repeats its START's stamp (CycleEvent ``start_stamp``), so the first
    MOTION_END or END of a cycle whose START was not seen here is preceded by a START at that stamp,
    marked ``stood_in``. Without the stamp (a publisher older than the field) the event passes as it
    came: "END without its START", as before. A stood-in START says when the cycle began, not that the
    listener saw it: what the listener measures from START needs its samples from that stamp on
    (:func:`unseen_window`).
    """

    def __init__(self) -> None:
        self._open: int | None = None  # the cycle whose START (received or stood in) came and no END yet
        #: STARTs stood in for so far
        self.stood_in = 0

    def events(self, kind: int, cycle: int, t: float, start: float | None) -> list[Event]:
        """What to handle for the event ``kind`` of ``cycle`` stamped ``t`` s carrying its START's stamp
        ``start`` s (None: absent), in order."""
        kind, cycle = int(kind), int(cycle)
        out = []
        if kind == START:
            self._open = cycle
        elif cycle != self._open and start is not None and kind in (MOTION_END, END):
            out.append(Event(START, cycle, float(start), True))
            self.stood_in += 1
            self._open = cycle
        if kind == END and cycle == self._open:
            self._open = None
        out.append(Event(kind, cycle, float(t)))
        return out


def start_stamp(msg: Any) -> float | None:
    """The START stamp a CycleEvent (live, or decoded from a recording) carries, s; None: absent, or decoded with
    a definition older than the field."""
    stamps = getattr(msg, "start_stamp", None)
    return stamp_to_sec(stamps[0]) if stamps is not None and len(stamps) else None


def unseen_window(start: float, first_held: float | None) -> str:
    """Why a listener that missed the START of a cycle that began at ``start`` s cannot measure it from START
    ("" if it can): it needs a sample stamped at or before ``start`` among those it held when the stand-in came
    (``first_held``, the earliest stamp held, s; None: none held), else it was not listening from START (started
    mid-cycle) or dropped the samples since."""
    if first_held is not None and first_held <= start:
        return ""
    held = "no samples held" if first_held is None else f"the samples held begin at {first_held:.3f} s"
    return (f"its START was missed (stood in for by a later event's start stamp, {start:.3f} s) and {held}: the"
            " window from START was not seen")


def evaluate_cycle(cycle: int, start: float, motion_end: float, end: float, accel_times: np.ndarray,
                   accel: np.ndarray, position_times: np.ndarray, positions: np.ndarray,
                   settle_tolerance: float = 1e-6, remove_mean: bool = False) -> CycleResult:
    """The residual vibration of one cycle from its samples (as :class:`CycleMonitor` does at END).

    The window runs from the time the positions have come to rest after ``motion_end`` (within
    ``settle_tolerance`` of their last value) until ``end``; times in s, acceleration in m/s^2.
    """
    after = position_times >= motion_end
    window_start = (settle_time(position_times[after], positions[after], motion_end, settle_tolerance)
                    if after.any() else motion_end)
    residual = residual_vibration(accel_times, accel, window_start, float(end) + 1e-12, remove_mean)
    return CycleResult(int(cycle), float(start), float(motion_end), residual, accel_times, accel,
                       position_times, positions)


class StampedCycleMonitor:
    """:class:`CycleMonitor` for samples and events that arrive over separate topics.

    Over DDS the accelerometer, the joint states and the cycle events come on different topics,
    so a sample stamped inside a cycle may arrive before its START or after its END. This monitor
    keeps the samples by their stamps and evaluates a cycle once samples stamped at or after its
    END have arrived on both streams (:meth:`poll`), selecting its samples by stamp; its results
    therefore do not depend on the order of arrival, i.e. on the load of the machine.

    Parameters
    ----------
    settle_tolerance, remove_mean
        As for :class:`CycleMonitor`.
    keep : int
        Most samples kept per stream (older ones are dropped first).
    max_wait : float
        A cycle is evaluated anyway, with the samples there are, once each stream not yet past its END
        has taken no sample for this long (s, wall clock) and its END arrived at least this long ago (a
        best-effort sample stamped at END may be lost, and a plant may stop after END). A stream still
        delivering, as a busy machine's backlog of samples stamped before END does, is waited for:
        counted from END's arrival alone, a load that held the samples back for a second left them out
        of the cycle's result (session 14).
    """

    def __init__(self, settle_tolerance: float = 1e-6, remove_mean: bool = False, keep: int = 500_000,
                 max_wait: float = 1.0) -> None:
        self.settle_tolerance = float(settle_tolerance)
        self.remove_mean = remove_mean
        self.max_wait = float(max_wait)
        self._acc: _Samples = deque(maxlen=keep)
        self._pos: _Samples = deque(maxlen=keep)
        self._open: tuple[int, float, float | None] | None = None
        self._pending: list[tuple[int, float, float, float, float]] = []  # ..., wall time END arrived
        self._arrived = {"acc": -np.inf, "pos": -np.inf}  # wall time of each stream's latest sample

    def add_accel(self, t: float, accel: npt.ArrayLike) -> None:
        """An accelerometer sample (m/s^2, 1 to 3 axes) stamped t (s)."""
        self._acc.append((float(t), np.asarray(accel, dtype=float).ravel()))
        self._arrived["acc"] = time.monotonic()

    def add_positions(self, t: float, positions: npt.ArrayLike) -> None:
        """Joint positions (rad or m) stamped t (s)."""
        self._pos.append((float(t), np.asarray(positions, dtype=float).ravel()))
        self._arrived["pos"] = time.monotonic()

    def event(self, kind: int, cycle: int, t: float) -> None:
        """A cycle event; a cycle's result comes from :meth:`poll` once its samples are in."""
        if kind == START:
            self._open = (int(cycle), float(t), None)
        elif self._open is not None and int(cycle) == self._open[0]:
            if kind == MOTION_END:
                self._open = (self._open[0], self._open[1], float(t))
            elif kind == END:
                cyc, start, motion_end = self._open
                self._pending.append((cyc, start, start if motion_end is None else motion_end, float(t),
                                      time.monotonic()))
                self._open = None

    def poll(self) -> list[CycleResult]:
        """The cycles whose END has passed on both sample streams (or whose streams behind it went quiet), in order."""
        out = []
        latest = {"acc": self._acc[-1][0] if self._acc else -np.inf,
                  "pos": self._pos[-1][0] if self._pos else -np.inf}

        def ready(end: float, end_arrived: float) -> bool:
            behind = [name for name, t in latest.items() if t < end]
            if not behind:
                return True
            # given up on only once the streams behind are quiet: not while a backlog is still coming in
            return time.monotonic() - max([end_arrived] + [self._arrived[n] for n in behind]) > self.max_wait

        while self._pending and ready(self._pending[0][3], self._pending[0][4]):
            cycle, start, motion_end, end, _ = self._pending.pop(0)
            acc_t, acc = self._select(self._acc, start, end, 3)
            pos_t, pos = self._select(self._pos, start, end, 1)
            out.append(evaluate_cycle(cycle, start, motion_end, end, acc_t, acc, pos_t, pos,
                                      self.settle_tolerance, self.remove_mean))
            # samples before this END cannot belong to a later cycle
            for buf in (self._acc, self._pos):
                while buf and buf[0][0] < end:
                    buf.popleft()
        return out

    @staticmethod
    def _select(buf: _Samples, start: float, end: float, width: int) -> tuple[np.ndarray, np.ndarray]:
        items = sorted(((t, v) for t, v in buf if start <= t <= end), key=lambda item: item[0])
        if not items:
            return np.zeros(0), np.zeros((0, width))
        return np.array([t for t, _ in items]), np.vstack([v for _, v in items])
