"""The hop above the floor against the shaper's own work, from the nodes' own timers in the same run.

The latency bench runs the floor (``echo_node --take``) and the shaper targets with
:data:`shaper_nodes.ros.stream_watch.WORK_TIMING_ENV` naming a file beside each node's log: the node then times, as
it runs at 1 kHz (caches cold from the wait between messages), its array callback (``callback``) and the wake-up
before it (``wake``: from the middleware's reception of the message to the callback's start), and for the shaper
the callback's work (``work``: ``RawArrays.shape``, the read, the stream's rules, the FIR and the write) and its
publish (``publish``); it writes their medians and spreads when it stops
(:class:`~shaper_nodes.ros.stream_watch.WorkTiming`). The floor's callback is its publish (a (message, info)
callback when timed, as the shaper's). Unset (any run of the node outside the bench) nothing is wrapped: no cost.

:func:`decomposition` sets them beside the round trips: the shaper's p50 above the floor's (its ``+p50``) against
its work's median. When the two agree (within the work's spread) the hop adds nothing beyond the work it must do.
The timers cost the shaper a little more than the floor (two timed calls inside the callback, about a fraction
of a microsecond each): the shaper's p50 carries that too.
"""

from __future__ import annotations

import math
import pathlib
from typing import Any

from shaper_nodes.ros.stream_watch import WORK_TIMING_ENV

#: the floor's label prefix (benchmarks/latency_targets.py, echo_target with take)
FLOOR = "echo, take loop"
#: the label of the floor that does the ZVD shaper's work (benchmarks/latency_suite.py, benchmarks/echo_node.py --shape)
LEAN = "floor + ZVD work"


def work_path(log_path: pathlib.Path) -> pathlib.Path:
    """The file a node logging to ``log_path`` writes its timers to."""
    return log_path.with_suffix(".work.json")


def work_env(log_path: pathlib.Path) -> dict[str, str]:
    """The environment that has a node (logging to ``log_path``) time its callback (:func:`work_path`)."""
    return {WORK_TIMING_ENV: str(work_path(log_path))}


def _p50(run: dict, name: str) -> float:
    part = run.get("extra", {}).get("work", {}).get(name)
    return float(part["p50_us"]) if part else math.nan


def decomposition(runs: list[dict]) -> list[dict[str, Any]]:
    """Per shaper run of one group (``runs``: LatencyResult dicts, the floor among them): its p50 above the floor's,
    and the medians of its work, publish and callback and of the floor's callback (us; NaN where not timed)."""
    floor = next((r for r in runs if r["label"].startswith(FLOOR)), None)
    if floor is None:
        return []
    out = []
    for r in runs:
        if not r["label"].startswith(("shaper", LEAN)):
            continue
        above = r["p50_us"] - floor["p50_us"]
        work = _p50(r, "work")
        out.append({"label": r["label"], "p50_us": r["p50_us"], "floor_p50_us": floor["p50_us"], "above_us": above,
                    "work_us": work, "work_p90_us": r.get("extra", {}).get("work", {}).get("work", {}).get("p90_us",
                                                                                                         math.nan),
                    "publish_us": _p50(r, "publish"), "callback_us": _p50(r, "callback"),
                    "floor_callback_us": _p50(floor, "callback"), "above_minus_work_us": above - work,
                    "wake_us": _p50(r, "wake"), "floor_wake_us": _p50(floor, "wake")})
    return out


def _f(value: float, spec: str = ".1f") -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def print_decomposition(lat: dict) -> None:
    """The table of :func:`decomposition` for each group of ``lat`` (the bench's latency report)."""
    rows = decomposition(lat["runs"]) + decomposition(lat.get("hog_runs", []))
    if not rows:
        return
    print("  the hop above the floor against the node's own work (medians over every message, timed in the nodes at")
    print("  1 kHz; work: read, rules, FIR, write; the floor's callback is its publish; wake: reception to callback;")
    print("  the timers are in the shaper's p50: loaded runs of session 13 put the timed ZVD at 1.19x the floor, the")
    print("  untimed at 1.09-1.12x: judge the p50 goal with --skip-work-timing as well)")
    head = (f"  {'node':<24}{'+p50 us':>9}{'work':>7}{'p90':>6}{'+p50-work':>10}{'publish':>9}{'floor pub':>10}"
            f"{'callback':>9}{'wake':>7}{'floor wake':>11}")
    print(head)
    for q in rows:
        print(f"  {q['label']:<24}{_f(q['above_us']):>9}{_f(q['work_us']):>7}{_f(q['work_p90_us']):>6}"
              f"{_f(q['above_minus_work_us'], '+.1f'):>10}{_f(q['publish_us']):>9}{_f(q['floor_callback_us']):>10}"
              f"{_f(q['callback_us']):>9}{_f(q['wake_us']):>7}{_f(q['floor_wake_us']):>11}")


def summary_rows(lat: dict, row: Any, goal: str) -> list[dict[str, Any]]:
    """The summary table's rows: each shaper's p50 above the floor against its work (``row``: the bench's
    ``_row``; ``goal`` for ZVD)."""
    rows = []
    for q in decomposition(lat["runs"]) + decomposition(lat.get("hog_runs", [])):
        if not math.isnan(q["work_us"]):
            rows.append(row(f"latency {q['label']}: p50 above the floor", q["above_us"], "us",
                            "its work per message in the node (median)", q["work_us"],
                            goal=goal if q["label"].startswith("shaper zvd") else ""))
    return rows
