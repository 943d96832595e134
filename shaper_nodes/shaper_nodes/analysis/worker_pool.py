"""A pool of processes that do not outlive their parent, one BLAS thread each (:func:`worker_pool`): calibrate's
identification runs in it (:func:`.calibration.compute`, :class:`.calibration_pool.PosePipeline`)."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from typing import Any

from shaper_nodes.core.lifetime import die_with_parent

#: one BLAS thread per identifying process: the fits' matrices are small, and several BLAS threads in each
#: of several processes on few cores spin against each other (on 2 cores: the default calibration's
#: identification 10.8 s with them, 4.3 s without)
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


#: how long a pool left by an exception waits for its manager thread to wind down, s (its workers are ended)
MANAGER_WAIT = 10.0


def _worker_start(parent: int, niceness: int = 0) -> None:
    """A pool worker's start: it ends with the process that started it (``kill -9`` of calibrate leaves no
    worker behind), and leaves Ctrl-C (sent to the whole process group) to that process, which stops it;
    ``niceness`` is added to its nice value (its CPU goes to the others first)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(signal.SIGTERM, parent)
    if niceness:
        os.nice(niceness)


@contextlib.contextmanager
def worker_pool(workers: int, niceness: int = 0) -> Iterator[Any]:
    """A pool of ``workers`` identifying processes (spawned, one BLAS thread each) that do not outlive the
    process that started them: each asks for SIGTERM when its parent ends (:func:`.core.lifetime.die_with_parent`).

    prctl's parent-death signal follows the *thread* that started the worker: use the pool (submit, map) from
    the main thread (calibrate and ``--from-bag`` do), whose life is the process's. Leaving the ``with`` block by
    an exception (Ctrl-C, SIGTERM, calibrate's abort) ends the workers at once instead of waiting for their poses,
    and waits for the pool's manager thread to wind down: left running, it closed its wake-up pipe while the
    interpreter's exit woke it, and calibrate's abort ended in "OSError: [Errno 9] Bad file descriptor" under a
    traceback (once, at load average 25: "no publisher of /tip_imu within 30 s", session 11). ``niceness`` is
    added to each worker's nice value (:class:`PosePipeline`'s, so that the recording goes first).
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    saved = {k: os.environ.get(k) for k in SINGLE_THREAD}
    os.environ.update(SINGLE_THREAD)  # read by each worker as it starts (spawn copies the environment)
    try:
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_worker_start, initargs=(os.getpid(), niceness))
        try:
            yield pool
        except BaseException:
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            manager = getattr(pool, "_executor_manager_thread", None)
            pool.shutdown(wait=False, cancel_futures=True)
            if manager is not None:  # wound down (its workers are ended) before the caller exits: at exit
                manager.join(MANAGER_WAIT)  # CPython 3.11 wakes it, racing its closing of that pipe (EBADF)
            raise
        pool.shutdown(wait=True)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
