"""A child process that ends with its parent: the one copy of the suite's parent-death glue.

A node started by a script (the demo's nodes, a test's nodes) and a worker of a process pool (the shaper's
whole-trajectory worker, the calibration analysis' workers) must not outlive the process that started it
when that process is killed with ``kill -9`` (it has no chance to stop them). On Linux the kernel does it:
``prctl(PR_SET_PDEATHSIG, sig)`` (see prctl(2)) asks for ``sig`` when the parent ends. Elsewhere
:func:`die_with_parent` does nothing and says so (returns False).

prctl(2) states the signal is sent when the *thread* that created the child ends, not only its process: start
children from a thread that lives as long as they should (the main thread, or a pool's own thread), never from
a short-lived one.

Imports nothing of ROS.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys

__all__ = ["PR_SET_PDEATHSIG", "die_with_parent"]

#: prctl(2) option: the signal the calling process gets when its parent ends (linux/prctl.h)
PR_SET_PDEATHSIG = 1


def die_with_parent(sig: int = signal.SIGTERM, parent: int | None = None) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent ends.

    For ``subprocess.Popen(preexec_fn=die_with_parent)`` and a process pool's ``initializer``. If the parent
    has already gone (this process was re-parented before the call) and ``parent`` (the pid the parent had) is
    given, ``sig`` is sent at once.

    Parameters
    ----------
    sig : int
        The signal (SIGTERM by default: a node stops cleanly on it).
    parent : int, optional
        The parent's pid as the parent knew it (``os.getpid()`` before the fork).

    Returns
    -------
    bool
        True when the request was made (Linux), False where the platform has no such call.
    """
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
        return False
    if parent is not None and os.getppid() != parent:  # the parent ended before the request was made
        os.kill(os.getpid(), sig)
    return True
