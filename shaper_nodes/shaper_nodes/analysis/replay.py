"""What the learners would have done over a recording: their replays, fed the recorded inputs in
recording order exactly as the live nodes are fed them.

LIST (:func:`replay` over a bag, :func:`replay_items` over a stream of inputs,
:func:`list_replay` over an analysed :class:`~.streams.Recording`): the same
:class:`~shaper_nodes.core.learning.list.ListSession` as the learner node, told after every update
that the new parameters were sent, as the node does, so a bag recorded during a live run gives the
live run's updates. The bag needs the accelerometer (sensor_msgs/Imu), the cycle events
(shaper_msgs/CycleEvent) and the shaper node's active shaper (shaper_msgs/Shaper); the recorder's
default topics cover them.

MRILC (:func:`mrilc_replay`): the joint states, the applied reference and the cycle events fed to a
:class:`~shaper_nodes.core.learning.mrilc.MrilcSession` where the recording has them.

:data:`LEARNER_REPLAYS` maps a learner's name to its replay over a recording (the recording, its
cycles, the segmentation and the parameters given with ``--param``), which returns a
:class:`LearnerReplay`.
"""

from __future__ import annotations

import bisect
import heapq
import pathlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from shaper_nodes.core.cycles import END, MOTION_END, START
from shaper_nodes.core.learning.list import ListError, ListLearner, ListParams, ListSession, SessionResult, list_config
from shaper_nodes.core.shaping import Mode
from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.recordings import shaper_after_end

from .segment import CycleSpan
from .streams import REFERENCE_SUFFIX, Events, Recording, Signal

if TYPE_CHECKING:
    from shaper_nodes.core.learning.mrilc import MrilcModel, MrilcSession

TOPICS = {"imu": "/tip_imu", "events": "/cycle_events", "shaper": "/shaper/active_shaper"}


def _number(values: Mapping[str, Any], name: str, default: float) -> float:
    """``values[name]`` as a float, or a ListError that names the parameter and the value."""
    value = values.get(name, default)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ListError(f"{name} must be a number, got {value!r}") from None


def session_for(params: Mapping[str, object] | None = None) -> ListSession:
    """A fresh ListSession configured as the learner node with these parameters (``list.*``,
    ``initial.frequency_hz``, ``initial.damping_ratio``, ``stale_after``), having asked for the
    identity shaper (the reference cycle) as a fresh node does.

    Raises
    ------
    ListError
        Invalid parameters.
    """
    # values as parsed from JSON or given as text: float() below checks the numeric ones
    values: dict[str, Any] = dict(params or {})
    config = list_config({k[len("list."):]: v for k, v in values.items() if k.startswith("list.")})
    hz = _number(values, "initial.frequency_hz", 0.0)
    initial = (ListParams.from_mode(Mode.from_hz(hz, _number(values, "initial.damping_ratio", 0.0)))
               if hz > 0 else None)
    session = ListSession(ListLearner(config, initial), config.structure, _number(values, "stale_after", 0.1))
    session.sent(None)
    return session


def replay_items(items: Iterable[tuple[str, tuple]], params: Mapping[str, object] | None = None
                 ) -> list[SessionResult]:
    """The learner's per-cycle results over a stream of recorded inputs, in recording order.

    ``items`` are ``("imu", (t, (ax, ay, az)))``, ``("shaper", (amplitudes, times, source,
    revision))`` and ``("event", (kind, cycle, t, start_positions, goal_positions))``, times in s.
    As in the node, an END waits until a sample stamped at or after it has arrived, and after
    every update the session is told that the new parameters were sent.
    """
    session = session_for(params)
    results: list[SessionResult] = []
    pending = None  # an END waits, as in the node, until a sample stamped at or after it arrives

    def event(ev) -> None:
        result = session.on_event(*ev)
        if result is None:
            return
        results.append(result)
        update = result.update
        if update is not None and update.action != "rejected" and update.next != update.used:
            session.sent(update.next)

    for kind, payload in items:
        if kind == "imu":
            session.on_imu(*payload)
            if pending is not None and session.latest_imu >= pending[2]:
                event(pending)
                pending = None
        elif kind == "shaper":  # recorded after the END: the END is handled first (in the node, the change it made
            if pending is not None:  # can only come once the END was handled)
                event(pending)
                pending = None
            session.on_shaper(*payload)
        else:
            if pending is not None:
                event(pending)
                pending = None
            if int(payload[0]) == END and session.latest_imu < payload[2]:
                pending = payload
            else:
                event(payload)
    if pending is not None:
        event(pending)
    return results


