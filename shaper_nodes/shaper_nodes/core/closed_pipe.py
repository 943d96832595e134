"""A command whose reader went away: ``shaper_design list | head -1`` ends quietly, as a shell
reports a process ended by SIGPIPE (status 141), instead of with a ``BrokenPipeError`` traceback.

Used by the command-line tools and by the nodes' ``--help``; it imports nothing of ROS.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["EXIT_CLOSED_PIPE", "quiet_closed_pipe", "survives_closed_pipe"]

#: exit status after the reader of stdout went away (128 + SIGPIPE, as a shell reports it)
EXIT_CLOSED_PIPE = 141
_F = TypeVar("_F", bound=Callable[..., int])


def quiet_closed_pipe(main: Callable[[], int]) -> int:
    """Run ``main`` and flush stdout; if the reader of stdout has gone (``... | head -1``), return
    :data:`EXIT_CLOSED_PIPE` without a traceback.

    As Python's documentation of ``signal`` recommends, stdout is then pointed at ``os.devnull``, so
    that the interpreter's own flush at exit does not fail again.
    """
    try:
        status = main()
        sys.stdout.flush()
        return status
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_CLOSED_PIPE


def survives_closed_pipe(main: _F) -> _F:
    """Decorate a CLI's ``main``: see :func:`quiet_closed_pipe`."""

    @functools.wraps(main)
    def wrapped(*args: Any, **kwargs: Any) -> int:
        return quiet_closed_pipe(lambda: main(*args, **kwargs))

    return wrapped  # type: ignore[return-value]
