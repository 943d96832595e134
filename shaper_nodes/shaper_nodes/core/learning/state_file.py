"""Learner state files: one JSON document, versioned, written atomically.

Both learners (LIST and MRILC) save their whole state after every update and reload it at
start. :func:`write_atomic` writes, fsyncs, renames and fsyncs the folder, so that a crash
leaves either the old file or the new one, never a torn one. :func:`read_state` reads a document
back and checks its version and what it was saved for; a file that fails is reported by the
caller and moved aside with :func:`set_aside`, never half-loaded.
"""

from __future__ import annotations

import json
import os
import pathlib
from collections.abc import Mapping
from typing import Any


class StateFileError(ValueError):
    """A state file that cannot be loaded: unreadable, not JSON, another version or another set-up."""


def write_atomic(path: pathlib.Path, doc: Mapping[str, Any]) -> None:
    """``doc`` as JSON to ``path`` atomically (write, fsync, rename, fsync the folder)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(doc, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_state(path: pathlib.Path, version: int, what: str = "learner state",
               expected: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The document saved in ``path``, checked.

    Parameters
    ----------
    path : pathlib.Path
        The state file.
    version : int
        The format version it must have (its ``version`` entry).
    what : str
        What the file holds, for the messages (``"learner state"``).
    expected : mapping, optional
        Entries the document must have with exactly these values (what it was saved for, such as
        the LIST structure or ``mode: mrilc``).

    Raises
    ------
    StateFileError
        The file is unreadable or not JSON, not a document of ``version``, or saved for another
        set-up (the message names the entry and both values).
    """
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise StateFileError(f"cannot read {what} {path}: {err}") from None
    if not isinstance(doc, dict) or doc.get("version") != version:
        raise StateFileError(f"{what} {path}: not a version-{version} state file")
    for key, want in (expected or {}).items():
        if doc.get(key) != want:
            raise StateFileError(f"{what} {path}: saved for {key} {doc.get(key)!r}, not {want!r}")
    return doc


def set_aside(path: pathlib.Path) -> pathlib.Path:
    """Move a state file that could not be loaded to ``<file>.corrupt`` (replacing an older one);
    returns the new path."""
    aside = path.with_name(path.name + ".corrupt")
    os.replace(path, aside)
    return aside