def replay(path: str | pathlib.Path, params: Mapping[str, object] | None = None,
           topics: Mapping[str, str] | None = None) -> list[SessionResult]:
    """The learner's per-cycle results over the bag at ``path``.

    Parameters
    ----------
    path : path
        A rosbag2 folder or a bare .mcap file.
    params : mapping
        The learner node's parameters that matter (``list.*``, ``initial.frequency_hz``,
        ``initial.damping_ratio``, ``stale_after``), as given to the live node.
    topics : mapping
        Topic names for "imu", "events" and "shaper" (defaults: :data:`TOPICS`).

    Raises
    ------
    ListError
        Invalid parameters, or the bag lacks one of the topics.
    BagError
        The recording cannot be read (see :class:`shaper_nodes.recordings.Bag`).
    """
    from shaper_nodes.recordings import Bag

    session_for(params)  # invalid parameters fail before the bag is read
    names = {**TOPICS, **(topics or {})}
    with Bag(path) as bag:  # the recordings package's reader: bounded, damaged files recovered
        infos = bag.topics
        missing = [t for t in names.values() if t not in infos]
        if missing:
            raise ListError(f"bag {path} has no messages on {missing} (topics: {sorted(infos)})")
        # typed at run time, from the recorded definitions; the topic says which fields a message has
        decode = {t: bag.deserializer(infos[t].msgtype) for t in names.values()}

        def is_end(m: tuple) -> bool:
            if m[0] != names["events"]:
                return False
            msg: Any = decode[m[0]](m[3])
            return int(msg.event) == END

        def items() -> Iterator[tuple[str, tuple]]:
            ordered = shaper_after_end(bag.messages(list(names.values())), lambda m: m[2],
                                       lambda m: m[0] == names["shaper"], is_end)
            for topic, _, _, raw in ordered:
                msg: Any = decode[topic](raw)
                if topic == names["imu"]:
                    a = msg.linear_acceleration
                    yield "imu", (stamp_to_sec(msg.header.stamp), (a.x, a.y, a.z))
                elif topic == names["shaper"]:
                    yield "shaper", (msg.amplitudes, msg.times, msg.source, msg.revision)
                else:
                    yield "event", (int(msg.event), int(msg.cycle), stamp_to_sec(msg.header.stamp), msg.start_positions,
                                    msg.goal_positions)

        return replay_items(items(), params)


def list_row(r: SessionResult) -> dict[str, Any]:
    """One cycle of a LIST replay as a row: the update's M, phi, action and parameters, or the
    reason it was skipped."""
    u = r.update
    if u is None or u.action == "rejected":
        return {"cycle": r.cycle, "skipped": r.skipped or (u.reason if u else "")}
    used = u.used or ListParams(float("nan"), float("nan"))
    # a learned-from cycle always has next parameters (None only before any initial guess)
    nxt = u.next or ListParams(float("nan"), float("nan"))
    return {"cycle": r.cycle, "iteration": u.iteration, "M": u.m, "phi": u.phi, "action": u.action,
            "parameter": u.parameter, "a1_used": used.a1, "t2_used": used.t2, "a1_next": nxt.a1,
            "t2_next": nxt.t2}


@dataclass
class LearnerReplay:
    """What a learner would have done over the recording, cycle by cycle."""

    name: str
    rows: list[dict]
    notes: list[str] = field(default_factory=list)


