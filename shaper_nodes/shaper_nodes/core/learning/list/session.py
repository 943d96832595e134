"""The learner's bookkeeping around :class:`~.learner.ListLearner`, free of ROS.

One class, fed the same stream of events whether it runs live in the learner node or offline
over a recorded bag, so that both give the same updates bit for bit:

- ``on_shaper``: the shaper node's active shaper (latched topic), to know which parameters a
  cycle actually ran with;
- ``on_imu``: accelerometer samples (time in s, 1 to 3 axes in m/s^2);
- ``on_event``: cycle events; at END the buffered cycle is handed to the learner.

A cycle is learned from only if it ran with the shaper the learner asked for (or unshaped,
which makes it the reference), with the same shaper from START to END; otherwise it is
skipped with the reason, as are cycles whose START was missed.

Memory is bounded: between cycles at most ``2 KEEP_BEFORE_START`` samples are kept (those stamped
after a START may arrive before it), or with ``keep_span`` the samples of the last ``keep_span`` s (at most twice
as many, and at least ``KEEP_BEFORE_START``): a START the learner missed is stood in for by a later event of its
cycle (:class:`~shaper_nodes.core.cycles.MissedStarts`), and the cycle is learned from only if the samples from
its START on are still held; a cycle that runs longer than ``max_cycle_duration`` is
refused, and its samples are dropped the moment a sample stamped past the limit arrives (the
session says so once, as :meth:`ListSession.on_imu`'s return value), not at its END. A cycle with
an accelerometer sample at or beyond the sensor's range (``max_abs_accel``) is saturated: the
samples are counted (:attr:`ListSession.saturated`) and the cycle refused with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.cycles import END, MOTION_END, START, unseen_window

from ..samples import MAX_ABS_ACCEL, MAX_CYCLE_DURATION, SampleBuffer, out_of_range, sensor_fault
from .learner import ListLearner
from .params import ListConfig, ListError, ListParams, finite_value
from .trials import ListUpdate

#: samples kept between cycles (those stamped after a START may arrive before it)
KEEP_BEFORE_START = 1000
#: the entries of the learner node's LIST state document
_DOC_KEYS = {"version", "structure", "saved_at", "learner"}
#: relative tolerance when matching the active shaper with the parameters the learner sent
MATCH_TOL = 1e-9


def _floats(value: Any) -> tuple[float, ...]:
    if isinstance(value, str):
        raise ValueError(f"expected a list of numbers, got {value!r}")
    return tuple(float(x) for x in value)


def _converted(key: str, kind: Any, value: Any) -> Any:
    """``kind(value)``, or a ListError naming ``list.<key>`` and the value (``float('abc')`` named neither)."""
    try:
        return kind(value)
    except (TypeError, ValueError) as err:
        name = {float: "a number", int: "an integer"}.get(kind, "a list of numbers")
        raise ListError(f"list.{key} must be {name}, got {value!r} ({err})") from None


def list_config(values: Mapping[str, Any]) -> ListConfig:
    """The ListConfig of the learner node's ``list.*`` parameters (keys without the prefix).

    Parameters use 0 (or [0, 0]) for "not set": ``window_delay`` 0 -> None, ``t2_bounds``
    [0, 0] -> None, ``saturation`` 0 -> no limit. Missing keys keep the defaults.

    Raises
    ------
    ListError
        An invalid value; the message names it.
    """
    v = dict(values)
    kw: dict[str, Any] = {}
    for key in ("structure", "rule"):
        if key in v:
            kw[key] = str(v[key])
    for key in ("highpass_hz", "max_step_a1", "max_step_t2", "switch_tol", "rollback_factor"):
        if key in v:
            kw[key] = _converted(key, float, v[key])
    for key in ("phase_trials", "patience", "min_samples"):
        if key in v:
            kw[key] = _converted(key, int, v[key])
    if "window_delay" in v:
        kw["window_delay"] = _converted("window_delay", float, v["window_delay"]) or None
    if "saturation" in v:
        kw["saturation"] = _converted("saturation", float, v["saturation"]) or math.inf
    if "a1_bounds" in v:
        kw["a1_bounds"] = _converted("a1_bounds", _floats, v["a1_bounds"])
    if "t2_bounds" in v:
        t2 = _converted("t2_bounds", _floats, v["t2_bounds"])
        kw["t2_bounds"] = t2 if any(t2) else None
    try:
        return ListConfig(**kw)
    except (TypeError, ValueError) as err:
        raise ListError(f"invalid learner configuration: {err}") from None


def learner_from_state(doc: Mapping[str, Any]) -> ListLearner:
    """The learner saved in the learner node's LIST state document (``version``, ``structure``,
    ``saved_at``, ``learner``), every entry checked (:meth:`ListLearner.from_dict` checks the
    learner's own state part by part).

    Raises
    ------
    ListError
        Entries missing or unknown, a ``saved_at`` that is not a finite number, or a learner
        state that is corrupt or inconsistent (the message names what).
    """
    if not isinstance(doc, Mapping):
        raise ListError(f"the LIST state must be a dictionary, got {type(doc).__name__}")
    missing, unknown = {"learner"} - set(doc), set(doc) - _DOC_KEYS
    if missing or unknown:
        raise ListError(f"LIST state entries differ: missing {sorted(missing)}, unknown {sorted(unknown)}")
    if "saved_at" in doc:
        finite_value("saved_at", doc["saved_at"])
    return ListLearner.from_dict(doc["learner"])


@dataclass(frozen=True)
class ActiveShaper:
    """What the shaper node reports as active: impulses, who set it, and its revision."""

    amplitudes: tuple[float, ...]
    times: tuple[float, ...]
    source: str
    revision: int

    @property
    def is_identity(self) -> bool:
        return len(self.amplitudes) == 1


@dataclass(frozen=True)
class SessionResult:
    """The outcome of one finished cycle: the learner's update, or why it was skipped."""

    cycle: int
    start: float
    motion_end: float
    end: float
    update: ListUpdate | None
    skipped: str = ""
    #: the class of a refusal the node reports on its diagnostics ("too_long", "saturated",
    #: "malformed"), "" otherwise
    refusal: str = ""

    @property
    def learned(self) -> bool:
        return self.update is not None and self.update.action != "rejected"


class ListSession:
    """Buffer one cycle at a time and run the LIST update at its END.

    Parameters
    ----------
    learner : ListLearner
        The learner (fresh, or restored from a save file).
    structure : str
        The impulse structure the learner's parameters are applied as ("zv2" or "zvd3").
    stale_after : float
        A cycle whose last accelerometer sample is older than this at END (s) is stale.
    max_cycle_duration : float
        The longest cycle, s: a longer one is refused, its samples dropped at the limit.
    max_abs_accel : float
        The accelerometer's range, m/s^2: a cycle with a sample at or beyond it is refused as
        saturated (inf: no bound).
    keep_span : float
        s of samples kept between cycles (0: the last ``KEEP_BEFORE_START``), so that a START stood in for
        (:meth:`on_event` with ``stood_in``) finds its samples; the learner node keeps
        :data:`~shaper_nodes.core.cycles.STAND_IN_SPAN`.

    Raises
    ------
    ListError
        ``max_cycle_duration`` or ``max_abs_accel`` not > 0.
    """

    def __init__(self, learner: ListLearner, structure: str = "zv2", stale_after: float = 0.1,
                 max_cycle_duration: float = MAX_CYCLE_DURATION, max_abs_accel: float = MAX_ABS_ACCEL,
                 keep_span: float = 0.0) -> None:
        self.learner = learner
        self.structure = structure
        self.stale_after = float(stale_after)
        self.max_cycle_duration = finite_value("max_cycle_duration", max_cycle_duration)
        self.max_abs_accel = float(max_abs_accel)
        self.keep_span = float(keep_span)
        if not self.max_cycle_duration > 0.0 or not self.max_abs_accel > 0.0:
            raise ListError(f"max_cycle_duration and max_abs_accel must be > 0, got {max_cycle_duration!r},"
                            f" {max_abs_accel!r}")
        self.active: ActiveShaper | None = None
        self._sent: ListParams | None = None
        self._previous: ListParams | None = None
        self._cycle: int | None = None
        self._start = 0.0
        self._motion_end: float | None = None
        self._at_start: ActiveShaper | None = None
        self._direction = 1.0
        self._buf = SampleBuffer()
        self._overlong = False     # the cycle passed max_cycle_duration: its samples are dropped
        self._malformed = 0        # samples of the cycle with another number of axes
        self._ref_displacement: npt.NDArray[np.float64] | None = None
        self._latest = -math.inf
        self._pending: float | None = None  # the stamp of a START received and not handled yet (s)
        self._trim_at = 2 * KEEP_BEFORE_START  # samples held between cycles at which they are cut (keep_span)
        self._unseen = ""  # why the cycle in progress (its START stood in for) was not seen from its START
        #: accelerometer samples counted as saturated, over all cycles refused for it
        self.saturated = 0
        #: accelerometer samples stamped before the START of the cycle in progress that arrived after it (dropped)
        self.before_start = 0

    @property
    def buffered(self) -> int:
        """Accelerometer samples held."""
        return len(self._buf)

    @property
    def buffered_bytes(self) -> int:
        """Bytes the sample buffer takes."""
        return self._buf.nbytes

    # ----------------------------------------------------------------- inputs
    def sent(self, params: ListParams | None) -> None:
        """The learner's parameters were sent to the shaper node (None: the identity)."""
        self._previous, self._sent = self._sent, params

    def switch(self, learner: ListLearner, sent: ListParams | None) -> None:
        """Learn the next cycle with another learner (per-move learning: the learner of the move that starts
        next, called before its START). ``sent``: the parameters applied to that move (None: none, its
        reference cycle). The move's goals are shaped per move (the scheduler's ``~/shaper_at``), not by the
        shaper node's active shaper: the cycle is taken to run with ``sent``, as the learner's request for
        the move was acknowledged, and the active shaper is set to match it."""
        self.learner, self._sent, self._previous = learner, sent, None
        self._ref_displacement = None  # each move is its own direction of reference
        if sent is None:
            self.active = ActiveShaper((1.0,), (0.0,), "learner", 0)
        else:
            sh = sent.shaper(self.structure)
            self.active = ActiveShaper(tuple(float(a) for a in sh.amplitudes), tuple(float(t) for t in sh.times),
                                       "learner", 0)

    def on_shaper(self, amplitudes: Iterable[float], times: Iterable[float], source: str, revision: int) -> None:
        self.active = ActiveShaper(tuple(float(a) for a in amplitudes), tuple(float(t) for t in times),
                                   str(source), int(revision))

    @property
    def latest_imu(self) -> float:
        """Stamp of the latest accelerometer sample received (s), -inf before the first."""
        return self._latest

    def on_imu(self, t: float, accel: npt.ArrayLike) -> str | None:
        """An accelerometer sample. Kept by its stamp: at END the cycle takes the samples stamped
        between its START and END, whatever order they arrived in relative to the events (one stamped
        before the START of the cycle in progress is dropped, and counted in :attr:`before_start`).

        Returns a notice, once per cycle, when the cycle in progress passes ``max_cycle_duration``
        (its samples are dropped then, and no more are kept for it); None otherwise.
        """
        t = float(t)
        self._latest = max(self._latest, t)
        buf, in_cycle = self._buf, self._cycle is not None and not self._overlong
        if self._cycle is not None and t < self._start:
            # stamped before the START already handled (the events come on another topic: rclpy's executor takes
            # one message per ready subscription at a time, so a learner behind by a few samples handles START
            # between them): it belongs to no cycle still to come
            self.before_start += 1
            return None
        if not buf.append(t, accel):
            if in_cycle:
                self._malformed += 1
            else:  # samples before a START only: go on with the new layout
                buf.clear()
                buf.append(t, accel)
        if in_cycle and t - self._start > self.max_cycle_duration:
            self._overlong = True
            buf.keep_last(KEEP_BEFORE_START)
            return (f"cycle {self._cycle} has run {t - self._start:.1f} s, longer than max_cycle_duration"
                    f" {self.max_cycle_duration:g} s: its samples are dropped, no more are kept for it, and it will"
                    " not be learned from")
        if not in_cycle and len(buf) > self._trim_at:
            pending = self._pending
            self._trim_at = 2 * KEEP_BEFORE_START
            recent = buf.times >= t - self.keep_span
            if pending is not None and t - pending <= self.max_cycle_duration:
                buf.keep(buf.times >= pending)  # the samples of a START on its way in are the cycle's
            elif self.keep_span > 0.0 and int(recent.sum()) >= KEEP_BEFORE_START:
                buf.keep(recent)
                self._trim_at = 2 * len(buf)  # cut again once doubled: amortised
            else:
                buf.keep_last(KEEP_BEFORE_START)
        return None

    def expect_start(self, t: float) -> None:
        """A START stamped ``t`` s was received and its handling waits (per-move learning asks the scheduler for
        a new move's first factor): the samples stamped from ``t`` on are kept until it comes to
        :meth:`on_event` (within ``max_cycle_duration``), not cut to the last ones kept between cycles."""
        self._pending = float(t)

    def drop(self, cycle: int) -> None:
        """Forget the cycle in progress if it is ``cycle``: its END then gives no update (a cycle not to be learned
        from, known before its END is handled: per-move learning's goal shaped with another shaper)."""
        if self._cycle == int(cycle):
            self._cycle, self._overlong = None, False

    def on_event(self, kind: int, cycle: int, t: float, start_positions: npt.ArrayLike = (),
                 goal_positions: npt.ArrayLike = (), stood_in: bool = False) -> SessionResult | None:
        """A cycle event; returns the result at a cycle's END, else None. ``stood_in``: a START the learner
        missed, stood in for by a later event of its cycle (its START stamp): the cycle is learned from only if
        the samples held reach back to ``t`` (:func:`~shaper_nodes.core.cycles.unseen_window`)."""
        t = float(t)
        if kind == START:
            held = self._buf.times
            self._unseen = unseen_window(t, float(held.min()) if held.size else None) if stood_in else ""
            self._pending = None
            self._cycle, self._start, self._motion_end = int(cycle), t, None
            self._at_start = self.active
            self._overlong, self._malformed = False, 0
            self._buf.keep(self._buf.times >= t)
            self._direction = self._direction_of(start_positions, goal_positions)
            return None
        if self._cycle is None or int(cycle) != self._cycle:
            if kind == END:
                return SessionResult(int(cycle), float("nan"), float("nan"), t, None,
                                     "END without its START (events lost, or the learner started mid-cycle)")
            return None
        if kind == MOTION_END:
            self._motion_end = t - self._start
            return None
        if kind != END:
            return None
        cycle, self._cycle = self._cycle, None
        motion_end = self._motion_end if self._motion_end is not None else 0.0
        start = self._start

        def result(update: ListUpdate | None, why: str = "", refusal: str = "") -> SessionResult:
            return SessionResult(cycle, start, start + motion_end, t, update, why, refusal)

        if self._overlong or t - start > self.max_cycle_duration:
            self._overlong = False
            return result(None, f"the cycle lasted {t - start:.1f} s, longer than max_cycle_duration"
                                f" {self.max_cycle_duration:g} s (its samples were dropped at the limit)", "too_long")
        if self._unseen:
            return result(None, self._unseen)
        if self._motion_end is None:
            return result(None, "no MOTION_END event in the cycle")
        used, why = self._used(self._at_start)
        if why:
            return result(None, why)
        if self.active != self._at_start:
            return result(None, "the shaper changed during the cycle")
        times, accel, why, refusal = self._cycle_samples(t)
        if why:
            return result(None, why, refusal)
        try:
            update = self.learner.update(times, accel, motion_end, t - self._start, used, self._direction)
        except ListError as err:
            return result(None, str(err))
        return result(update)

    # ----------------------------------------------------------------- helpers
    def _cycle_samples(self, t: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], str, str]:
        """The samples stamped from START to the END at ``t`` (times from START, accel), taken out of
        the buffer, and why they cannot be learned from with the class of the refusal ("" if they can).
        (None stamped before START is there: those are dropped at START and, arriving later, by
        :meth:`on_imu`.)"""
        buf = self._buf
        mine = buf.times <= t
        times = buf.times[mine] - self._start
        accel = buf.values[mine] if mine.any() else np.zeros((0, 3))
        buf.keep(~mine)
        if times.size == 0:
            return times, accel, "no accelerometer data in the cycle (sensor missing or stale)", "sensor"
        if self._malformed:
            return times, accel, (f"{self._malformed} accelerometer samples of the cycle had another number of axes"
                                  f" than its others ({accel.shape[1]})"), "malformed"
        saturated = out_of_range(accel, self.max_abs_accel)
        if saturated is not None:
            self.saturated += saturated.count
            why = "saturated accelerometer: " + saturated.describe("accelerometer", "m/s^2", "sensor.max_abs_accel")
            return times, accel, why, "saturated"
        fault = sensor_fault(accel)
        if fault is not None:
            return times, accel, "sensor fault: " + fault, "sensor"
        if (t - self._start) - times[-1] > self.stale_after:
            return times, accel, (f"stale accelerometer: its last sample is {(t - self._start) - times[-1]:.3f} s"
                                  f" before the cycle's END (limit {self.stale_after:g} s)"), ""
        return times, accel, "", ""

    def _direction_of(self, start_positions: npt.ArrayLike, goal_positions: npt.ArrayLike) -> float:
        d = np.asarray(goal_positions, dtype=float) - np.asarray(start_positions, dtype=float)
        if d.size == 0 or not np.all(np.isfinite(d)) or not np.any(d):
            return 1.0
        if self._ref_displacement is None or self._ref_displacement.shape != d.shape:
            self._ref_displacement = d
        return 1.0 if float(np.dot(d, self._ref_displacement)) >= 0.0 else -1.0

    def _matches(self, params: ListParams, active: ActiveShaper) -> bool:
        mine = params.shaper(self.structure)
        return (len(mine.amplitudes) == len(active.amplitudes)
                and np.allclose(mine.amplitudes, active.amplitudes, rtol=MATCH_TOL, atol=MATCH_TOL)
                and np.allclose(mine.times, active.times, rtol=MATCH_TOL, atol=MATCH_TOL))

    def _used(self, active: ActiveShaper | None) -> tuple[ListParams | None, str]:
        """The parameters a cycle ran with (None: unshaped), or a reason not to learn from it."""
        if active is None:
            return None, "the active shaper is not known yet (no message on the active-shaper topic)"
        if active.is_identity:
            if self._sent is None or self.learner.reference is None:
                return None, ""  # asked for (or needed): the reference cycle
            return None, ("the cycle ran unshaped although the learner had sent its shaper (the update"
                          " arrived after it started, or another source set none); not learned from")
        if self._sent is not None and self._matches(self._sent, active):
            return self._sent, ""
        if self._previous is not None and self._matches(self._previous, active):
            return None, ("the cycle ran with the learner's previous parameters (the update arrived after it"
                          " started); not learned from")
        return None, (f"the cycle ran with a shaper the learner did not set (source {active.source!r},"
                      f" revision {active.revision}); not learned from")
