"""Analyse a fleet's recordings in parallel on Dask: modes over time per robot, drift alerts, retunes.

``analyze_fleet FOLDER [--out DIR]`` (also ``ros2 run shaper_nodes analyze_fleet``) finds every
recording under FOLDER (rosbag2 folders, bare .mcap files), analyses those not already in the
cache (``FOLDER/.fleet_cache``; keyed by the SHA-256 of the recording's bytes, the options and the
analysis version) on a local Dask cluster (``--workers N`` processes, one thread and one BLAS
thread each; ``--workers 0``: a plain loop in this process) or on an existing cluster
(``--scheduler tcp://host:port``; its workers must see FOLDER at the same path), groups them by
robot (``robot`` in the rosbag2 metadata's custom_data, else the parent folder's name), compares
each robot's later recordings with its first ones, and prints the alerts; ``--out`` writes the
report (Markdown, CSV, JSON, PNG). Every recording is read within the bounds ``analyze_bag`` has
(``--max-metadata-mib``, ``--max-chunk-mib``); one beyond them is not analysed, with analyze_bag's
message. See docs/guide/fleet.md. Exit codes: 0 done (alerts or not; ``--strict``:
1 when there are alerts), 2 the fleet cannot be analysed (the message says why).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys

from shaper_nodes.analysis.fleet import MAX_RECORDINGS, Cache, FleetError, find_recordings, run_fleet
from shaper_nodes.analysis.fleet_drift import DriftRule, fleet_drift
from shaper_nodes.analysis.fleet_report import fleet_doc, headline, write_fleet_report

from .analyze_bag import add_limit_options, limits_of
from .common import add_analysis_options, analysis_options


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="analyze_fleet", description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=pathlib.Path, help="folder holding the recordings (searched recursively)")
    p.add_argument("--out", type=pathlib.Path, help="write the fleet report here (Markdown, CSV, JSON, PNG)")
    p.add_argument("--json", action="store_true", help="print the report as JSON instead of the summary")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=2,
                       help="local Dask worker processes (one thread each; default 2); 0: no Dask, a plain loop")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--cache", type=pathlib.Path, help="cache folder (default FOLDER/.fleet_cache)")
    p.add_argument("--no-cache", action="store_true", help="analyse every recording, store nothing")
    p.add_argument("--max-recordings", type=int, default=MAX_RECORDINGS,
                   help=f"refuse a folder with more recordings than this (default {MAX_RECORDINGS})")
    p.add_argument("--quiet", action="store_true", help="no progress bar (none either when stderr is not a terminal)")
    g = p.add_argument_group("drift rule (docs/guide/fleet.md)")
    g.add_argument("--baseline", type=int, default=5, help="each robot's first N recordings with a mode (default 5)")
    g.add_argument("--max-frequency-shift", type=float, default=0.05,
                   help="frequency change counted, fraction of the baseline (default 0.05)")
    g.add_argument("--max-damping-change", type=float, default=0.5,
                   help="damping ratio change counted, fraction of the baseline's (default 0.5)")
    g.add_argument("--damping-floor", type=float, default=0.005,
                   help="smallest damping ratio change counted, absolute (default 0.005)")
    g.add_argument("--drift-sigmas", type=float, default=3.0,
                   help="the change must also exceed this many combined standard deviations (default 3)")
    g.add_argument("--confirm", type=int, default=2, help="recordings out in a row before an alert (default 2)")
    a = p.add_argument_group("analysis of each recording (the same as analyze_bag's)")
    add_analysis_options(a)
    add_limit_options(a)  # the bounds of analyze_bag: a recording beyond them is refused as analyze_bag refuses it
    p.add_argument("--strict", action="store_true", help="exit 1 when a robot has an alert")
    args = p.parse_args(argv)
    if args.workers < 0 or args.max_recordings < 1:
        p.error("--workers must be >= 0 and --max-recordings >= 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)

    def warn(text: str) -> None:
        print(f"analyze_fleet: WARNING: {text}", file=sys.stderr)

    try:
        options = analysis_options(args, learners=())
        rule = DriftRule(baseline=args.baseline, max_frequency_shift=args.max_frequency_shift,
                         max_damping_change=args.max_damping_change, damping_floor=args.damping_floor,
                         sigmas=args.drift_sigmas, confirm=args.confirm, target=args.target, sigmas_box=args.sigmas,
                         min_saving=args.min_saving)
        paths = find_recordings(args.folder, args.max_recordings)
        if not paths:
            raise FleetError(f"{args.folder}: no recording (rosbag2 folder or .mcap file) found")
        cache = None if args.no_cache else Cache(args.cache or args.folder / ".fleet_cache")
        run = run_fleet(paths, options, cache, workers=args.workers, scheduler=args.scheduler,
                        progress=not args.quiet and sys.stderr.isatty(), warn=warn, limits=limits_of(args),
                        root=args.folder)
    except (FleetError, ValueError, OSError) as err:
        print(f"analyze_fleet: {err}", file=sys.stderr)
        return 2
    drift = fleet_drift(run.results, rule)
    for r in run.results:
        if r.error:
            warn(f"{r.path}: not analysed: {r.error}")
    if args.out:
        files = write_fleet_report(run, drift, rule, args.out)
        print(f"report: {args.out / 'fleet.md'} ({len(files)} files)", file=sys.stderr)
    alerts = [d for d in drift if d.verdict == "ALERT"]
    if args.json:
        print(json.dumps(fleet_doc(run, drift, rule), indent=1, allow_nan=False))
    else:
        print(headline(run, drift))
        for d in drift:
            base = f"baseline {d.baseline_hz:8.4g} Hz" if math.isfinite(d.baseline_hz) else "baseline: none     "
            why = ": the baseline is not steady (below)" if d.baseline_issue and not d.alerts else ""
            print(f"  {d.robot:<20} {len(d.points):>4} rec.  {base}  {d.verdict}{why}"
                  + (f"  ({d.note})" if d.note else ""))
            if d.baseline_issue:
                print(f"      the baseline is not steady: {d.baseline_issue}")
            for p in d.points:
                for h in p.result.headline:
                    print(f"      {p.result.path}: {h}")
            for a in d.alerts:
                retune = (f"{a.retune['family']} at {a.retune['designed_hz']:.4g} Hz" if a.retune else "none")
                print(f"      from {a.first_out}: {a.why}; retune: {retune}")
    return 1 if args.strict and alerts else 0


if __name__ == "__main__":
    raise SystemExit(main())
