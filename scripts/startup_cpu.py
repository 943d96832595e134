"""The start-up CPU of every installed executable: ``EXE --help`` run a few times, user + system CPU of each run.

    ./run exec python scripts/startup_cpu.py [--runs 3] [EXECUTABLE ...]

``--help`` imports the executable's module (and through it everything a node imports before it starts) and
prints the usage without starting anything, so its CPU is what every start of the executable pays before the
node is made: the interpreter, the entry-point script's look-up of the package, the imports. Prints a table
(median and spread over the runs, s); on a shared machine compare old and new alternated, with the load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

from shaper_nodes.ros.launching import UsagePopen, executable

#: (package, executable) of every installed executable (the setup.py entry points)
EXECUTABLES = [("shaper_nodes", name) for name in (
    "shaper_node", "recorder", "identifier", "learner", "scheduler", "calibrate", "list_replay", "shaper_design",
    "loop_design", "analyze_bag", "analyze_fleet", "bag_play", "shaper_keystore", "send_goal")] + [
    ("sim_plant_node", "sim_plant"), ("sim_plant_node", "demo")]


def help_cpu(package: str, name: str) -> float:
    """CPU (user + system, s) of one ``name --help``."""
    proc = UsagePopen([str(executable(package, name)), "--help"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    proc.wait()
    assert proc.usage is not None
    return proc.usage.ru_utime + proc.usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="runs of each executable (default 3)")
    parser.add_argument("names", nargs="*", help="executables (default: all)")
    args = parser.parse_args(argv)
    chosen = [e for e in EXECUTABLES if not args.names or e[1] in args.names]
    print(f"load average {os.getloadavg()[0]:.1f}; {args.runs} runs each\n")
    print("| executable | CPU of `--help`, median (s) | min - max (s) |\n|---|---:|---:|")
    for package, name in chosen:
        cpus = [help_cpu(package, name) for _ in range(args.runs)]
        print(f"| {name} | {statistics.median(cpus):.2f} | {min(cpus):.2f} - {max(cpus):.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
