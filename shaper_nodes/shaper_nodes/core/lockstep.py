"""The lockstep exchange between the simulated plant and the shaper, free of ROS.

In lockstep (the sim plant's ``mode: lockstep``) the plant asks the shaper for the shaped setpoints of
its next steps and steps only once the answer is in. This module is the one home of that exchange's
rules; the sim plant node, the shaper node and the reproductions use it.

Asks
    Each ask is a std_msgs/Float64MultiArray of raw setpoints, numbered in its layout's first label:
    ``"joints, ask K"`` for one setpoint (layout [joints]), ``"samples, ask K"`` for a block of the
    setpoints of several steps (layout [samples, joints], ``lockstep.block`` > 1). The shaper passes
    the layout on with the shaped data (:class:`Asks`, :func:`ask_layout`).
Late answers
    An answer labelled with another ask than the pending one (it came after ``lockstep_timeout`` went
    by) is ignored and counted, so that it is never applied to a later step. An answer with no layout,
    or with a layout of its own (a peer that does not pass the plant's on), is taken as the answer to
    the pending ask (:func:`is_late`).
Blocks
    How many samples a received array carries, from its layout sizes (:func:`block_rows`: one without
    a layout or with one dimension, ``sizes[0]`` for [samples, joints]; a layout that does not describe
    the data, or a block of more samples than allowed, is refused with the reason).
Block size
    The block a run at a given rate uses (:func:`lockstep_block`: 0.1 s of samples per exchange).
Readers
    The plant never runs more than a bounded lead of simulated time beyond the slowest reader a run
    declares (the sim plant's ``lockstep.readers``). Each reader acknowledges the simulated time it has
    processed, the oldest of the latest stamps of its streams (:class:`Acks`); the plant holds a step that
    would go beyond the slowest acknowledgement plus ``lockstep.lead`` (:class:`ReaderGate`). A reader that
    acknowledges nothing for ``lockstep.reader_timeout`` s of wall time while the plant waits for it, or whose
    acknowledgements go away, is dropped with one line naming it (it is waited for again once it acknowledges; one
    back from out of the graph is counted from the plant's time then: the steps sent meanwhile never reach it).
Losses
    In lockstep the plant's streams have a known period (``1 / rate``, the IMU's ``1 / (rate substeps)``), so a
    lost sample is a gap in the stamps (:class:`Gaps`); a repeated stamp (the joint states at rest) is none.

A layout dimension is a :class:`Dim` (label, size, stride), the fields of
std_msgs/MultiArrayDimension; the nodes convert at the edge.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import NamedTuple

from .checks import InputError

__all__ = ["ACK_PERIOD", "ANNOUNCE", "ASK_LABELS", "JOINTS_LABEL", "Acks", "Asks", "Dim", "Gaps", "ReaderGate",
           "ask_label", "ask_layout", "block_rows", "is_late", "lockstep_block"]

#: how the first layout label of an ask begins (then the ask's number): one setpoint, a block
ASK_LABELS = ("joints, ask ", "samples, ask ")
#: the second label of a block's layout
JOINTS_LABEL = "joints"


class Dim(NamedTuple):
    """One dimension of a Float64MultiArray layout (std_msgs/MultiArrayDimension's fields)."""

    label: str
    size: int
    stride: int


def ask_label(ask: int, block: bool) -> str:
    """The first layout label of ask number ``ask``: ``"joints, ask K"``, or ``"samples, ask K"`` for a
    block (``block``: the plant exchanges blocks, ``lockstep.block`` > 1)."""
    return f"{ASK_LABELS[1 if block else 0]}{ask}"


def ask_layout(ask: int, rows: int, joints: int, block: bool) -> list[Dim]:
    """The layout of ask number ``ask`` carrying ``rows`` setpoints of ``joints`` joints.

    Parameters
    ----------
    ask : int
        The ask's number (1 for the first).
    rows : int
        Setpoints (samples) in the ask; 1 unless ``block``.
    joints : int
        Values per setpoint.
    block : bool
        The plant exchanges blocks (``lockstep.block`` > 1): layout [samples, joints] even for one row,
        otherwise [joints].

    Returns
    -------
    list of Dim
        [("joints, ask K", joints, joints)], or [("samples, ask K", rows, rows joints),
        ("joints", joints, joints)].
    """
    label = ask_label(ask, block)
    if not block:
        return [Dim(label, joints, joints)]
    return [Dim(label, rows, rows * joints), Dim(JOINTS_LABEL, joints, joints)]


def is_late(label: str | None, pending: str) -> bool:
    """Whether an answer whose first layout label is ``label`` (None: no layout) answers an earlier ask
    than the ``pending`` one: it carries an ask's label, and not the pending ask's. An answer with no
    layout, or with a label of its own, is not late (it is taken as the pending ask's answer)."""
    if not label:
        return False
    return label != pending and label.startswith(ASK_LABELS)


def block_rows(sizes: Sequence[int], values: int, joints: int, max_samples: int) -> int:
    """The samples a received Float64MultiArray carries, from its layout's sizes.

    Parameters
    ----------
    sizes : sequence of int
        The sizes of the layout's dimensions, in order (empty: no layout).
    values : int
        The number of values in the data.
    joints : int
        Values per sample.
    max_samples : int
        The largest block taken, samples.

    Returns
    -------
    int
        1 without a layout or with a layout of one dimension (forward_command_controller's input);
        ``sizes[0]`` for a layout of two, [samples, joints] (the sim plant's blocks), whose rows are
        consecutive samples.

    Raises
    ------
    InputError
        ``wrong_size``: the layout does not describe samples x ``joints`` in ``values`` values;
        ``too_large``: a block of more than ``max_samples`` samples.
    """
    if len(sizes) <= 1:
        return 1
    shape = [int(s) for s in sizes]
    if len(shape) != 2 or shape[1] != joints or shape[0] * joints != values or shape[0] < 1:
        raise InputError("wrong_size", f"layout {shape} does not describe samples x {joints} joints in"
                         f" {values} values")
    if shape[0] > max_samples:
        raise InputError("too_large", f"a block of {shape[0]} samples is more than"
                         f" limits.max_trajectory_samples ({max_samples})")
    return shape[0]


def lockstep_block(rate: float) -> int:
    """The sim plant's ``lockstep.block`` for a run at ``rate`` Hz: 0.1 s of samples per exchange with the
    shaper, at least 1. For a feedforward command path (the shaper between the task and the plant, changed
    only at rest between cycles) a run in blocks is the run one setpoint at a time
    (tests/test_lockstep_blocks.py), with ten to fifty times fewer round trips through DDS."""
    return max(1, int(round(0.1 * rate)))


class Asks:
    """The plant's side of the exchange: numbers its asks and tells late answers from the pending one.

    Parameters
    ----------
    joints : int
        Values per setpoint.
    block : bool
        The plant exchanges blocks (``lockstep.block`` > 1).
    """

    def __init__(self, joints: int, block: bool) -> None:
        self.joints = joints
        self.block = block
        #: asks made so far
        self.count = 0
        #: the first layout label of the pending (latest) ask; '' before the first
        self.pending = ""

    def next(self, rows: int) -> list[Dim]:
        """Number a new ask of ``rows`` setpoints (it becomes the pending one); returns its layout."""
        self.count += 1
        layout = ask_layout(self.count, rows, self.joints, self.block)
        self.pending = layout[0].label
        return layout

    def late(self, label: str | None) -> bool:
        """Whether an answer with first layout label ``label`` (None: no layout) is late (:func:`is_late`)."""
        return is_late(label, self.pending)


#: simulated s a reader's acknowledgement advances before it is sent again (:class:`Acks`)
ACK_PERIOD = 0.02
#: the acknowledgement of a reader that has taken no sample yet: "hold the plant where it is now"
ANNOUNCE = -1.0
#: slack in comparisons of simulated times, s (stamps are whole nanoseconds)
_EPS = 1e-9


class Acks:
    """A reader's side of the lockstep wait: the simulated time it has processed, and when to say it.

    The time processed is the oldest of the latest stamps taken on each of its streams (a stream is taken in
    order, so every earlier sample of it is in); streams that have given nothing yet do not count.

    Parameters
    ----------
    period : float
        Simulated s the acknowledgement advances before it is sent again (:data:`ACK_PERIOD`).
    """

    def __init__(self, period: float = ACK_PERIOD) -> None:
        if not (math.isfinite(period) and period >= 0):
            raise ValueError(f"the acknowledgement period must be finite and >= 0 s, got {period!r}")
        self.period = float(period)
        self.latest: dict[str, float] = {}
        #: the last acknowledgement sent, simulated s (None: none yet)
        self.sent: float | None = None

    @property
    def processed(self) -> float | None:
        """The simulated time processed on every stream, s (None before any sample)."""
        return min(self.latest.values()) if self.latest else None

    def took(self, stream: str, t: float) -> float | None:
        """A sample stamped ``t`` (simulated s) of ``stream`` was taken; returns the acknowledgement to send now
        (the time processed, once it advanced by ``period`` since the last one sent), else None."""
        if t > self.latest.get(stream, -math.inf):
            self.latest[stream] = t
        done = self.processed
        if done is None or (self.sent is not None and done < self.sent + self.period - _EPS):
            return None
        self.sent = done
        return done

    def flush(self) -> float | None:
        """The time processed, if it is beyond the last acknowledgement sent (the last samples before the plant
        rests, which :meth:`took` holds back until ``period`` more are in); else None. A reader calls it on a
        wall-clock timer, so that its acknowledgement reaches the end of a run: the run's client waits on it to
        know the reader has taken every sample (the recorder, before its recording is closed)."""
        done = self.processed
        if done is None or (self.sent is not None and done <= self.sent + _EPS):
            return None
        self.sent = done
        return done


class ReaderGate:
    """The plant's side of the lockstep wait: how far it may step given what its declared readers processed.

    A reader counts from its first acknowledgement (:data:`ANNOUNCE`, "nothing taken yet", holds the plant
    at the simulated time it arrives); a reader not heard from yet does not hold the plant (it has not
    started). The plant may step to ``t`` while ``t <= ack + lead`` for every counted reader.

    Parameters
    ----------
    readers : iterable of str
        The readers' names (node names).
    lead : float
        Simulated s the plant may run beyond the slowest reader's acknowledgement.
    timeout : float
        Wall s the plant waits for a reader that holds it before it drops that reader.
    """

    def __init__(self, readers: Iterable[str], lead: float, timeout: float) -> None:
        self.readers = list(dict.fromkeys(readers))
        if not (math.isfinite(lead) and lead > 0):
            raise ValueError(f"lockstep.lead must be finite and > 0 s, got {lead!r}")
        if not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"lockstep.reader_timeout must be finite and > 0 s, got {timeout!r}")
        self.lead, self.timeout = float(lead), float(timeout)
        #: the simulated time each counted reader processed, s
        self.acked: dict[str, float] = {}
        #: readers dropped (gone, or silent past the timeout) and not back yet
        self.dropped: set[str] = set()
        #: of those, the ones that went away (out of the graph): what the plant sent meanwhile never reaches them
        self.gone: set[str] = set()
        #: wall time (s) the plant started to wait for the reader that holds it; None: not waiting
        self._since: float | None = None
        #: how many times each reader held the plant (a step postponed)
        self.waits: dict[str, int] = {}

    def ack(self, reader: str, t: float, sim_time: float) -> str:
        """Reader ``reader`` processed up to ``t`` (simulated s; :data:`ANNOUNCE`: nothing yet, taken as
        ``sim_time``, the plant's time now). Returns a line to log ('' if none): the first acknowledgement
        counts the reader, or a dropped reader is back."""
        if reader not in self.readers:
            return ""
        value = sim_time if t < 0 else t
        back, first = reader in self.dropped, reader not in self.acked
        missed = reader in self.gone and value < sim_time
        self.dropped.discard(reader)
        self.gone.discard(reader)
        if back or first:
            # a reader back from out of the graph (paused past the DDS lease, its network cut) was unmatched
            # while the plant stepped on: those steps never reach it, so it is counted from now, as a new one
            # (held at what it processed, it held the plant until lockstep.reader_timeout: session 13)
            self.acked[reader] = sim_time if missed else value
        else:
            self.acked[reader] = max(self.acked[reader], value)
        if first:  # (a plant holds only for a reader it has heard: a client may wait for this line)
            return f"lockstep: reader {reader} counted from t = {value:.3f} s (it holds the steps past it)"
        if missed:
            return (f"lockstep: reader {reader} is back (processed up to t = {value:.3f} s; the steps to"
                    f" t = {sim_time:.3f} s went out while it was away and never reach it: counted from there)")
        return f"lockstep: reader {reader} is back (processed up to t = {value:.3f} s)" if back else ""

    def leave(self, reader: str) -> str:
        """Reader ``reader`` went away (its acknowledgements have no publisher any more): dropped. Returns the
        line to log ('' if it was not counted, or was dropped already: then it is marked gone, silently)."""
        if reader not in self.acked:
            return ""
        said = reader in self.dropped
        self.dropped.add(reader)
        self.gone.add(reader)
        if said:
            return ""
        return (f"lockstep: reader {reader} went away (processed up to t = {self.acked[reader]:.3f} s);"
                " stepping on without it")

    def holding(self, t: float) -> list[str]:
        """The counted readers that hold a step to simulated time ``t`` (``t`` beyond their ack plus the lead)."""
        return [r for r, a in self.acked.items() if r not in self.dropped and t > a + self.lead + _EPS]

    def may_step(self, t: float, wall: float) -> tuple[bool, str]:
        """Whether the plant may step to simulated time ``t`` now (``wall``: monotonic wall time, s), and a line
        to log ('' if none): a reader that held the plant for ``timeout`` s is dropped, named in the line."""
        held = self.holding(t)
        if not held:
            self._since = None
            return True, ""
        if self._since is None:
            self._since = wall
            for r in held:
                self.waits[r] = self.waits.get(r, 0) + 1
            return False, ""
        if wall - self._since < self.timeout:
            return False, ""
        self.dropped.update(held)
        self._since = None
        names = ", ".join(f"{r} (processed up to t = {self.acked[r]:.3f} s)" for r in held)
        return not self.holding(t), (f"lockstep: no acknowledgement from reader {names} within"
                                     f" lockstep.reader_timeout ({self.timeout:g} s); stepping on without it")


