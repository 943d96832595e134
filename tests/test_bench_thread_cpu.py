"""The latency bench's per-thread figures (benchmarks/thread_cpu.py): each node's busiest thread per message.

Pure Python on this process's own threads and on made-up reports (no node, no timing): what is read and printed,
not what it measures.
"""

from __future__ import annotations

import math
import os
import threading

import pytest

from benchmarks.thread_cpu import ThreadCpu, print_threads, thread_times

pytestmark = pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/task"), reason="Linux /proc only")


def _burn() -> None:
    total = 0
    for i in range(3_000_000):
        total += i * i


def test_a_process_threads_are_read_with_their_cpu_wait_and_preemptions():
    times = thread_times(os.getpid())
    run, wait, invol = times[threading.get_native_id()]
    assert run > 0 and wait >= 0 and invol >= 0


def test_the_busiest_thread_is_the_one_that_worked_and_its_figures_are_per_message():
    cpu = ThreadCpu()
    go, done, tid = threading.Event(), threading.Event(), []

    def worker() -> None:
        tid.append(threading.get_native_id())
        for _ in range(2):
            go.wait()
            _burn()
            go.clear()
            done.set()

    t = threading.Thread(target=worker)  # seen by both reads: threads that start or end within a turn are not counted
    t.start()
    while not tid:
        pass
    for _ in range(2):  # two turns, added up
        go.clear()
        done.clear()
        cpu.start(os.getpid())
        go.set()
        done.wait()
        cpu.stop(os.getpid(), 500)
    t.join()
    got = cpu.busiest()
    assert cpu.messages == 1000
    assert got["tid"] == tid[0]
    assert got["cpu_us_per_msg"] > 0 and got["wait_us_per_msg"] >= 0 and got["involuntary_per_msg"] >= 0
    # the main thread (this one, the process's id) waited for the worker; the process's sum holds the worker's
    assert 0 <= got["main_cpu_us_per_msg"] < got["cpu_us_per_msg"] <= got["process_cpu_us_per_msg"]


def test_nothing_read_gives_nan():
    assert all(math.isnan(v) for v in ThreadCpu().busiest().values())


def test_each_group_is_printed_against_its_floor(capsys):
    def run(label: str, cpu: float, main: float | None = None) -> dict:
        thread = {"cpu_us_per_msg": cpu, "wait_us_per_msg": 5.0, "involuntary_per_msg": 0.5, "tid": 1}
        if main is not None:  # the main thread's and the process's, since session 15
            thread.update(main_cpu_us_per_msg=main, process_cpu_us_per_msg=cpu + main + 10.0)
        return {"label": label, "extra": {"thread": thread}}

    lat = {"runs": [run("echo (baseline)", 80.0, 3.0), run("echo, take loop", 40.0), run("shaper zvd 8 Hz", 62.0)],
           "hog_runs": [run("echo, take loop + hog", 45.0), run("shaper zvd 8 Hz + hog", 70.0)]}
    print_threads(lat)
    out = capsys.readouterr().out.splitlines()

    def line(label: str) -> list[str]:
        return next(x for x in out if x.startswith(f"  {label} ")).split()

    assert line("shaper zvd 8 Hz")[4:6] == ["62.0", "+22.0"]  # against the floor of its own group
    assert line("shaper zvd 8 Hz + hog")[6:8] == ["70.0", "+25.0"]
    assert line("echo (baseline)")[2:4] == ["80.0", "+40.0"]
    assert line("echo (baseline)")[6:8] == ["3.0", "93.0"]  # the main thread's and the process's CPU
    assert line("shaper zvd 8 Hz")[8:10] == ["n/a", "n/a"]  # a report without them
