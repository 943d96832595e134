"""``python -m reproductions.arm_learning``: the options, the runs of the cases named, the JSON and the page
(or the page alone from an earlier JSON, ``--render``)."""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

from reproductions.arm_learning.pages import figures, markdown
from reproductions.arm_learning.runs import CASES, OUT, Context, Row, calibration, modal_calibration
from reproductions.arm_learning.speed import OPTIONAL_CASES
from reproductions.common import docs_option

#: the CLI's description: the first paragraph of the package's docstring (:mod:`reproductions.arm_learning`)
_DESCRIPTION = (sys.modules[__name__.rpartition(".")[0]].__doc__ or "").split("\n\n")[0]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reproductions.arm_learning", description=_DESCRIPTION)
    p.add_argument("--cycles", type=int, default=10, help="cycles per case (default 10)")
    p.add_argument("--noise", type=float, default=0.0, help="IMU noise, m/s^2 per axis (default 0)")
    p.add_argument("--json", type=pathlib.Path, default=None, help="write every row here as JSON")
    default = [c for c in CASES if c not in OPTIONAL_CASES]
    p.add_argument("--cases", default=",".join(default),
                   help=f"comma-separated cases (default: {','.join(default)}; also {','.join(OPTIONAL_CASES)})")
    p.add_argument("--no-docs", action="store_true", help="do not write the docs page and figures")
    p.add_argument("--schedule", choices=("calibration", "modal"), default="calibration",
                   help="the schedule: the offline calibration (default, cached in out/arm_learning) or the"
                        " modal analysis at the calibration's grid poses (quick)")
    p.add_argument("--render", type=pathlib.Path, default=None,
                   help="write the docs page and figures from the rows of an earlier --json run (no runs)")
    p.add_argument("--out", type=pathlib.Path, default=OUT,
                   help=f"where the moves' learned states and the calibration cache go (default {OUT})")
    docs_option(p, "arm_learning.md and its figures")
    args = p.parse_args(argv)
    if args.cycles < 1:
        p.error(f"--cycles must be >= 1, got {args.cycles}")
    if not (math.isfinite(args.noise) and args.noise >= 0):
        p.error(f"--noise must be finite and >= 0 m/s^2, got {args.noise}")
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        p.error(f"unknown case(s) {', '.join(unknown)}; known: {', '.join(CASES)}")
    if args.render is not None:
        doc = json.loads(args.render.read_text())
        ctx = Context({}, float(doc["noise"]), notes=dict(doc.get("notes", {})))
        _write_docs(args.docs, doc["rows"], ctx, int(doc["cycles"]), float(doc.get("seconds", float("nan"))))
        return 0
    t0 = time.monotonic()
    cal = calibration(args.out / "calibration.json") if args.schedule == "calibration" else modal_calibration()
    ctx = Context(cal, args.noise, out=args.out)
    rows: list[Row] = []
    for case in cases:
        rows += CASES[case](ctx, args.cycles)
        print(f"{case}: done ({time.monotonic() - t0:.0f} s)", flush=True)
    if args.json is not None:
        from shaper_nodes.core.files import write_atomic

        write_atomic(args.json, json.dumps({"noise": args.noise, "cycles": args.cycles, "rows": rows,
                                            "seconds": time.monotonic() - t0,
                                            "notes": ctx.notes}, indent=1, default=float))
    if not args.no_docs:
        _write_docs(args.docs, rows, ctx, args.cycles, time.monotonic() - t0)
    return 0


def _write_docs(docs: pathlib.Path, rows: list[Row], ctx: Context, cycles: int, seconds: float) -> None:
    tag = "" if ctx.noise == 0 else "_noise"
    docs.mkdir(parents=True, exist_ok=True)
    figs = figures(rows, docs, tag)
    text = markdown(rows, ctx, cycles, seconds, figs)
    (docs / f"arm_learning{tag}.md").write_text(text)
    print(text)
