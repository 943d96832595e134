# Copyright 2026 The ros2 vibration suppression authors
# SPDX-License-Identifier: Apache-2.0
"""The interrupt a signal raised, found where rclpy hid it.

A signal whose Python handler raises (Ctrl-C's KeyboardInterrupt, calibrate's ``Stopped``) while rclpy's C++
calls back into Python (building a message it takes) comes out of pybind11 as another error (a ``TypeError``:
"Unable to convert function return value") whose cause or context is the interrupt. A command that waits by
spinning an executor looks for it there, so that a Ctrl-C still ends the run as a Ctrl-C (the goal cancelled,
one line) and not as a traceback.
"""

from __future__ import annotations

from typing import TypeVar

__all__ = ["interrupt_in"]

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
