"""Run the LIST learner over a recorded bag: the updates it made live, or would have made.

The bag needs the accelerometer (sensor_msgs/Imu), the cycle events (shaper_msgs/CycleEvent)
and the shaper node's active shaper (shaper_msgs/Shaper) — the recorder's default topics
cover them. The replay itself is :func:`shaper_nodes.analysis.replay.replay`: the same
:class:`~shaper_nodes.core.learning.list.ListSession` as the learner node, fed the messages in
the order they were recorded, so a bag recorded during a live run gives the live run's updates.

``list_replay BAG [--param list.rule=paper ...] [--json]`` (also ``ros2 run shaper_nodes
list_replay``).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
from collections.abc import Iterable

from shaper_nodes.analysis.replay import TOPICS, list_row, replay
from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.core.learning.list import ListError


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


@survives_closed_pipe
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
        rows = [list_row(r) for r in replay(args.bag, params, {k: getattr(args, f"{k}_topic") for k in TOPICS})]
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
