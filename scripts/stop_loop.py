"""Issue 33's measurement: a node stopped right after its first log line, many times, and how it ended.

Each run starts ``shaper_node`` (as the suite starts nodes, ros/launching.py), waits until its log file has
its first line (the node made, its executor threads started), sends the signal, waits for the exit and counts
aborts ("terminate called without an active exception", exit -6), other non-zero exits (a segmentation fault
is -11) and tracebacks in the log. Before issue 33 a SIGINT there aborted or crashed a few times in 30 runs
(docs/guide/shaper_node.md, *Stopping it*).

Run with ``./run exec python scripts/stop_loop.py`` (``--runs``, ``--signal INT|TERM``, ``--logs``); set
``ROS_DOMAIN_ID`` to a domain of its own.
"""

from __future__ import annotations

import argparse
import collections
import pathlib
import signal
import subprocess
import tempfile
import time

from shaper_nodes.ros.launching import NodeProcess

#: the shaper node's parameters for the runs (two joints, a ZV shaper)
PARAMS = {"joint_names": ["j1", "j2"], "command_rate": 100.0, "shaper.family": "zv", "shaper.frequency_hz": 5.0}
UP, DOWN = 120.0, 60.0  # s, bounds on start-up and on the stop


def one_run(sig: signal.Signals, log: pathlib.Path) -> tuple[int, str]:
    """Start, wait for the first log line, signal, wait; the exit code and the log's text."""
    proc = NodeProcess("shaper_nodes", "shaper_node", PARAMS, log_path=log).start()
    assert proc.proc is not None
    end = time.monotonic() + UP
    while time.monotonic() < end and proc.running() and not log.read_text().strip():
        time.sleep(0.005)
    proc.proc.send_signal(sig)
    try:
        code = proc.proc.wait(DOWN)
    except subprocess.TimeoutExpired:
        proc.proc.kill()
        code = proc.proc.wait()
    proc.stop()
    return code, log.read_text()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--signal", choices=("INT", "TERM"), default="INT")
    ap.add_argument("--logs", type=pathlib.Path, default=None,
                    help="folder for the runs' logs (default: a temporary one)")
    args = ap.parse_args()
    sig = signal.Signals[f"SIG{args.signal}"]
    logs = args.logs or pathlib.Path(tempfile.mkdtemp(prefix="stop_loop-"))
    logs.mkdir(parents=True, exist_ok=True)
    codes: collections.Counter[int] = collections.Counter()
    aborts = tracebacks = 0
    for k in range(args.runs):
        code, text = one_run(sig, logs / f"shaper-{k}.log")
        codes[code] += 1
        aborts += "terminate called" in text
        tracebacks += "Traceback" in text
        if code != 0 or "Traceback" in text or "terminate called" in text:
            print(f"run {k}: exit {code}; {text.strip().splitlines()[-1]}", flush=True)
    print(f"{args.runs} runs, {sig.name} after the first log line: {aborts} aborts ('terminate called'),"
          f" {sum(n for c, n in codes.items() if c != 0)} non-zero exits, {tracebacks} with a traceback;"
          f" exit codes {dict(sorted(codes.items()))}; logs in {logs}")


if __name__ == "__main__":
    main()