def _shaper_order(rec: Recording) -> list[int]:
    """Where each active shaper goes in the recording order: its own place, or just after a cycle's END when it
    was recorded before that END (inside the cycle) yet became active at or after it: logged at the END's own
    stamp (:func:`shaper_nodes.recordings.shaper_after_end`, on the events and shapers in recording order), or
    stamped later than the END (the shaper node stamps a change when it makes it; an END delivered to the recorder
    after the change it caused, session 17's suite: stamps 15.012 against the END's 15.008). The key the merge
    gives such a shaper is then the END's."""
    s, e = rec.shapers, rec.events
    marks = sorted([(q, t, k == END, None) for q, k, t in zip(e.seq, e.kind, e.t, strict=True)]
                   + [(q, t, False, i) for i, (q, t) in enumerate(zip(s.seq, s.t, strict=True))],
                   key=lambda m: m[0])
    out = list(s.seq)
    before = -1  # the recording position of the last event passed
    for q, _, _, i in shaper_after_end(marks, lambda m: m[1], lambda m: m[3] is not None, lambda m: m[2]):
        if i is None:
            before = q
        else:
            out[i] = max(q, before)
    # the next event after each shaper, in recording order: an END stamped no later than the shaper takes it along
    events = sorted(zip(e.seq, e.kind, e.t, strict=True))
    seqs = [q for q, _, _ in events]
    for i, (q, t) in enumerate(zip(out, s.t, strict=True)):
        k = bisect.bisect_right(seqs, q)
        if k < len(events) and events[k][1] == END and events[k][2] <= t:
            out[i] = events[k][0]
    return out


def _list_items(rec: Recording, spans: list[CycleSpan], from_events: bool, assume_unshaped: bool
                ) -> Iterator[tuple[str, tuple]]:
    """The recording as the LIST learner's input stream, in recording order."""
    acc = rec.accel

    def imu():
        for q, t, a in zip(acc.seq.tolist(), acc.t.tolist(), acc.values.tolist(), strict=True):
            yield (q, 0), "imu", (t, a)

    def shapers():
        s = rec.shapers
        if assume_unshaped:
            yield (-1, 1), "shaper", ((1.0,), (0.0,), "assumed", 0)
        for i, q in enumerate(_shaper_order(rec) if from_events else s.seq):
            yield (q, 1), "shaper", (s.amplitudes[i], s.times[i], s.source[i], s.revision[i])

    def events():
        if from_events:
            e = rec.events
            for i in np.argsort(np.asarray(e.seq), kind="stable"):
                yield (e.seq[i], 0), "event", (e.kind[i], e.cycle[i], e.t[i], e.start[i], e.goal[i])
            return
        for s in spans:
            yield (s.start_seq, 0), "event", (START, s.cycle, s.start, s.start_positions, s.goal_positions)
            yield (s.motion_end_seq, 0), "event", (MOTION_END, s.cycle, s.motion_end, (), ())
            if s.complete:
                yield (s.end_seq, 0), "event", (END, s.cycle, s.end, (), ())

    for _, kind, payload in heapq.merge(imu(), shapers(), events(), key=lambda x: x[0]):
        yield kind, payload


def list_replay(rec: Recording, spans: list[CycleSpan], segmentation: str, params: Mapping[str, object]
                ) -> LearnerReplay:
    """LIST over the recording: the learner node's per-cycle updates (:func:`replay_items`)."""
    notes = []
    params = {k: v for k, v in params.items()}
    try:
        session_for(params)
    except ListError as err:
        return LearnerReplay("list", [], [f"not run: {err}"])
    by_events = segmentation.startswith("cycle events")
    assume = not rec.shapers.seq
    if not by_events:
        notes.append("cycle boundaries from the motion, not from events")
    if assume:
        notes.append("no active-shaper topic: the first cycle is taken as unshaped; later cycles ran"
                     " without the learner's shaper, so the learner could only make its first update")
    rows = [list_row(r) for r in replay_items(_list_items(rec, spans, by_events, assume), params)]
    learned = sum(1 for r in rows if "skipped" not in r)
    notes.append(f"{learned} of {len(rows)} cycles learned from")
    return LearnerReplay("list", rows, notes)


