"""Where the test suite's CPU goes: a summary of the CPU log of a run with ``SHAPER_CPU_LOG`` set.

    SHAPER_CPU_LOG=$PWD/cpu.jsonl ./run test tests/test_calibrate.py
    ./run exec python scripts/test_cpu.py cpu.jsonl                # the 25 tests with the most CPU, by executable
    ./run exec python scripts/test_cpu.py before.jsonl after.jsonl  # the same tests: CPU before, after, ratio

The log (root conftest.py, shaper_nodes/ros/launching.py) has a line per test (the pytest worker's own CPU in the
test's protocol and that of the processes it reaped meanwhile) and a line per process reaped by any process of
the run (its CPU with that of the processes it reaped). A process's own CPU here is its CPU less that of the
logged processes it reaped (the demo CLI less its nodes).
"""

from __future__ import annotations

import collections
import json
import sys
from collections.abc import Iterable


def read(path: str) -> tuple[dict[str, dict], list[dict]]:
    """The tests (by node id: the last line of a test wins) and the processes of a CPU log."""
    tests: dict[str, dict] = {}
    procs: list[dict] = []
    with open(path) as f:
        for line in f:
            row = json.loads(line)
            if row["kind"] == "test":
                tests[row["test"]] = row
            else:
                procs.append(row)
    return tests, procs


def own_cpu(procs: list[dict]) -> list[tuple[dict, float]]:
    """Each process with its own CPU (s): its logged CPU less that of the logged processes it reaped."""
    reaped: dict[int, float] = collections.defaultdict(float)
    for p in procs:
        reaped[p["parent"]] += p["user"] + p["sys"]
    return [(p, p["user"] + p["sys"] - reaped.get(p["pid"], 0.0)) for p in procs]


def total(row: dict) -> float:
    return row["user"] + row["sys"] + row["children_user"] + row["children_sys"]


def table(rows: Iterable[Iterable[object]]) -> str:
    return "\n".join("| " + " | ".join(str(c) for c in r) + " |" for r in rows)


def summary(path: str, top: int = 25) -> str:
    tests, procs = read(path)
    own = own_cpu(procs)
    by_test: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for p, _ in own:
        by_test[p["test"]][p["name"]] += 1
    worker = sum(t["user"] + t["sys"] for t in tests.values())
    children = sum(t["children_user"] + t["children_sys"] for t in tests.values())
    wall = sum(t["wall"] for t in tests.values())
    out = [f"{len(tests)} tests: {worker + children:.0f} s of CPU ({worker:.0f} s in pytest, {children:.0f} s in "
           f"{len(procs)} processes they started), {wall:.0f} s of wall time summed over the tests", ""]
    out.append(f"The {top} tests with the most CPU (pytest's + the processes', s):\n")
    rows: list[tuple[object, ...]] = [("CPU", "pytest", "processes", "wall", "test", "processes started")]
    for name, t in sorted(tests.items(), key=lambda kv: -total(kv[1]))[:top]:
        started = ", ".join(f"{n} {k}" for k, n in by_test[name].most_common())
        rows.append((f"{total(t):.1f}", f"{t['user'] + t['sys']:.1f}", f"{t['children_user'] + t['children_sys']:.1f}",
                     f"{t['wall']:.1f}", name, started))
    out.append(table(rows[:1]) + "\n|" + "---|" * len(rows[0]) + "\n" + table(rows[1:]))
    out.append("\nProcesses by executable (own CPU, s):\n")
    per: dict[str, list[float]] = collections.defaultdict(list)
    for p, cpu in own:
        per[p["name"]].append(cpu)
    rows = [("executable", "processes", "CPU", "median per process (s)")]
    for name, cpus in sorted(per.items(), key=lambda kv: -sum(kv[1])):
        rows.append((name, len(cpus), f"{sum(cpus):.1f}", f"{sorted(cpus)[len(cpus) // 2]:.2f}"))
    out.append(table(rows[:1]) + "\n|" + "---|" * len(rows[0]) + "\n" + table(rows[1:]))
    return "\n".join(out)


def compare(before: str, after: str) -> str:
    old, _ = read(before)
    new, _ = read(after)
    common = sorted(set(old) & set(new), key=lambda n: -total(old[n]))
    a, b = sum(total(old[n]) for n in common), sum(total(new[n]) for n in common)
    rows: list[tuple[object, ...]] = [("before", "after", "ratio", "test")]
    rows += [(f"{total(old[n]):.1f}", f"{total(new[n]):.1f}", f"{total(new[n]) / max(total(old[n]), 1e-9):.2f}", n)
             for n in common]
    return (f"{len(common)} tests in both: {a:.0f} s of CPU before, {b:.0f} s after ({b / max(a, 1e-9):.2f})\n\n"
            + table(rows[:1]) + "\n|---|---|---|---|\n" + table(rows[1:]))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (1, 2):
        print(__doc__, file=sys.stderr)
        return 2
    print(summary(args[0]) if len(args) == 1 else compare(*args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
