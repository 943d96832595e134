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
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from shaper_nodes.recordings import Bag, BagError, Damage, ReadLimits, ReadResult, TopicInfo, describe_damage

from .collect import _Collector, _stamp  # noqa: F401 (re-exported)
from .signals import (
    ARRAY,
    EVENT,
    IMU,
    JOINT_STATE,
    SHAPER,
    TRAJECTORY,
    Events,
    Shapers,
    Signal,
)

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
