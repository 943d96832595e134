"""Files written whole: a reader sees the old file or the new one, never half of one.

:func:`write_atomic` writes to ``<name>.tmp`` beside the file, flushes and fsyncs it, renames it over
the file and fsyncs the folder, so that a crash (power loss, ``kill -9``) leaves either version. Used
by the learners' state files, calibration's outputs and its report's figures.
"""

from __future__ import annotations

import os
import pathlib

__all__ = ["write_atomic"]


def write_atomic(path: pathlib.Path, data: str | bytes) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically: write, fsync, rename, fsync the folder.

    The folder is made if it does not exist.

    Raises
    ------
    OSError
        The folder or the file could not be written (the file as it was is kept).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
