"""The MRILC session: whole cycles on the sample grid from the streams a learner sees, free of ROS.

:class:`MrilcSession` turns the streams of the learner node (joint states, the applied
reference, cycle events) into whole cycles on the sample grid, rejecting cycles with missing,
stale, non-finite or implausible samples, and calls :class:`~.learner.MrilcLearner`. The learner
node and offline replays share it.

Memory is bounded. Between cycles (before the first START, after an END, or when no START ever
comes) each stream keeps only the samples stamped within :data:`KEEP_BETWEEN` s of its newest (a
START is handled after the END before it, which may wait for services, so samples stamped after
a START can be there before it is); a cycle keeps its own samples, and one that runs longer than
``max_cycle_duration`` is refused, its samples dropped the moment a sample stamped past the limit
arrives (the session says so once, as the return value of the ``on_*`` methods).

Implausible samples: a joint state or reference position, or an effort, whose magnitude is at or
beyond ``max_abs_position`` or ``max_abs_effort`` (the joints' range, the actuators' range, with
a margin) refuses the cycle with the reason; such a sample is a sensor or transport fault, and
learning from it would put its error, times the learning gain, into the next profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.cycles import END, START

from ..samples import MAX_CYCLE_DURATION, SampleBuffer, out_of_range
from .learner import MrilcLearner, MrilcUpdate
from .model import MrilcError
from .params import MAX_ABS_EFFORT, MAX_ABS_POSITION

#: samples kept between cycles, s of each stream's newest stamps
KEEP_BETWEEN = 30.0


@dataclass
class MrilcCycle:
    """One cycle's outcome: the update, or why it was skipped (``refusal``: the class of a refusal
    the node reports on its diagnostics, "too_long" or "implausible", else "")."""

    cycle: int
    start: float
    end: float
    update: MrilcUpdate | None = None
    skipped: str = ""
    refusal: str = ""


class _Stream:
    """Samples keyed by stamp (s), kept in order (a repeated stamp: the newest wins); old ones dropped."""

    def __init__(self) -> None:
        self.buf = SampleBuffer()
        self.dropped = 0  # samples of another width than the stream's

    def __len__(self) -> int:
        return len(self.buf)

    def add(self, t: float, value: npt.ArrayLike) -> None:
        buf = self.buf
        if not math.isfinite(t):
            self.dropped += 1
            return
        if buf.n == 0 or t > buf.times[-1]:
            ok = buf.append(t, value)
        else:
            i = int(np.searchsorted(buf.times, t, "left"))
            ok = buf.replace(i, value) if buf.times[i] == t else buf.insert(i, t, value)
        self.dropped += not ok

    def add_many(self, t: npt.NDArray[np.float64], values: npt.NDArray[np.float64]) -> None:
        """Samples in a block: appended at once when they come in order after the newest."""
        buf = self.buf
        if t.size and (buf.n == 0 or t[0] > buf.times[-1]) and np.all(np.diff(t) > 0.0) and math.isfinite(t[-1]):
            if not buf.extend(t, values):
                self.dropped += t.size
            return
        for k in range(t.size):
            self.add(float(t[k]), values[k])

    def latest(self) -> float:
        return float(self.buf.times[-1]) if self.buf.n else -math.inf

    def prune(self, before: float) -> None:
        self.buf.drop_first(int(np.searchsorted(self.buf.times, before, "left")))

    def bound(self, keep: float, now: float) -> None:
        """Keep the samples stamped within ``keep`` s before ``now``, the stamp of the latest arrival
        (pruned in steps of ``keep``; not the newest stamp held, which one sample stamped far in the
        future would make drop everything after it)."""
        if self.buf.n and now - self.buf.times[0] > 2.0 * keep:
            self.prune(now - keep)

    def grid(self, t0: float, period: float, n: int, name: str) -> npt.NDArray[np.float64]:
        """The samples at t0 + k period, k < n; MrilcError naming the first missing one."""
        stamps = self.buf.times
        i0 = int(np.searchsorted(stamps, t0 - 0.25 * period, "left"))
        t = stamps[i0:i0 + n + 1]
        want = t0 + period * np.arange(n)
        if t.size < n:
            missing = n - t.size
            raise MrilcError(f"{missing} of {n} {name} samples missing in the cycle")
        k = np.rint((t[:n] - t0) / period).astype(int)
        if not np.array_equal(k, np.arange(n)) or np.max(np.abs(t[:n] - want)) > 0.25 * period:
            first = int(np.argmax(k != np.arange(n))) if not np.array_equal(k, np.arange(n)) else 0
            raise MrilcError(f"{name} samples are not on the {period:g} s grid from START: first gap or"
                             f" jitter at t = {want[first]:.6f} s (sample {first} of {n})")
        return self.buf.values[i0:i0 + n].copy()


class MrilcSession:
    """Collects joint states (y and effort), the applied reference and cycle events.

    ``on_joint_state(t, positions, efforts)`` and ``on_reference(t, positions)`` take samples
    already ordered as the learner's joints (None for a missing effort); ``on_joint_states`` and
    ``on_references`` take blocks of them (the same as one call a sample). A cycle is learned
    from at its END if the profile the learner sent was installed before its START
    (``profile_ready``), every sample from START to END is there on the grid, finite and within
    the bounds, and the cycle is not longer than ``max_cycle_duration`` s.

    Raises
    ------
    MrilcError
        ``max_cycle_duration``, ``max_abs_position`` or ``max_abs_effort`` not > 0.
    """

    def __init__(self, learner: MrilcLearner, stale_after: float = 0.1, max_cycle_duration: float = MAX_CYCLE_DURATION,
                 max_abs_position: float = MAX_ABS_POSITION, max_abs_effort: float = MAX_ABS_EFFORT) -> None:
        self.learner = learner
        self.period = learner.model.period
        self.stale_after = float(stale_after)
        self.max_cycle_duration = float(max_cycle_duration)
        self.max_abs_position, self.max_abs_effort = float(max_abs_position), float(max_abs_effort)
        if not (math.isfinite(self.max_cycle_duration) and self.max_cycle_duration > 0.0
                and self.max_abs_position > 0.0 and self.max_abs_effort > 0.0):
            raise MrilcError(f"max_cycle_duration (finite), max_abs_position and max_abs_effort must be > 0, got"
                             f" {max_cycle_duration!r}, {max_abs_position!r}, {max_abs_effort!r}")
        self.y, self.ref, self.effort = _Stream(), _Stream(), _Stream()
        self._cycle: int | None = None
        self._start = 0.0
        self._ready_at_start = False
        self._overlong = False
        self.profile_ready = True  # False from sending a profile until it is accepted

    @property
    def latest(self) -> float:
        """The oldest of the newest stamps of y and the reference: how far both have arrived."""
        return min(self.y.latest(), self.ref.latest())

    @property
    def buffered(self) -> int:
        """Samples held, over the three streams."""
        return len(self.y) + len(self.ref) + len(self.effort)

    @property
    def buffered_bytes(self) -> int:
        """Bytes the three streams' buffers take."""
        return self.y.buf.nbytes + self.ref.buf.nbytes + self.effort.buf.nbytes

    def on_joint_state(self, t: float, positions: npt.ArrayLike, efforts: npt.ArrayLike | None = None) -> str | None:
        self.y.add(float(t), positions)
        if efforts is not None:
            self.effort.add(float(t), efforts)
        return self._bound(float(t))

    def on_reference(self, t: float, positions: npt.ArrayLike) -> str | None:
        self.ref.add(float(t), positions)
        return self._bound(float(t))

    def on_joint_states(self, times: npt.ArrayLike, positions: npt.ArrayLike,
                        efforts: npt.ArrayLike | None = None) -> str | None:
        """A block of joint states: times (m,), positions and efforts (m, joints)."""
        t = np.asarray(times, dtype=float).ravel()
        self.y.add_many(t, np.asarray(positions, dtype=float).reshape(t.size, -1))
        if efforts is not None:
            self.effort.add_many(t, np.asarray(efforts, dtype=float).reshape(t.size, -1))
        return self._bound(float(t[-1])) if t.size else None

    def on_references(self, times: npt.ArrayLike, positions: npt.ArrayLike) -> str | None:
        """A block of reference samples: times (m,), positions (m, joints)."""
        t = np.asarray(times, dtype=float).ravel()
        self.ref.add_many(t, np.asarray(positions, dtype=float).reshape(t.size, -1))
        return self._bound(float(t[-1])) if t.size else None

    def _bound(self, t: float) -> str | None:
        """Drop what no cycle needs; a notice when the cycle in progress passes its duration limit."""
        if not math.isfinite(t):
            return None
        if self._cycle is not None and not self._overlong:
            if t - self._start <= self.max_cycle_duration:
                return None
            self._overlong = True
            for s in (self.y, self.ref, self.effort):
                s.prune(t - KEEP_BETWEEN)
            return (f"cycle {self._cycle} has run {t - self._start:.1f} s, longer than max_cycle_duration"
                    f" {self.max_cycle_duration:g} s: its samples are dropped, no more are kept for it, and it will"
                    " not be learned from")
        for s in (self.y, self.ref, self.effort):
            s.bound(KEEP_BETWEEN, t)
        return None

    def on_event(self, kind: int, cycle: int, t: float) -> MrilcCycle | None:
        if kind == START:
            self._cycle, self._start, self._overlong = int(cycle), float(t), False
            self._ready_at_start = self.profile_ready
            for s in (self.y, self.ref, self.effort):
                s.prune(t - 1.0)
            return None
        if kind != END:
            return None
        if self._cycle != int(cycle):
            return MrilcCycle(int(cycle), math.nan, t, skipped=f"END of cycle {cycle} without its START")
        out = MrilcCycle(int(cycle), self._start, float(t))
        self._cycle = None
        if self._overlong or t - self._start > self.max_cycle_duration:
            out.skipped = (f"the cycle lasted {t - self._start:.1f} s, longer than max_cycle_duration"
                           f" {self.max_cycle_duration:g} s (its samples were dropped at the limit)")
            out.refusal = "too_long"
            return out
        if not self._ready_at_start:
            out.skipped = "the cycle started before the learner's profile was installed"
            return out
        if self.latest < t - self.stale_after:
            out.skipped = (f"stale data: the newest joint state / reference is {t - self.latest:.3f} s older than"
                           f" END (limit {self.stale_after:g} s)")
            return out
        n = int(round((t - self._start) / self.period)) + 1
        try:
            y = self.y.grid(self._start, self.period, n, "joint state")
            r = self.ref.grid(self._start, self.period, n, "reference")
            try:
                effort: npt.NDArray[np.float64] | None = self.effort.grid(self._start, self.period, n, "effort")
            except MrilcError:
                effort = None
            why = self._implausible(y, r, effort)
            if why:
                out.skipped, out.refusal = why, "implausible"
                return out
            out.update = self.learner.learn(r, y, effort)
        except MrilcError as err:
            out.skipped = str(err)
        return out

    def _implausible(self, y: npt.NDArray[np.float64], r: npt.NDArray[np.float64],
                     effort: npt.NDArray[np.float64] | None) -> str:
        """Why the cycle's samples are implausible (at or beyond the bounds), or ""."""
        for values, what, limit, unit, name in (
                (y, "joint state position", self.max_abs_position, "rad or m", "sensor.max_abs_position"),
                (r, "reference position", self.max_abs_position, "rad or m", "sensor.max_abs_position"),
                (effort, "effort", self.max_abs_effort, "N or N m", "sensor.max_abs_effort")):
            found = out_of_range(values, limit) if values is not None else None
            if found is not None:
                return "implausible samples: " + found.describe(what, unit, name)
        return ""
