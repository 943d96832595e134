# Copyright 2026 The ros2 vibration suppression authors
# SPDX-License-Identifier: Apache-2.0
"""Stop signals as exceptions, and the interrupt a signal raised, found where rclpy hid it.

:func:`stop_on_signals` makes SIGINT and SIGTERM raise :class:`Stopped` (a KeyboardInterrupt) in the main thread,
once, also where the process was started with SIGINT ignored (a background job of a non-interactive shell, a test
runner's worker: Python then installs no Ctrl-C handler of its own), so that a command that has a goal out at a
controller cancels it on either signal instead of dying with it running.

A signal whose Python handler raises (Ctrl-C's KeyboardInterrupt, calibrate's ``Stopped``) while rclpy's C++
calls back into Python (building a message it takes) comes out of pybind11 as another error (a ``TypeError``:
"Unable to convert function return value") whose cause or context is the interrupt. A command that waits by
spinning an executor looks for it there, so that a Ctrl-C still ends the run as a Ctrl-C (the goal cancelled,
one line) and not as a traceback.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from types import FrameType
from typing import TypeVar

__all__ = ["Stopped", "interrupt_in", "signals_held", "stop_on_signals"]

K = TypeVar("K", bound=BaseException)


def interrupt_in(err: BaseException, kind: type[K]) -> K | None:
    """The ``kind`` (a KeyboardInterrupt class) that ``err`` is or carries as its cause or context, if any."""
    seen: set[int] = set()
    cur: BaseException | None = err
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, kind):
            return cur
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return None


class Stopped(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (raised where the main thread was, as Ctrl-C's KeyboardInterrupt is)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def status(self) -> int:
        """The exit status of a process ended by the signal (the shells' convention: 128 + its number)."""
        return 128 + self.signum


class _Stops:
    """The process's stop signals: the one that came (once), and whether the main thread holds them now."""

    def __init__(self) -> None:
        self.hit: list[int] = []
        self.held = 0
        self.pending: int | None = None


_STOPS = _Stops()


def stop_on_signals() -> None:
    """SIGINT and SIGTERM raise :class:`Stopped` in the main thread, once: the stop that follows (cancelling the
    goal, removing a partial file) is not interrupted by a second signal. Inside :func:`signals_held` the
    signal is noted and raised when the block ends."""
    stops = _STOPS
    stops.hit.clear()
    stops.pending = None

    def handler(signum: int, frame: FrameType | None) -> None:
        if stops.hit:
            return
        stops.hit.append(signum)
        if stops.held:
            stops.pending = signum
            return
        raise Stopped(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold a stop signal (of :func:`stop_on_signals`) until the block ends, then raise its :class:`Stopped`.

    For an executor's ``spin_once``: a handler that raises while rclpy takes messages (its C++ calling back into
    Python) drops every message of that take, the answer to a goal and its status with it (seen: calibrate's
    SIGTERM as the controller's answer came; the goal it had sent was then not known accepted, and not
    cancelled). Held, the take and its callbacks complete, and the stop comes at most one ``spin_once`` later.
    If the block raised too, the :class:`Stopped` is raised from its error: the signal is never lost."""
    stops = _STOPS
    stops.held += 1
    try:
        yield
    except BaseException as err:
        stops.held -= 1
        if not stops.held and stops.pending is not None and not isinstance(err, KeyboardInterrupt):
            signum, stops.pending = stops.pending, None
            raise Stopped(signum) from err
        raise
    stops.held -= 1
    if not stops.held and stops.pending is not None:
        signum, stops.pending = stops.pending, None
        raise Stopped(signum)
