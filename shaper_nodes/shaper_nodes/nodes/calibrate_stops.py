"""How a calibrate run stops: its exit statuses, the stops as exceptions, the signals it ends on, the params file
it refuses to parse.

Every stop ends calibrate with one line on stderr naming the cause, and a status telling them apart:

=====================  ======  ==========================================================================
stop                   status  the line
=====================  ======  ==========================================================================
done (or plan only)    0
aborted                1       ``calibrate: aborted: ...`` (a goal rejected or aborted, a dead controller,
                               no data)
refused                2       ``calibrate: refused: ...`` (a bad plan, params file or argument)
write failed           3       ``calibrate: stopped: cannot write FILE: REASON (ENOSPC) ...`` (a full disk,
                               an I/O error, a permission)
Ctrl-C (SIGINT)        130     ``calibrate: cancelled by SIGINT ...``
SIGTERM                143     ``calibrate: cancelled by SIGTERM ...``
=====================  ======  ==========================================================================

On each of them the goal running at the controller is cancelled (the node's ``Calibrator.cancel``), the
pose in progress is discarded and the completed ones are kept, so ``--resume`` continues the run.

Imports nothing of ROS.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Sequence

from shaper_nodes.core.interrupts import Stopped, interrupt_in, stop_on_signals
from shaper_nodes.recordings import describe_write_error

__all__ = ["EXIT_ABORTED", "EXIT_CANCELLED", "EXIT_REFUSED", "EXIT_TERMINATED", "EXIT_WRITE_FAILED",
           "MAX_PARAMS_FILE_BYTES", "Aborted", "Stopped", "WriteFailed", "params_file_too_large", "stop_on_signals"]

EXIT_ABORTED, EXIT_REFUSED, EXIT_WRITE_FAILED = 1, 2, 3
EXIT_CANCELLED, EXIT_TERMINATED = 128 + signal.SIGINT, 128 + signal.SIGTERM  # 130, 143: the shells' convention
#: the largest params file calibrate reads, bytes. The largest plan it takes (core.calibration.plan.MAX_POSES
#: = 100 explicit poses of 6 joints) takes about 15 kB; a larger file is refused before anything parses it
#: (before, a 37 MB file of 10^6 poses was still being parsed 90 s after calibrate started and 60 s after a
#: SIGINT; the issue saw more than 240 s).
MAX_PARAMS_FILE_BYTES = 1 << 20


class Aborted(RuntimeError):
    """The run stopped: the message names why."""


class WriteFailed(Aborted):
    """A file of the run could not be written (a full disk, an I/O error, a permission): the message names the
    file and the system's reason (``cannot write FILE: No space left on device (ENOSPC)``)."""

    def __init__(self, err: BaseException, path: os.PathLike[str] | str) -> None:
        import pathlib

        super().__init__(describe_write_error(err, pathlib.Path(path)))


def stop_in(err: BaseException) -> Stopped | None:
    """The :class:`Stopped` that ``err`` carries as its cause or context, if any: a signal that lands while rclpy's C++
    calls back into Python (a message built while taking it) comes out of pybind11 as a ``TypeError`` ("Unable to
    convert function return value") whose cause is the :class:`Stopped`."""
    return interrupt_in(err, Stopped)


def params_file_too_large(files: Sequence[str], limit: int = MAX_PARAMS_FILE_BYTES) -> str | None:
    """Why one of the params ``files`` is refused for its size (one line naming it), or None: checked before
    any parser reads it."""
    for path in files:
        try:
            size = os.stat(path).st_size
        except OSError:
            continue  # missing or unreadable: params_file_problem names it
        if size > limit:
            return (f"--params-file {path}: {size / 1e6:.1f} MB, more than calibrate reads ({limit / 2**20:g} MiB;"
                    " the largest plan, 100 poses, takes about 15 kB)")
    return None
