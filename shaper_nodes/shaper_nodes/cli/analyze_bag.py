"""Analyse a recording: residual vibration per cycle, modes, a better shaper, what a learner would do.

``analyze_bag BAG [--out DIR] [--json]`` (also ``ros2 run shaper_nodes analyze_bag``) reads a
rosbag2 folder or a bare .mcap file (a truncated or corrupt MCAP too: what can be read is
analysed, and a warning says what was lost), finds the accelerometer, joint-state, command,
cycle-event and shaper topics by type, segments the cycles (from the cycle events, else from the
motion of the commands), replays the learners (LIST; MRILC where the recording has the cycle
events, joint states and the applied reference), and prints a table; ``--out`` writes a report
folder (Markdown, CSV, JSON, PNG plots); ``--json`` prints the summary as JSON instead of the
table. See
docs/guide/analysis.md. Exit codes: 0 done, 2 the recording cannot be analysed (the message says
why), 3 analysed but the recording was damaged (with ``--strict``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from shaper_nodes.analysis.analyze import analyze
from shaper_nodes.analysis.replay import LEARNER_REPLAYS
from shaper_nodes.analysis.report import summary, table, write_report
from shaper_nodes.analysis.streams import ROLE_TYPES, read_recording
from shaper_nodes.core.closed_pipe import survives_closed_pipe
from shaper_nodes.recordings import MIB, Bag, BagError, ReadLimits, describe_damage

from .common import add_analysis_options, analysis_options
from .list_replay import parse_params


def add_limit_options(p: argparse._ActionsContainer) -> None:
    """The reading limits' options (``--max-chunk-mib``, ``--max-metadata-mib``), the same in analyze_fleet."""
    p.add_argument("--max-chunk-mib", type=float, default=ReadLimits.chunk_bytes / MIB,
                   help="refuse an MCAP chunk that declares more than this uncompressed, MiB, before inflating it"
                        " (default %(default)g)")
    p.add_argument("--max-metadata-mib", type=float, default=ReadLimits.metadata_bytes / MIB,
                   help="refuse a metadata.yaml larger than this, MiB, before parsing it (default %(default)g)")


def limits_of(args: argparse.Namespace) -> ReadLimits:
    """The reading limits the options of :func:`add_limit_options` ask for."""
    return ReadLimits(metadata_bytes=int(args.max_metadata_mib * MIB), chunk_bytes=int(args.max_chunk_mib * MIB))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="analyze_bag", description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=pathlib.Path, help="rosbag2 folder or .mcap file")
    p.add_argument("--out", type=pathlib.Path, help="write the report folder here (Markdown, CSV, JSON, PNG)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead of the table")
    for role, types in ROLE_TYPES.items():
        p.add_argument(f"--{role}-topic", metavar="TOPIC", help=f"the {role} topic ({' or '.join(types)};"
                       " default: found by type)")
    add_analysis_options(p.add_argument_group("analysis (the same in analyze_fleet)"))
    p.add_argument("--learners", default=",".join(LEARNER_REPLAYS),
                   help=f"learner replays to run, comma-separated, '' for none (known: {','.join(LEARNER_REPLAYS)})")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a learner parameter as given to the live node, e.g. list.highpass_hz=0.5 or"
                        " mrilc.gamma=10 (repeatable); replay.learned_run=true replays every MRILC cycle"
                        " (a recording of a live MRILC run)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    add_limit_options(p)
    p.add_argument("--strict", action="store_true", help="exit 3 when the recording was damaged")
    return p.parse_args(argv)


def _damage_of(path: pathlib.Path, limits: ReadLimits) -> list[str]:
    """What a recording lost, described (nothing if it cannot be opened or is whole)."""
    try:
        with Bag(path, limits=limits) as bag:
            return [describe_damage(d) for d in bag.damage]
    except Exception:
        return []


def _holds_recordings(path: pathlib.Path) -> bool:
    """``path`` is a folder of several recordings (not one): a hint to use analyze_fleet."""
    from shaper_nodes.analysis.fleet import FleetError, find_recordings

    try:
        return path.is_dir() and len(find_recordings(path, limit=2)) > 1
    except (FleetError, OSError):
        return True  # more than the limit: several


@survives_closed_pipe
def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    limits = limits_of(args)
    try:
        params = parse_params(args.param)
        overrides = {role: getattr(args, f"{role}_topic") for role in ROLE_TYPES if getattr(args, f"{role}_topic")}
        options = analysis_options(args, learners=tuple(x.strip() for x in args.learners.split(",") if x.strip()),
                                   learner_params=params)
        rec = read_recording(args.bag, overrides, progress=not args.no_progress and sys.stderr.isatty(),
                             limits=limits)
        an = analyze(rec, options)
    except (BagError, OSError, ValueError) as err:
        print(f"analyze_bag: {err}", file=sys.stderr)
        for text in _damage_of(args.bag, limits):  # what the recording holds, even if it cannot be analysed
            print(f"analyze_bag: WARNING: damaged recording: {text}", file=sys.stderr)
        if _holds_recordings(args.bag):
            print(f"analyze_bag: {args.bag} holds several recordings: analyze_fleet analyses them all"
                  " (docs/guide/fleet.md)", file=sys.stderr)
        return 2
    for d in rec.damage:
        print(f"analyze_bag: WARNING: damaged recording: {describe_damage(d)}", file=sys.stderr)
    if args.out:
        files = write_report(an, args.out)
        if not args.json:
            print(f"report: {args.out / 'report.md'} ({len(files)} files)", file=sys.stderr)
    if args.json:
        print(json.dumps(summary(an), indent=2, allow_nan=False))
    else:
        print(table(an))
    return 3 if args.strict and rec.damage else 0


if __name__ == "__main__":
    raise SystemExit(main())