def mrilc_replay(rec: Recording, spans: list[CycleSpan], segmentation: str, params: Mapping[str, object]
                 ) -> LearnerReplay:
    """MRILC over the recording: the learner node's per-cycle updates, where the data allows.

    Needs the cycle events, the joint states' positions (y; efforts optional, for RMS(u1)) and the
    applied reference (role "reference", ``--reference-topic``) for the learner's joints
    (``joint_names``, else those of the first START, as the node takes them). The model is built
    from the node's ``mrilc.*`` parameters (:func:`~shaper_nodes.core.learning.mrilc.model_from_params`).
    With ``replay.learned_run`` false (default: a recording made without the learner), only the
    first cycle learned from gives a valid update (the later ones did not run with the learned
    profile) and the rest are listed as skipped; true replays every cycle, as for a recording of a
    live MRILC run.
    """
    from shaper_nodes.core.learning.mrilc import MrilcError, MrilcLearner, MrilcSession, model_from_params

    def refused(why: str) -> LearnerReplay:
        return LearnerReplay("mrilc", [], [f"not possible: {why}"])

    missing = _mrilc_missing(rec)
    if missing or rec.joints is None or rec.reference is None:  # (the same: the missing ones are named)
        return refused("the recording has no " + "; no ".join(missing))
    joints, reference = rec.joints, rec.reference
    learned_run = params.get("replay.learned_run", False)
    if not isinstance(learned_run, bool):
        return refused(f"parameter replay.learned_run must be true or false, got {learned_run!r}")
    try:
        model, settings = model_from_params(params)
    except MrilcError as err:
        return refused(str(err))
    names = _mrilc_joint_names(rec.events, joints, settings.joint_names)
    cols = {}
    for label, sig in (("joint states", joints), ("reference", reference)):
        absent = [n for n in names if n not in sig.names]
        if absent:
            return refused(f"the {label} ({sig.topic}) lack joint(s) {absent} (they have {list(sig.names)})")
        cols[label] = [sig.names.index(n) for n in names]
    efforts = _efforts_by_seq(rec.efforts, names)
    stale = params.get("stale_after", 0.1)
    if isinstance(stale, bool) or not isinstance(stale, (int, float)) or not stale > 0:
        return refused(f"parameter stale_after must be a number > 0 s, got {stale!r}")
    learner = MrilcLearner(model, len(names), settings.patience, settings.noise_floor)
    learner.holding = not settings.learn
    session = MrilcSession(learner, float(stale))
    notes = [_mrilc_setup(names, joints, reference, bool(efforts), model)]
    stream = heapq.merge(_joint_samples(joints, cols["joint states"], efforts),
                         _reference_samples(reference, cols["reference"]), _event_samples(rec.events),
                         key=lambda x: x[0])
    rows = _mrilc_rows(session, stream, learned_run)
    learned = sum(1 for r in rows if "skipped" not in r)
    notes.append(f"{learned} of {len(rows)} cycles learned from")
    if not learned_run and learned:
        notes.append("a recording made without learning gives only the first update: later cycles did not run"
                     " with the learned profile")
    return LearnerReplay("mrilc", rows, notes)


def _mrilc_missing(rec: Recording) -> list[str]:
    """What the MRILC replay needs and the recording lacks."""
    missing = []
    if not rec.events.kind:
        missing.append("cycle events (shaper_msgs/CycleEvent)")
    if rec.joints is None or not rec.joints.names:
        missing.append("joint states with named positions (sensor_msgs/JointState)")
    if rec.reference is None:
        missing.append(f"applied reference (a sensor_msgs/JointState topic ending in '{REFERENCE_SUFFIX}',"
                       " or --reference-topic)")
    return missing


def _mrilc_joint_names(events: Events, joints: Signal, configured: tuple[str, ...]) -> list[str]:
    """The learner's joints: ``configured``, else those of the first START, else the joint states'."""
    names = list(configured)
    if not names:
        # joint_names is filled last for each event: one decoded with an older CycleEvent definition
        # (without joint_names) leaves it shorter than kind
        first = [n for k, n in zip(events.kind, events.joint_names, strict=False) if k == START and n]
        names = list(first[0]) if first else list(joints.names)
    return names


