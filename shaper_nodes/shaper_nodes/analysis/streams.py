"""Find the topics an analysis needs, by type, and extract them into arrays.

Roles and the types that fill them (:data:`ROLE_TYPES`): the accelerometer (sensor_msgs/Imu),
the joint states (sensor_msgs/JointState), the commands (std_msgs/Float64MultiArray as
forward_command_controller takes them, or trajectory_msgs/JointTrajectory), the cycle events
(shaper_msgs/CycleEvent), the active shaper (shaper_msgs/Shaper) and the applied reference
(sensor_msgs/JointState positions, what the MRILC replay needs). When several topics have a
role's type, the one named as this suite and ROS name it (:data:`PREFERRED`) is taken, else the
one with the most messages (ties: the first by name); the choice is reported and can be forced.
The reference is only taken by default from a JointState topic whose name ends in "reference"
(the sim plant's ``/sim_plant/reference``), and such a topic is not taken for the joint states
while another one exists. When a reference topic is read, the joint states' efforts are read too.

Times are the messages' header stamps where they have one (non-zero), else the time the message
was logged; everything is in seconds on the recording's clock (simulated time in lockstep runs).
Imu and JointState messages in little-endian CDR are decoded by a direct parser of the fields
used (:mod:`shaper_nodes.recordings.cdr`, checked against rosbags' deserialiser in the tests); other
layouts go through rosbags.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.recordings import Bag, BagError, Damage, ReadLimits, ReadResult, TopicInfo, describe_damage
from shaper_nodes.recordings.cdr import JointStateDecoder, imu_fast, joint_state_efforts, little_endian

IMU, JOINT_STATE = "sensor_msgs/msg/Imu", "sensor_msgs/msg/JointState"
ARRAY, TRAJECTORY = "std_msgs/msg/Float64MultiArray", "trajectory_msgs/msg/JointTrajectory"
EVENT, SHAPER = "shaper_msgs/msg/CycleEvent", "shaper_msgs/msg/Shaper"

#: role -> message types that fill it
ROLE_TYPES: dict[str, tuple[str, ...]] = {
    "accel": (IMU,),
    "joints": (JOINT_STATE,),
    "commands": (ARRAY, TRAJECTORY),
    "events": (EVENT,),
    "shaper": (SHAPER,),
    "reference": (JOINT_STATE,),
}
#: names taken first when several topics have a role's type
PREFERRED: dict[str, tuple[str, ...]] = {
    "accel": ("/tip_imu", "/imu", "/imu/data"),
    "joints": ("/joint_states",),
    "commands": ("/shaper/commands",),
    "events": ("/cycle_events",),
    "shaper": ("/shaper/active_shaper",),
    "reference": ("/sim_plant/reference",),
}
#: the reference role takes by default only topics whose name ends so
REFERENCE_SUFFIX = "reference"


@dataclass
class Events:
    """Cycle events: order in the recording, time (s), kind, cycle, start and goal positions."""

    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    kind: list[int] = field(default_factory=list)
    cycle: list[int] = field(default_factory=list)
    start: list[tuple[float, ...]] = field(default_factory=list)
    goal: list[tuple[float, ...]] = field(default_factory=list)
    joint_names: list[tuple[str, ...]] = field(default_factory=list)


@dataclass
class Shapers:
    """Active-shaper messages: order, time it became active (s), family, impulses, source, revision."""

    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    family: list[str] = field(default_factory=list)
    amplitudes: list[tuple[float, ...]] = field(default_factory=list)
    times: list[tuple[float, ...]] = field(default_factory=list)
    source: list[str] = field(default_factory=list)
    revision: list[int] = field(default_factory=list)


@dataclass
class Signal:
    """Samples of one topic: order in the recording, time (s) and values (N, k)."""

    topic: str
    seq: np.ndarray
    t: np.ndarray
    values: np.ndarray
    names: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass
class Recording:
    """What an analysis uses of a bag, as arrays, and what was chosen, skipped or lost."""

    path: str
    topics: dict[str, str]  # role -> topic ("" if none)
    accel: Signal  # never empty: a recording without accelerometer samples is refused
    joints: Signal | None
    commands: Signal | None
    events: Events
    shapers: Shapers
    messages_read: int
    notes: list[str]
    damage: list[Damage]
    reader: str
    all_topics: dict[str, str]  # topic -> type
    reference: Signal | None = None  # the applied reference's positions (role "reference")
    efforts: Signal | None = None    # the joint states' efforts (read with a reference), joints' names


def choose_topics(topics: Mapping[str, TopicInfo], overrides: Mapping[str, str] | None = None
                  ) -> tuple[dict[str, str], list[str]]:
    """role -> topic for every role (``""`` if the bag has none), and notes on the choices.

    Parameters
    ----------
    topics : mapping
        topic -> TopicInfo (``msgtype``, ``count``).
    overrides : mapping
        role -> topic to use instead (must exist, with a type of that role).

    Raises
    ------
    BagError
        An override names a topic that is not in the bag or has the wrong type.
    """
    chosen: dict[str, str] = {}
    notes: list[str] = []
    for role, types in ROLE_TYPES.items():
        forced = (overrides or {}).get(role)
        if forced:
            info = topics.get(forced)
            if info is None:
                raise BagError(f"--{role}-topic {forced}: no such topic in the bag (topics: {sorted(topics)})")
            if info.msgtype not in types:
                raise BagError(f"--{role}-topic {forced} has type {info.msgtype}, expected one of {list(types)}")
            chosen[role] = forced
            continue
        cands = [info for info in topics.values() if info.msgtype in types]
        if role == "reference":
            cands = [c for c in cands if c.topic.endswith(REFERENCE_SUFFIX)]
        elif role == "joints" and any(not c.topic.endswith(REFERENCE_SUFFIX) for c in cands):
            cands = [c for c in cands if not c.topic.endswith(REFERENCE_SUFFIX)]
        if not cands:
            chosen[role] = ""
            continue
        pref = [c for c in cands if c.topic in PREFERRED.get(role, ())]
        pick = pref[0] if pref else sorted(cands, key=lambda c: (-(c.count or 0), c.topic))[0]
        chosen[role] = pick.topic
        if len(cands) > 1:
            others = ", ".join(sorted(c.topic for c in cands if c.topic != pick.topic))
            notes.append(f"{role}: took {pick.topic} ({pick.msgtype}); also of that type: {others}"
                         f" (choose with --{role}-topic)")
    if chosen["reference"] and chosen["reference"] == chosen["joints"] and not (overrides or {}).get("reference"):
        notes.append(f"reference: {chosen['reference']} is the only JointState topic, taken as the joint states")
        chosen["reference"] = ""
    return chosen, notes


# ------------------------------------------------------------------------------ extraction
class Progress:
    """A progress line on stderr (messages read, percent, rate), at most twice a second."""

    def __init__(self, total: int | None, enabled: bool = True, stream=sys.stderr) -> None:
        self.total, self.enabled, self.stream = total, enabled, stream
        self.t0 = self._last = time.monotonic()
        self.shown = False

    def __call__(self, done: int) -> None:
        now = time.monotonic()
        if not self.enabled or now - self._last < 0.5:
            return
        self._last, self.shown = now, True
        rate = done / max(now - self.t0, 1e-9)
        if self.total:
            frac = min(done / self.total, 1.0)
            bar = "#" * int(30 * frac)
            eta = (self.total - done) / rate if rate > 0 else 0.0
            text = (f"\rreading [{bar:<30}] {100 * frac:5.1f} % {done}/{self.total} messages, {rate:,.0f}/s,"
                    f" {eta:.0f} s left")
        else:
            text = f"\rreading {done} messages, {rate:,.0f}/s"
        self.stream.write(text)
        self.stream.flush()

    def close(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


def _stamp(msg, log_ns: int) -> float:
    st = msg.header.stamp
    return stamp_to_sec(st) if (st.sec or st.nanosec) else log_ns * 1e-9


def read_recording(path, overrides: Mapping[str, str] | None = None, progress: bool = False,
                   on_progress: Callable[[int], None] | None = None, limits: ReadLimits | None = None) -> Recording:
    """Open the bag at ``path``, choose the topics and extract them.

    A recording that rosbags opens but fails to read to the end (a corrupt record in an indexed
    file) is read again record by record, skipping what is corrupt.

    Raises
    ------
    BagError
        Not a recording, unreadable, beyond the reading limits (``limits``, see
        :class:`~shaper_nodes.recordings.ReadLimits`), no message, or no accelerometer topic.
    """
    try:
        return _read(path, overrides, progress, on_progress, recover=False, limits=limits)
    except _ReadFailed as err:
        rec = _read(path, overrides, progress, on_progress, recover=True, limits=limits)
        rec.notes.insert(0, f"rosbags stopped reading after {err.count} messages ({err.reason});"
                            " read again record by record")
        return rec


class _ReadFailed(Exception):
    def __init__(self, count: int, reason: str) -> None:
        super().__init__(reason)
        self.count, self.reason = count, reason


def _read(path, overrides, progress, on_progress, recover: bool, limits: ReadLimits | None = None) -> Recording:
    with Bag(path, recover=recover, limits=limits) as bag:
        infos = bag.topics
        chosen, roles, notes = _roles(path, bag, infos, overrides)
        decoders = _decoders(bag, roles, infos, notes)
        wanted = set(decoders)
        total = sum(infos[t].count or 0 for t in wanted) or None
        show = Progress(total, progress)
        got = _Collector(decoders, with_efforts=bool(chosen["reference"]))
        result = ReadResult()
        seq = _read_messages(bag.messages(wanted, result), roles, got, show, on_progress, path, recover, notes)
        if seq < 0:
            raise BagError(f"{path}: no messages could be read on {sorted(wanted)}")
        accel, joints, commands, reference, efforts = got.signals(path, chosen, notes)
        return Recording(str(path), chosen, accel, joints, commands, got.events, got.shapers, result.messages, notes,
                         list(bag.damage), bag.reader_name, {t: i.msgtype for t, i in infos.items()},
                         reference, efforts)


def _roles(path, bag: Bag, infos: dict[str, TopicInfo], overrides: Mapping[str, str] | None
           ) -> tuple[dict[str, str], dict[str, str], list[str]]:
    """role -> topic, topic -> role of the topics read, and the notes so far (the bag's, the choices').

    Raises
    ------
    BagError
        The bag has no topics or no accelerometer topic, or one topic is taken for two roles.
    """
    if not infos and bag.damage:
        said = [n for n in bag.notes if "not closed" in n] or [describe_damage(d) for d in bag.damage]
        raise BagError("nothing readable before the damage (no channel, no message): " + "; ".join(said))
    if not infos:
        raise BagError(f"{path}: the recording has no topics (empty bag)")
    chosen, notes = choose_topics(infos, overrides)
    notes = list(bag.notes) + notes
    if not chosen["accel"]:
        raise BagError(f"{path}: no accelerometer topic (sensor_msgs/msg/Imu); topics: "
                       + ", ".join(f"{t} [{i.msgtype}]" for t, i in sorted(infos.items())))
    if chosen["reference"] and chosen["reference"] == chosen["joints"]:
        raise BagError(f"{path}: {chosen['reference']} cannot be both the joint states and the reference"
                       " (choose another with --joints-topic or --reference-topic)")
    roles = {topic: role for role, topic in chosen.items() if topic}
    unused = sorted(f"{t} [{i.msgtype}]" for t, i in infos.items() if t not in roles)
    if unused:
        notes.append("not used: " + ", ".join(unused))
    return chosen, roles, notes


def _decoders(bag: Bag, roles: dict[str, str], infos: dict[str, TopicInfo], notes: list[str]
              ) -> dict[str, Callable[[Any], Any]]:
    """topic -> deserialiser of the topics read; a topic whose type cannot be decoded is noted and skipped."""
    decoders: dict[str, Callable[[Any], Any]] = {}
    for topic in roles:
        msgtype = infos[topic].msgtype
        try:
            decoders[topic] = bag.deserializer(msgtype)
        except BagError as err:
            notes.append(f"{topic} skipped: {err}")
    return decoders


def _read_messages(messages: Iterator[tuple[str, str, int, Any]], roles: dict[str, str], got: _Collector,
                   show: Progress, on_progress: Callable[[int], None] | None, path, recover: bool,
                   notes: list[str]) -> int:
    """Feed every message to ``got``, noting the topics whose messages could not be decoded.

    Returns the recording-order index of the last message read (-1: none).

    Raises
    ------
    BagError
        Reading failed, in a record-by-record read (``recover``).
    _ReadFailed
        Reading failed, in a read with rosbags.
    """
    bad: dict[str, int] = {}
    first_error: dict[str, str] = {}
    seq = -1
    while True:
        try:
            topic, msgtype, log_ns, raw = next(messages)
        except StopIteration:
            break
        except Exception as err:
            if recover:
                raise BagError(f"{path}: reading failed after {seq + 1} messages: {err}") from None
            raise _ReadFailed(seq + 1, f"{type(err).__name__}: {err}") from None
        seq += 1
        if seq % 4096 == 0:
            show(seq)
            if on_progress:
                on_progress(seq)
        role = roles[topic]
        try:
            got.add(role, topic, msgtype, seq, log_ns, raw)
        except Exception as err:
            bad[topic] = bad.get(topic, 0) + 1
            first_error.setdefault(topic, f"{type(err).__name__}: {err}")
    show.close()
    for topic, n in bad.items():
        notes.append(f"{topic}: {n} message(s) could not be decoded and were skipped (first: {first_error[topic]})")
    return seq


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
        events.t.append(_stamp(m, log_ns))
        events.kind.append(int(m.event))
        events.cycle.append(int(m.cycle))
        events.start.append(tuple(float(x) for x in m.start_positions))
        events.goal.append(tuple(float(x) for x in m.goal_positions))
        events.joint_names.append(tuple(str(x) for x in m.joint_names))

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