#: a learned period holds while every spacing is within this fraction of a period of a whole number of periods
GRID_TOLERANCE = 0.01


class Gaps:
    """Lost samples of a stream of known period, from gaps in its stamps.

    Parameters
    ----------
    period : float or None
        The stream's sample period, s; None: the smallest positive spacing seen so far, as long as every spacing is
        a whole number of it (within :data:`GRID_TOLERANCE`): a stream stamped on simulated time (lockstep) is on
        such a grid. One stamped on the wall clock (a real-time plant, a robot's driver) is not: its jitter made
        the smallest spacing a fraction of the period, and every ordinary spacing then counted as lost samples
        (the identifier beside a real-time sim plant: "lost 20878 samples of /joint_states" in a cycle of 2.6 s,
        session 11). Such a stream is :attr:`off_grid` and counts no loss.
    """

    def __init__(self, period: float | None = None) -> None:
        if period is not None and not (math.isfinite(period) and period > 0):
            raise ValueError(f"a stream's period must be finite and > 0 s, got {period!r}")
        self.period = period
        self._fixed = period is not None
        self.last: float | None = None
        self.samples = 0
        #: the gaps: (stamp before, stamp after) of each spacing above 1.5 periods
        self.holes: list[tuple[float, float]] = []
        #: a learned period's stream whose spacings are not whole numbers of it: its gaps are not losses
        self.off_grid = False

    def add(self, t: float) -> None:
        """A sample stamped ``t`` s (a repeated or older stamp is no gap)."""
        self.samples += 1
        last = self.last
        if last is None or t <= last:
            self.last = t if last is None else last
            return
        d = t - last
        if not self._fixed:
            if self.period is None or d < self.period:
                if self.period is not None and not _whole(self.period / d):
                    self.off_grid = True
                self.period = d
            elif not _whole(d / self.period):
                self.off_grid = True
        if self.period is not None and d > 1.5 * self.period:
            self.holes.append((last, t))
        self.last = t

    def lost(self, t0: float = -math.inf, t1: float = math.inf) -> int:
        """Samples missing with stamps in (t0, t1] s (none on a stream that is :attr:`off_grid`)."""
        if self.period is None or self.off_grid:
            return 0
        p, n = self.period, 0
        for a, b in self.holes:  # the missing stamps are a + k p, k = 1 .. m
            m = round((b - a) / p) - 1
            lo = 1 if t0 == -math.inf else max(1, math.floor((t0 - a) / p + 1e-6) + 1)
            hi = m if t1 == math.inf else min(m, math.floor((t1 - a) / p + 1e-6))
            n += max(0, hi - lo + 1)
        return n


def _whole(ratio: float) -> bool:
    """Whether ``ratio`` is a whole number within :data:`GRID_TOLERANCE`."""
    return abs(ratio - round(ratio)) <= GRID_TOLERANCE
