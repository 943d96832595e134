"""Where a test run's time went: per file (set-up, call, teardown) and the slowest tests.

Reads the ``--durations=0`` section that pytest prints at the end of a run::

    ./run test --durations=0 2>&1 | tee run.log
    python scripts/test_durations.py run.log            # per file and the 15 slowest
    python scripts/test_durations.py before.log after.log   # per file, before and after, and the ratio
    python scripts/test_durations.py run.log --tests-of REV  # also: the time of the tests that existed at REV

(pytest hides durations under 5 ms unless ``-vv``; they do not change the sums.) See docs/results/testing.md.
"""

from __future__ import annotations

import argparse
import collections
import pathlib
import re
import subprocess

LINE = re.compile(r"^\s*([\d.]+)s (setup|call|teardown)\s+(\S+?)::(\S.*)$")


def durations(path: pathlib.Path) -> list[tuple[float, str, str, str]]:
    """(seconds, phase, file, test) of every line of the log's durations section."""
    out = []
    for line in path.read_text(errors="replace").splitlines():
        m = LINE.match(line)
        if m:
            out.append((float(m.group(1)), m.group(2), m.group(3), m.group(4)))
    return out


Phases = dict[str, float]  # seconds by phase: setup, call, teardown


def per_file(rows: list[tuple[float, str, str, str]]) -> dict[str, Phases]:
    files: dict[str, Phases] = collections.defaultdict(lambda: dict.fromkeys(("setup", "call", "teardown"), 0.0))
    for seconds, phase, file, _ in rows:
        files[file][phase] += seconds
    return files


def existed(rev: str, file: str, test: str) -> bool:
    """Whether the test function of ``test`` (a node id's name, parameters dropped) was in ``file`` at git
    revision ``rev`` (the tests of an issue's day, say)."""
    name = test.split("[", 1)[0].split("::")[-1]
    try:
        text = subprocess.run(["git", "show", f"{rev}:{file}"], capture_output=True, text=True, check=True).stdout
    except subprocess.CalledProcessError:  # no such file then
        return False
    return re.search(rf"^\s*def {re.escape(name)}\(", text, re.MULTILINE) is not None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Where a test run's time went, from pytest --durations=0.")
    parser.add_argument("logs", type=pathlib.Path, nargs="+", help="one log, or two: before and after")
    parser.add_argument("--top", type=int, default=15, help="slowest tests to list (default 15)")
    parser.add_argument("--tests-of", metavar="REV", help="also sum the tests whose function existed at git REV")
    args = parser.parse_args(argv)
    runs = [durations(p) for p in args.logs]
    for path, rows in zip(args.logs, runs, strict=True):
        if not rows:
            parser.error(f"{path}: no durations section (run pytest with --durations=0)")
    files = [per_file(rows) for rows in runs]
    if len(runs) == 1:
        (table,) = files
        print(f"total {sum(sum(c.values()) for c in table.values()):.1f} s\n")
        print("| s | set-up | call | teardown | file |\n|---:|---:|---:|---:|---|")
        for name, c in sorted(table.items(), key=lambda kv: -sum(kv[1].values())):
            print(f"| {sum(c.values()):.1f} | {c['setup']:.1f} | {c['call']:.1f} | {c['teardown']:.1f} | {name} |")
        print("\n| s | phase | test |\n|---:|---|---|")
        for seconds, phase, file, test in sorted(runs[0], reverse=True)[: args.top]:
            print(f"| {seconds:.2f} | {phase} | {file}::{test} |")
        if args.tests_of:
            known: dict[tuple[str, str], bool] = {}
            old = new = 0.0
            tests: dict[bool, set[str]] = {True: set(), False: set()}
            for seconds, _, file, test in runs[0]:
                key = (file, test)
                if key not in known:
                    known[key] = existed(args.tests_of, file, test)
                tests[known[key]].add(f"{file}::{test}")
                if known[key]:
                    old += seconds
                else:
                    new += seconds
            print(f"\ntests that existed at {args.tests_of}: {len(tests[True])} ({old:.1f} s); added since:"
                  f" {len(tests[False])} ({new:.1f} s). (Tests under 5 ms are not listed by pytest.)")
        return 0
    before, after = files[0], files[-1]
    print("| before s | after s | after / before | file |\n|---:|---:|---:|---|")
    def total(table: dict[str, Phases], name: str) -> float:
        return sum(table[name].values()) if name in table else 0.0

    for name in sorted(set(before) | set(after), key=lambda n: -total(before, n)):
        b, a = total(before, name), total(after, name)
        ratio = f"{a / b:.2f}" if b > 0 else "-"
        print(f"| {b:.1f} | {a:.1f} | {ratio} | {name} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
