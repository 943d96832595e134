"""Learner state files: one JSON document, versioned, written atomically, checked fully on reading.

Both learners (LIST and MRILC) save their whole state after every update and reload it at
start. :func:`write_state` writes, fsyncs, renames and fsyncs the folder, so that a crash
leaves either the old file or the new one, never a torn one. :func:`read_state` reads a document
back and checks what can be checked without knowing the learner: its size, that it parses
(a nesting so deep that the parser recurses out is caught), its nesting depth, its version and
what it was saved for. :func:`load_state` is what a node calls at start: it reads, has the
learner build itself from the document (which checks the rest: shapes, types, finiteness), and
on any failure moves the file aside with :func:`set_aside` and says why; a file that cannot even
be moved aside (a read-only folder) is reported as such and ignored. A learner never fails to
start because of its state file: it starts afresh.
"""

from __future__ import annotations

import json
import os
import pathlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from shaper_nodes.core.files import write_atomic

#: largest state file read, bytes (a longer one is refused before it is read into memory)
MAX_BYTES = 512 * 1024 * 1024
#: deepest nesting of lists and dictionaries a state document may have (the learners' need 6)
MAX_DEPTH = 16

T = TypeVar("T")


class StateFileError(ValueError):
    """A state file that cannot be loaded: unreadable, not JSON, another version or another set-up."""


def write_state(path: pathlib.Path, doc: Mapping[str, Any]) -> None:
    """``doc`` as JSON to ``path``, atomically (:func:`shaper_nodes.core.files.write_atomic`)."""
    write_atomic(path, json.dumps(doc))


def nesting_depth(doc: Any) -> int:
    """How deeply lists and dictionaries nest in ``doc`` (a scalar: 0, ``[]``: 1), without recursion."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children: Any = item.values()
        elif isinstance(item, list):
            children = item
        else:
            continue
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    return deepest


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
        The file is unreadable, longer than :data:`MAX_BYTES`, not JSON (or nested so deeply that
        the parser gives up), nested deeper than :data:`MAX_DEPTH`, not a document of ``version``,
        or saved for another set-up (the message names the entry and both values).
    """
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise StateFileError(f"{what} {path}: {size} bytes, more than the {MAX_BYTES} a state file may have")
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise StateFileError(f"cannot read {what} {path}: {err}") from None
    try:
        doc = json.loads(text)
    except RecursionError:
        raise StateFileError(f"{what} {path}: not JSON a learner wrote (nested too deeply to parse)") from None
    except (ValueError, MemoryError) as err:  # JSONDecodeError, and integers too long to convert
        raise StateFileError(f"{what} {path}: not valid JSON: {err}") from None
    depth = nesting_depth(doc)
    if depth > MAX_DEPTH:
        raise StateFileError(f"{what} {path}: nested {depth} deep, deeper than the {MAX_DEPTH} a state file may be")
    if not isinstance(doc, dict) or doc.get("version") != version:
        raise StateFileError(f"{what} {path}: not a version-{version} state file")
    for key, want in (expected or {}).items():
        if doc.get(key) != want:
            raise StateFileError(f"{what} {path}: saved for {key} {doc.get(key)!r}, not {want!r}")
    return doc


def set_aside(path: pathlib.Path) -> pathlib.Path:
    """Move a state file that could not be loaded to ``<file>.corrupt`` (replacing an older one);
    returns the new path. Raises OSError if it cannot be moved (a read-only folder)."""
    aside = path.with_name(path.name + ".corrupt")
    os.replace(path, aside)
    return aside


@dataclass(frozen=True)
class Loaded(Generic[T]):
    """What :func:`load_state` found: the state built (None: start afresh) and, if the file could
    not be used, why (``problem``, for the log and diagnostics) and where it went (``aside``)."""

    state: T | None
    problem: str = ""
    aside: pathlib.Path | None = None


def load_state(path: pathlib.Path | None, version: int, build: Callable[[dict[str, Any]], T],
               what: str = "learner state", expected: Mapping[str, Any] | None = None) -> Loaded[T]:
    """The state saved in ``path`` built by ``build`` (which validates the document and raises on
    anything wrong), or nothing and why.

    No file (or no path): ``Loaded(None)``. A file that fails :func:`read_state` or ``build``, for
    whatever reason (``build`` is the learner's own restore; any exception it raises means the
    file cannot be used), is moved aside (:func:`set_aside`) and reported in ``problem``; one that
    cannot be moved aside either is reported too, and will be refused the same way at the next
    start. This function never raises: a learner starts, afresh if need be.
    """
    if path is None:
        return Loaded(None)
    try:
        if not path.exists():
            return Loaded(None)
        state = build(read_state(path, version, what, expected))
    except Exception as err:  # whatever the file holds (or its builder raises), the learner must start
        why = str(err) if isinstance(err, StateFileError) else f"{what} {path}: {type(err).__name__}: {err}"
        try:
            aside = set_aside(path)
        except OSError as move:
            return Loaded(None, f"{why}; not loaded, and it could not be moved aside ({move}): it stays where it is"
                                " and will be refused again at the next start; starting afresh")
        return Loaded(None, f"{why}; not loaded, moved to {aside}; starting afresh", aside)
    return Loaded(state)
