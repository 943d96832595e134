"""Freed memory given back to the system: the one copy of the ``malloc_trim`` glue.

A process that has just dropped a large message (a refused trajectory of 10^5 points: rclpy's C copy and
its Python objects, some hundred MiB) has freed that memory, but the C library's allocator keeps most of it
for later allocations, so the process' resident size stays near its peak. On glibc, ``malloc_trim(0)`` (see
malloc_trim(3)) returns the free pages of every allocator arena to the system; Python's own small-object
arenas go back by themselves once empty. Elsewhere :func:`release_freed_memory` does nothing and says so.

Imports nothing of ROS.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

__all__ = ["release_freed_memory"]


def release_freed_memory() -> bool:
    """Give the C allocator's free pages back to the system (glibc ``malloc_trim(0)``).

    Costs a few ms for a process of some hundred MiB; call it after dropping something large, not per message.

    Returns
    -------
    bool
        True when the call was made (Linux with glibc), False where there is no such call.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):  # another C library (musl has no malloc_trim)
        return False
    trim.argtypes = [ctypes.c_size_t]
    trim(0)
    return True
