"""The processes that identify a calibration's poses: a pool that does not outlive its parent (:func:`worker_pool`),
and :class:`PosePipeline`, which identifies each pose in it as soon as its recording is complete, while the next
pose is recorded (``calibrate --execute``), instead of all of them after the last.

Each worker reads its pose's bag itself and returns the pose's result, so the recording process spends no time on
the analysis; the results are those :func:`.calibration.compute` gives on the whole recording (the same function
on the same samples, one BLAS thread in every worker).
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import signal
from collections.abc import Iterator
from typing import Any

from shaper_nodes.core.lifetime import die_with_parent

#: one BLAS thread per identifying process: the fits' matrices are small, and several BLAS threads in each
#: of several processes on few cores spin against each other (on 2 cores: the default calibration's
#: identification 10.8 s with them, 4.3 s without)
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: the nice value added to :class:`PosePipeline`'s workers: while poses are recorded the recording is the
#: calibration's critical path (the arm in lockstep with calibrate), and the workers take the CPU it leaves first.
#: Moderate: on a loaded machine a worker at +10 got so little CPU beside the other processes that the poses' results
#: came 2x later than without the pipeline (121 s against 64 s after the last pose, load 23-33)
NICENESS = 5


def _worker_start(parent: int, niceness: int = 0) -> None:
    """A pool worker's start: it ends with the process that started it (``kill -9`` of calibrate leaves no
    worker behind), and leaves Ctrl-C (sent to the whole process group) to that process, which stops it;
    ``niceness`` is added to its nice value (its CPU goes to the others first)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(signal.SIGTERM, parent)
    if niceness:
        os.nice(niceness)


def warm() -> None:
    """Import what a worker of :class:`PosePipeline` runs (the fits, scipy, matplotlib's Agg backend): done while
    the first poses are recorded, not when their results are awaited."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot
    import scipy.stats  # noqa: F401

    from shaper_nodes.core import identification  # noqa: F401

    from . import calibration_report  # noqa: F401


@contextlib.contextmanager
def worker_pool(workers: int, niceness: int = 0) -> Iterator[Any]:
    """A pool of ``workers`` identifying processes (spawned, one BLAS thread each) that do not outlive the
    process that started them: each asks for SIGTERM when its parent ends (:func:`.core.lifetime.die_with_parent`).

    prctl's parent-death signal follows the *thread* that started the worker: use the pool (submit, map) from
    the main thread (calibrate and ``--from-bag`` do), whose life is the process's. Leaving the ``with`` block by
    an exception (Ctrl-C, SIGTERM) ends the workers at once instead of waiting for their poses. ``niceness`` is
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
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class PosePipeline:
    """The poses of a calibration run identified in ``pool`` (:func:`worker_pool` with ``workers`` processes,
    :data:`NICENESS`) as their recordings complete.

    :meth:`submit` hands a completed pose's folder (``pose_NNN``) to a worker (:func:`.calibration.identify_folder`:
    it reads the bag and identifies the pose on the setup recorded in it); :meth:`results` waits for every pose
    submitted and returns the setup they were recorded with and their results in pose order.

    Raises
    ------
    PlanError
        From :meth:`results`: poses recorded under different setups (as :func:`.calibration.read_recording`).
    """

    def __init__(self, pool: Any, setup: dict[str, Any], workers: int) -> None:
        self.pool, self.setup = pool, setup
        self._futures: dict[int, Any] = {}
        for _ in range(workers):  # each starts its worker now (a pool starts one per job waiting), which imports
            pool.submit(warm)     # what it will run while the arm moves

    def submit(self, index: int, folder: pathlib.Path) -> None:
        from .calibration import identify_folder

        self._futures[index] = self.pool.submit(identify_folder, folder, self.setup)

    def results(self) -> tuple[dict[str, Any], list[Any]]:
        from shaper_nodes.core.calibration import PlanError

        setup: dict[str, Any] | None = None
        results = []
        for index in sorted(self._futures):
            this, result = self._futures[index].result()
            if setup is not None and this != setup:
                raise PlanError(f"pose_{index:03d} was recorded with another setup than the poses before it")
            setup = this
            results.append(result)
        if setup is None:
            raise PlanError("no completed pose")
        return setup, results

    def finish(self, out: pathlib.Path, setup: dict[str, Any], results: list[Any]) -> tuple[Any, list[pathlib.Path]]:
        """The calibration assembled and its outputs written in ``out`` by a worker
        (:func:`.calibration_report.assemble_and_write`); an OSError of the writing is raised here."""
        from .calibration_report import assemble_and_write

        return self.pool.submit(assemble_and_write, out, setup, results).result()