def _efforts_by_seq(efforts: Signal | None, names: list[str]) -> dict[int, np.ndarray]:
    """Recording-order index -> efforts of the joints ``names`` (nothing if no efforts were recorded)."""
    if efforts is None:
        return {}
    e_cols = [efforts.names.index(n) for n in names]
    return dict(zip(efforts.seq.tolist(), efforts.values[:, e_cols], strict=True))


def _mrilc_setup(names: list[str], joints: Signal, reference: Signal, with_efforts: bool, model: MrilcModel) -> str:
    """The replay's first note: joints, topics, and the reference model (its mode in rad/s)."""
    mode = (f"{model.mode.omega:.4g} rad/s, zeta {model.mode.zeta:.4g}" if model.mode is not None
            else "none lightly damped")
    return (f"joints {names}; joint states {joints.topic}, reference {reference.topic}"
            + ("" if with_efforts else " (no efforts recorded: RMS(u1) not available)")
            + f"; model: reference mode {mode}, law {model.law.law}, {1 / model.period:g} Hz")


def _joint_samples(joints: Signal, cols: list[int], efforts: dict[int, np.ndarray]
                   ) -> Iterator[tuple[int, int, tuple[Any, ...]]]:
    """(recording order, 0, (time s, positions of the learner's joints, efforts or None)) per joint state."""
    for q, t, v in zip(joints.seq.tolist(), joints.t.tolist(), joints.values[:, cols], strict=True):
        yield q, 0, (t, v, efforts.get(q))


def _reference_samples(reference: Signal, cols: list[int]) -> Iterator[tuple[int, int, tuple[Any, ...]]]:
    """(recording order, 1, (time s, reference of the learner's joints)) per reference sample."""
    for q, t, v in zip(reference.seq.tolist(), reference.t.tolist(), reference.values[:, cols], strict=True):
        yield q, 1, (t, v)


def _event_samples(events: Events) -> Iterator[tuple[int, int, tuple[Any, ...]]]:
    """(recording order, 2, (kind, cycle, time s)) per cycle event, in recording order."""
    for i in np.argsort(np.asarray(events.seq), kind="stable"):
        yield events.seq[i], 2, (events.kind[i], events.cycle[i], events.t[i])


def _mrilc_rows(session: MrilcSession, stream: Iterator[tuple[int, int, tuple[Any, ...]]], learned_run: bool
                ) -> list[dict]:
    """Feed the merged samples and events to ``session``: one row per cycle it reports (an update, or why not)."""
    unapplied = ("ran without the learned profile (a recording made without learning; --param"
                 " replay.learned_run=true for a recording of a live MRILC run)")
    rows: list[dict] = []

    def handle(event) -> None:
        result = session.on_event(*event)
        if result is None:
            return
        u = result.update
        if u is None:
            not_installed = not learned_run and result.skipped.startswith("the cycle started before")
            rows.append({"cycle": result.cycle, "skipped": unapplied if not_installed else result.skipped})
            return
        rows.append({"cycle": result.cycle, "iteration": u.iteration, "rms_e": u.rms_e, "rms_u1": u.rms_u1,
                     "rms_u2": u.rms_u2, "residual": u.residual, "action": u.action})
        # the node installs the new profile before the next START; a recording made without
        # learning never ran with it, so its later cycles are not learned from
        session.profile_ready = learned_run

    # as the node waits at an END for the samples stamped up to it (they may be logged after the
    # END), an END and the events after it wait until both streams have reached its stamp
    pending: list[tuple[int, int, float]] = []
    for _, kind, payload in stream:
        if kind == 0:
            session.on_joint_state(*payload)
        elif kind == 1:
            session.on_reference(*payload)
        else:
            pending.append(payload)
        while pending and (pending[0][0] != END or session.latest >= pending[0][2]):
            handle(pending.pop(0))
    for event in pending:  # the recording ended: what is still missing is missing
        handle(event)
    return rows


#: learner name -> replay function (recording, cycles, segmentation, parameters) -> LearnerReplay
LEARNER_REPLAYS: dict[str, Callable[[Recording, list[CycleSpan], str, Mapping[str, object]], LearnerReplay]] = {
    "list": list_replay,
    "mrilc": mrilc_replay,
}


