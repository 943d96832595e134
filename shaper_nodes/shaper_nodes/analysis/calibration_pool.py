"""The processes that identify a calibration's poses: a pool that does not outlive its parent
(:func:`.worker_pool.worker_pool`), and :class:`PosePipeline`, which identifies each pose in it as soon as its
recording is complete, while the next pose is recorded (``calibrate --execute``), instead of all of them after the last.

Each worker reads its pose's bag itself and returns the pose's result, so the recording process spends no time on
the analysis; the results are those :func:`.calibration.compute` gives on the whole recording (the same function
on the same samples, one BLAS thread in every worker).
"""

from __future__ import annotations

import pathlib
from typing import Any

#: the nice value added to :class:`PosePipeline`'s workers: while poses are recorded the recording is the
#: calibration's critical path (the arm in lockstep with calibrate), and the workers take the CPU it leaves first.
#: Moderate: on a loaded machine a worker at +10 got so little CPU beside the other processes that the poses' results
#: came 2x later than without the pipeline (121 s against 64 s after the last pose, load 23-33)
NICENESS = 5


def warm() -> None:
    """Import what a worker of :class:`PosePipeline` runs (the fits, scipy, matplotlib's Agg backend): done while
    the first poses are recorded, not when their results are awaited."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot
    import scipy.stats  # noqa: F401

    from shaper_nodes.core import identification  # noqa: F401

    from . import calibration_report  # noqa: F401


class PosePipeline:
    """The poses of a calibration run identified in ``pool`` (:func:`.worker_pool.worker_pool` with ``workers``
    processes, :data:`NICENESS`) as their recordings complete.

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
        """The calibration assembled by a worker (:func:`.calibration_report.assemble_from_setup`), its figures
        drawn by the workers at once (the longest first), then the rest of its outputs written by one
        (:func:`.calibration_report.write_outputs`): the files :func:`.calibration_report.write_outputs` alone
        writes, byte for byte. An OSError of the writing is raised here."""
        from .calibration_report import FIGURES, LONGEST, assemble_from_setup, write_figure, write_outputs

        cal = self.pool.submit(assemble_from_setup, setup, results).result()
        names = sorted((name for name, _ in FIGURES), key=lambda name: name != LONGEST)
        jobs = {name: self.pool.submit(write_figure, out, cal, name) for name in names}
        figs = [path for name, _ in FIGURES if (path := jobs[name].result()) is not None]
        return cal, self.pool.submit(write_outputs, out, cal, "recording", figs).result()
