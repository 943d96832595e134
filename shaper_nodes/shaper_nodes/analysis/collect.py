"""What the analysis keeps of each message it reads: the collector of :func:`.streams.read_recording`
(rows per role, decoded with the fast CDR parsers where the layout allows), and the rows turned into
time-ordered, finite :class:`~.signals.Signal` arrays (split out of :mod:`.streams`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.cycles import start_stamp
from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.recordings import BagError
from shaper_nodes.recordings.cdr import JointStateDecoder, imu_fast, joint_state_efforts, little_endian

from .signals import ARRAY, Events, Shapers, Signal


def _stamp(msg, log_ns: int) -> float:
    st = msg.header.stamp
    return stamp_to_sec(st) if (st.sec or st.nanosec) else log_ns * 1e-9



@dataclass
class _Rows:
    """Samples of one topic as read: order in the recording, time (s), values, names (of the first message)."""

    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    p: list[tuple[float, ...]] = field(default_factory=list)
    names: tuple[str, ...] | None = None
    #: indices (into t) of the samples stamped 0, timed by their log time instead (see :func:`_stamped_only`)
    unstamped: list[int] = field(default_factory=list)


class _Collector:
    """The samples of every role, gathered message by message (:meth:`add`), then as arrays (:meth:`signals`).

    Parameters
    ----------
    decoders : dict
        topic -> deserialiser (messages not in little-endian CDR, and the types without a direct parser).
    with_efforts : bool
        Read the joint states' efforts too (when a reference topic is read).
    """

    def __init__(self, decoders: dict[str, Callable[[Any], Any]], with_efforts: bool) -> None:
        self.decoders = decoders
        self.with_efforts = with_efforts
        self.acc_seq: list[int] = []
        self.acc_t: list[float] = []
        self.acc: list[float] = []  # flat x, y, z, x, ...
        self.acc_unstamped: list[int] = []  # as _Rows.unstamped
        self.js, self.ref, self.eff, self.cmd = _Rows(), _Rows(), _Rows(), _Rows()
        self.fast = {"joints": JointStateDecoder(), "reference": JointStateDecoder()}
        self.events, self.shapers = Events(), Shapers()
        self.events_unstamped: list[int] = []  # indices of the events stamped 0 (timed by their log time)

    def add(self, role: str, topic: str, msgtype: str, seq: int, log_ns: int, raw: Any) -> None:
        """Decode one message of ``topic`` (logged at ``log_ns``, ns) and keep what its role uses."""
        if role == "accel":
            self._accel(topic, seq, log_ns, raw)
        elif role in ("joints", "reference"):
            self._joint_state(role, topic, seq, log_ns, raw)
        elif role == "commands":
            self._commands(topic, msgtype, seq, log_ns, raw)
        elif role == "events":
            self._event(topic, seq, log_ns, raw)
        else:
            self._shaper(topic, seq, log_ns, raw)

    def _accel(self, topic: str, seq: int, log_ns: int, raw: Any) -> None:
        if little_endian(raw):
            t, a = imu_fast(raw)
        else:
            m = self.decoders[topic](raw)
            t, la = stamp_to_sec(m.header.stamp), m.linear_acceleration
            a = (la.x, la.y, la.z)
        if t == 0.0:
            self.acc_unstamped.append(len(self.acc_t))
            t = log_ns * 1e-9
        self.acc_seq.append(seq)
        self.acc_t.append(t)
        self.acc.extend(a)

    def _joint_state(self, role: str, topic: str, seq: int, log_ns: int, raw: Any) -> None:
        e: tuple[float, ...] | None = None
        if little_endian(raw):
            fast = self.fast[role]
            t, names, p = fast(raw)
            if role == "joints" and self.with_efforts:
                e = joint_state_efforts(raw, fast.positions_end)
        else:
            m = self.decoders[topic](raw)
            t, names, p = stamp_to_sec(m.header.stamp), tuple(m.name), tuple(m.position)
            e = tuple(m.effort) if role == "joints" and self.with_efforts else None
        d = self.js if role == "joints" else self.ref
        if t == 0.0:
            d.unstamped.append(len(d.t))
            if e is not None and len(e) == len(names):
                self.eff.unstamped.append(len(self.eff.t))
            t = log_ns * 1e-9
        if d.names is None:
            d.names = names
        if e is not None and len(e) == len(names):  # a message without efforts has none
            self.eff.seq.append(seq)
            self.eff.t.append(t)
            self.eff.p.append(e if names == d.names else _reorder(d.names, names, e))
        if names != d.names or len(p) != len(names):
            p = _reorder(d.names, names, p)
        d.seq.append(seq)
        d.t.append(t)
        d.p.append(p)

    def _commands(self, topic: str, msgtype: str, seq: int, log_ns: int, raw: Any) -> None:
        m = self.decoders[topic](raw)
        cmd = self.cmd
        if msgtype == ARRAY:
            dims = m.layout.dim
            if len(dims) == 2 and int(dims[0].size) > 1:  # skipped with this reason in the notes
                raise ValueError(f"a block of {int(dims[0].size)} samples (layout [samples, joints], the sim plant's"
                                 " lockstep.block exchange) has no time per sample")
            cmd.seq.append(seq)
            cmd.t.append(log_ns * 1e-9)
            cmd.p.append(tuple(float(x) for x in m.data))
        else:  # JointTrajectory: each point at stamp + time_from_start
            t0 = _stamp(m, log_ns)
            for pt in m.points:
                cmd.seq.append(seq)
                cmd.t.append(t0 + pt.time_from_start.sec + 1e-9 * pt.time_from_start.nanosec)
                cmd.p.append(tuple(float(x) for x in pt.positions))

    def _event(self, topic: str, seq: int, log_ns: int, raw: Any) -> None:
        m = self.decoders[topic](raw)
        events = self.events
        events.seq.append(seq)
        if not (m.header.stamp.sec or m.header.stamp.nanosec):
            self.events_unstamped.append(len(events.t))
        events.t.append(_stamp(m, log_ns))
        events.kind.append(int(m.event))
        events.cycle.append(int(m.cycle))
        events.start.append(tuple(float(x) for x in m.start_positions))
        events.goal.append(tuple(float(x) for x in m.goal_positions))
        events.joint_names.append(tuple(str(x) for x in m.joint_names))
        start = start_stamp(m)
        events.start_stamp.append(math.nan if start is None else start)

    def _shaper(self, topic: str, seq: int, log_ns: int, raw: Any) -> None:
        m = self.decoders[topic](raw)
        shapers = self.shapers
        shapers.seq.append(seq)
        shapers.t.append(_stamp(m, log_ns))
        shapers.family.append(str(m.family))
        shapers.amplitudes.append(tuple(float(x) for x in m.amplitudes))
        shapers.times.append(tuple(float(x) for x in m.times))
        shapers.source.append(str(m.source))
        shapers.revision.append(int(m.revision))

    def signals(self, path, chosen: dict[str, str], notes: list[str]
                ) -> tuple[Signal, Signal | None, Signal | None, Signal | None, Signal | None]:
        """Accelerometer, joint states, commands, reference and efforts, without non-finite samples (noted).

        Raises
        ------
        BagError
            No accelerometer sample could be read.
        """
        accel = _finite(_signal(chosen["accel"], *_stamped_only(
            chosen["accel"], self.acc_seq, self.acc_t, np.array(self.acc).reshape(-1, 3), self.acc_unstamped, notes)),
            notes) if self.acc else None
        if accel is None or len(accel) == 0:
            raise BagError(f"{path}: no accelerometer message could be read on {chosen['accel']}")
        joints = _rows_signal(chosen["joints"], self.js, notes, self.js.names)
        commands = _rows_signal(chosen["commands"], self.cmd, notes)
        reference = _rows_signal(chosen["reference"], self.ref, notes, self.ref.names)
        efforts = _rows_signal(f"{chosen['joints']} (efforts)", self.eff, notes, self.js.names)
        zero = self.events_unstamped
        if zero and len(zero) < len(self.events.t):  # among stamped events: time 0 of their clock, not unstamped
            for i in zero:
                self.events.t[i] = 0.0
            notes.append(f"{chosen['events']}: {len(zero)} event(s) stamped 0 among stamped ones: taken at time 0"
                         " of their clock (a simulator's first instant), not at the time they were logged")
        return accel, joints, commands, reference, efforts


def _rows_signal(topic: str, rows: _Rows, notes: list[str], names: tuple[str, ...] | None = None
                 ) -> Signal | None:
    """The rows as a :class:`Signal` without non-finite samples (noted), or None if there are none."""
    if not rows.t:
        return None
    seq, t, p = _stamped_only(topic, rows.seq, rows.t, rows.p, rows.unstamped, notes)
    return _finite(_signal(topic, seq, t, p, names or ()), notes)


def _stamped_only(topic: str, seq: list[int], t: list[float], values: Any, unstamped: list[int], notes: list[str]
                  ) -> tuple[list[int], list[float], Any]:
    """The rows without their samples stamped 0 when the others are stamped (noted); all of them when none is.

    A message stamped 0 is timed by its log time (the recorder's clock). In a stream stamped on another clock
    that sample lands far from the others: the lockstep sim plant's joint states at rest before its first step
    are stamped 0 while the rest are on simulated time, and a recording begun before the first move was read as
    one move from the wall-clock time of those samples to the end (session 11). A stream stamped 0 throughout is
    timed by its log times, as before."""
    if not unstamped or len(unstamped) == len(t):
        return seq, t, values
    notes.append(f"{topic}: {len(unstamped)} sample(s) stamped 0 left out (the others are stamped: another clock)")
    keep = np.ones(len(t), dtype=bool)
    keep[unstamped] = False
    idx = np.flatnonzero(keep)
    kept = values[keep] if isinstance(values, np.ndarray) else [values[i] for i in idx]
    return [seq[i] for i in idx], [t[i] for i in idx], kept


def _finite(sig: Signal, notes: list[str]) -> Signal:
    """``sig`` without samples whose time or values are not finite (noted)."""
    good = np.isfinite(sig.t) & np.all(np.isfinite(sig.values), axis=1)
    if good.all():
        return sig
    notes.append(f"{sig.topic}: {int((~good).sum())} sample(s) with non-finite time or values dropped")
    return Signal(sig.topic, sig.seq[good], sig.t[good], sig.values[good], sig.names)


def _reorder(names: tuple[str, ...], got: tuple[str, ...], p: tuple[float, ...]) -> tuple[float, ...]:
    index = dict(zip(got, p, strict=False))  # a malformed message may have fewer values than names
    return tuple(index.get(n, float("nan")) for n in names)


def _signal(topic: str, seq: list[int], t: list[float], values: Sequence[Sequence[float]] | np.ndarray,
            names: Iterable[str] = ()) -> Signal:
    try:
        if isinstance(values, np.ndarray):
            vals = values
        else:  # rows of equal length: flatten first (much faster than from a list of tuples)
            width = len(values[0]) if len(values) else 0
            if any(len(v) != width for v in values):
                raise ValueError("ragged")
            vals = np.fromiter((x for v in values for x in v), dtype=float, count=len(values) * width)
            vals = vals.reshape(len(values), width)
    except ValueError:  # ragged rows (a malformed message) become NaN-padded
        width = max((len(v) for v in values), default=0)
        vals = np.full((len(values), width), np.nan)
        for i, v in enumerate(values):
            vals[i, : len(v)] = v
    seq_a, t_a = np.asarray(seq, dtype=np.int64), np.asarray(t, dtype=float)
    order = np.argsort(t_a, kind="stable")  # by time; equal times keep the recording's order
    return Signal(topic, seq_a[order], t_a[order], vals[order], tuple(names))
