"""``python -m benchmarks._profiled OUT SCRIPT_OR_-m_MODULE [ARGS...]``: run a program with cProfile in
every thread (one profile per thread, merged into ``OUT`` at exit, pstats format).

cProfile alone profiles only the thread that enables it; the shaper node runs its streamed
inputs, its side node and its main executor in threads of their own. Times are each thread's CPU
time (:func:`time.thread_time`), not wall time: on a loaded machine wall time would charge the
other processes' time slices to whatever function was preempted, and blocking waits would count.
"""

from __future__ import annotations

import atexit
import cProfile
import pstats
import runpy
import sys
import threading
import time

_profiles: list[cProfile.Profile] = []
_run = threading.Thread.run


def _profile() -> cProfile.Profile:
    return cProfile.Profile(time.thread_time)


def _profiled_run(self: threading.Thread) -> None:
    prof = _profile()
    _profiles.append(prof)
    prof.enable()
    try:
        _run(self)
    finally:
        prof.disable()


def _dump(out: str) -> None:
    stats: pstats.Stats | None = None
    for prof in _profiles:
        prof.snapshot_stats()  # also for daemon threads still running (their entries so far)
        if not prof.stats:
            continue
        if stats is None:
            stats = pstats.Stats(prof)
        else:
            stats.add(prof)
    if stats is not None:
        stats.dump_stats(out)


def main() -> None:
    out, target, *rest = sys.argv[1:]
    threading.Thread.run = _profiled_run  # type: ignore[method-assign]
    main_prof = _profile()
    _profiles.append(main_prof)
    atexit.register(_dump, out)
    if target == "-m":
        module, *rest = rest
        sys.argv = [module, *rest]
        main_prof.enable()
        try:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
        except SystemExit:
            pass
        finally:
            main_prof.disable()
    else:
        sys.argv = [target, *rest]
        main_prof.enable()
        try:
            runpy.run_path(target, run_name="__main__")
        except SystemExit:
            pass
        finally:
            main_prof.disable()


if __name__ == "__main__":
    main()
