"""The MRILC session: whole cycles on the sample grid from the streams a learner sees, free of ROS.

:class:`MrilcSession` turns the streams of the learner node (joint states, the applied
reference, cycle events) into whole cycles on the sample grid, rejecting cycles with missing,
stale or non-finite samples, and calls :class:`~.learner.MrilcLearner`. The learner node and
offline replays share it.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.cycles import END, START

from .learner import MrilcLearner, MrilcUpdate
from .model import MrilcError


@dataclass
class MrilcCycle:
    """One cycle's outcome: the update, or why it was skipped."""

    cycle: int
    start: float
    end: float
    update: MrilcUpdate | None = None
    skipped: str = ""


class _Stream:
    """Samples keyed by stamp (s), kept in order; old ones dropped."""

    def __init__(self, keep: float = 3600.0) -> None:
        self.t: list[float] = []
        self.v: list[npt.NDArray[np.float64]] = []
        self.keep = keep

    def add(self, t: float, value: npt.NDArray[np.float64]) -> None:
        if self.t and t <= self.t[-1]:
            if t == self.t[-1]:
                self.v[-1] = value  # a repeated stamp: the newest wins
                return
            i = bisect.bisect_left(self.t, t)
            self.t.insert(i, t)
            self.v.insert(i, value)
            return
        self.t.append(t)
        self.v.append(value)

    def latest(self) -> float:
        return self.t[-1] if self.t else -math.inf

    def prune(self, before: float) -> None:
        i = bisect.bisect_left(self.t, before)
        del self.t[:i], self.v[:i]

    def grid(self, t0: float, period: float, n: int, name: str) -> npt.NDArray[np.float64]:
        """The samples at t0 + k period, k < n; MrilcError naming the first missing one."""
        i0 = bisect.bisect_left(self.t, t0 - 0.25 * period)
        t = np.asarray(self.t[i0:i0 + n + 1])
        want = t0 + period * np.arange(n)
        if t.size < n:
            missing = n - t.size
            raise MrilcError(f"{missing} of {n} {name} samples missing in the cycle")
        k = np.rint((t[:n] - t0) / period).astype(int)
        if not np.array_equal(k, np.arange(n)) or np.max(np.abs(t[:n] - want)) > 0.25 * period:
            first = int(np.argmax(k != np.arange(n))) if not np.array_equal(k, np.arange(n)) else 0
            raise MrilcError(f"{name} samples are not on the {period:g} s grid from START: first gap or"
                             f" jitter at t = {want[first]:.6f} s (sample {first} of {n})")
        return np.stack(self.v[i0:i0 + n])


class MrilcSession:
    """Collects joint states (y and effort), the applied reference and cycle events.

    ``on_joint_state(t, positions, efforts)`` and ``on_reference(t, positions)`` take samples
    already ordered as the learner's joints (None for a missing effort). A cycle is learned
    from at its END if the profile the learner sent was installed before its START
    (``profile_ready``), every sample from START to END is there on the grid and finite.
    """

    def __init__(self, learner: MrilcLearner, stale_after: float = 0.1) -> None:
        self.learner = learner
        self.period = learner.model.period
        self.stale_after = float(stale_after)
        self.y, self.ref, self.effort = _Stream(), _Stream(), _Stream()
        self._cycle: int | None = None
        self._start = 0.0
        self._ready_at_start = False
        self.profile_ready = True  # False from sending a profile until it is accepted

    @property
    def latest(self) -> float:
        """The oldest of the newest stamps of y and the reference: how far both have arrived."""
        return min(self.y.latest(), self.ref.latest())

    def on_joint_state(self, t: float, positions: npt.ArrayLike, efforts: npt.ArrayLike | None = None) -> None:
        self.y.add(t, np.asarray(positions, dtype=float))
        if efforts is not None:
            self.effort.add(t, np.asarray(efforts, dtype=float))

    def on_reference(self, t: float, positions: npt.ArrayLike) -> None:
        self.ref.add(t, np.asarray(positions, dtype=float))

    def on_event(self, kind: int, cycle: int, t: float) -> MrilcCycle | None:
        if kind == START:
            self._cycle, self._start = int(cycle), float(t)
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
                effort = self.effort.grid(self._start, self.period, n, "effort")
            except MrilcError:
                effort = None
            out.update = self.learner.learn(r, y, effort)
        except MrilcError as err:
            out.skipped = str(err)
        return out

