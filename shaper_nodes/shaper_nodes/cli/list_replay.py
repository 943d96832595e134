"""Run the LIST learner over a recorded bag: the updates it made live, or would have made.

The bag needs the accelerometer (sensor_msgs/Imu), the cycle events (shaper_msgs/CycleEvent)
and the shaper node's active shaper (shaper_msgs/Shaper) — the recorder's default topics
cover them. The same :class:`~shaper_nodes.core.list_session.ListSession` as the learner node
is fed the messages in the order they were recorded, and after every update it is told that
the new parameters were sent, as the node does, so a bag recorded during a live run gives
the live run's updates.

``list_replay BAG [--param list.rule=paper ...] [--json]`` (also ``ros2 run shaper_nodes
list_replay``).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from shaper_nodes.core.cycles import END
from shaper_nodes.core.learning.list import ListError, ListLearner, ListParams, ListSession, SessionResult, list_config
from shaper_nodes.core.shaping import Mode

TOPICS = {"imu": "/tip_imu", "events": "/cycle_events", "shaper": "/shaper/active_shaper"}


def _sec(stamp) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


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
    hz = float(values.get("initial.frequency_hz", 0.0))
    initial = (ListParams.from_mode(Mode.from_hz(hz, float(values.get("initial.damping_ratio", 0.0))))
               if hz > 0 else None)
    session = ListSession(ListLearner(config, initial), config.structure, float(values.get("stale_after", 0.1)))
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
        elif kind == "shaper":
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
    """
    from rosbags.highlevel import AnyReader

    from shaper_nodes.ros.bag_writer import typestore_with_own_types

    session_for(params)  # invalid parameters fail before the bag is read
    names = {**TOPICS, **(topics or {})}
    with AnyReader([pathlib.Path(path)], default_typestore=typestore_with_own_types()) as reader:
        conns = [c for c in reader.connections if c.topic in names.values()]
        found = {c.topic for c in conns}
        missing = [t for t in names.values() if t not in found]
        if missing:
            raise ListError(f"bag {path} has no messages on {missing} (topics: {sorted(reader.topics)})")

        def items() -> Iterator[tuple[str, tuple]]:
            for conn, _, raw in reader.messages(connections=conns):
                # typed only at run time (built from the recorded definition); the topic says which fields it has
                msg: Any = reader.deserialize(raw, conn.msgtype)
                if conn.topic == names["imu"]:
                    a = msg.linear_acceleration
                    yield "imu", (_sec(msg.header.stamp), (a.x, a.y, a.z))
                elif conn.topic == names["shaper"]:
                    yield "shaper", (msg.amplitudes, msg.times, msg.source, msg.revision)
                else:
                    yield "event", (int(msg.event), int(msg.cycle), _sec(msg.header.stamp), msg.start_positions,
                                    msg.goal_positions)

        return replay_items(items(), params)


def _row(r: SessionResult) -> dict:
    u = r.update
    if u is None or u.action == "rejected":
        return {"cycle": r.cycle, "skipped": r.skipped or (u.reason if u else "")}
    used = u.used or ListParams(math.nan, math.nan)
    assert u.next is not None  # None only before an initial guess, and such a cycle is rejected
    return {"cycle": r.cycle, "iteration": u.iteration, "M": u.m, "phi": u.phi, "action": u.action,
            "parameter": u.parameter, "a1_used": used.a1, "t2_used": used.t2, "a1_next": u.next.a1,
            "t2_next": u.next.t2}


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def parse_params(items: Iterable[str]) -> dict[str, object]:
    """``NAME=VALUE`` strings (``--param``) as a dict; values parsed as JSON where they are JSON.

    Raises
    ------
    ListError
        An item without ``=``.
    """
    params: dict[str, object] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise ListError(f"--param needs NAME=VALUE, got {item!r}")
        params[name.strip()] = _value(value)
    return params


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="list_replay", description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=pathlib.Path, help="rosbag2 folder or .mcap file")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a learner parameter as given to the live node, e.g. list.highpass_hz=0.3 (repeatable)")
    for key, default in TOPICS.items():
        p.add_argument(f"--{key}-topic", default=default, help=f"topic of the {key} messages (default {default})")
    p.add_argument("--json", action="store_true", help="one JSON document instead of a table")
    args = p.parse_args(argv)
    try:
        params = parse_params(args.param)
        rows = [_row(r) for r in replay(args.bag, params, {k: getattr(args, f"{k}_topic") for k in TOPICS})]
    except (ListError, OSError, ValueError) as err:
        print(f"list_replay: {err}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'cycle':>5} {'M':>10} {'phi deg':>8} {'action':>10} {'A1 used':>9} {'T2 used':>9} {'A1 next':>9}"
          f" {'T2 next':>9}")
    for r in rows:
        if "skipped" in r:
            print(f"{r['cycle']:>5} skipped: {r['skipped']}")
            continue
        print(f"{r['cycle']:>5} {r['M']:>10.4g} {math.degrees(r['phi']):>8.1f} {r['action']:>10} {r['a1_used']:>9.5f}"
              f" {r['t2_used']:>9.5f} {r['a1_next']:>9.5f} {r['t2_next']:>9.5f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
