"""The bench's echo node (benchmarks/echo_node.py, the baseline and the floor of the hop) stops on SIGINT with
status 0, bare and on the take loop, and shuts no executor down while rclpy's signal handlers are installed.

On SIGINT rclpy 7.1.6 triggers every executor's SIGINT guard condition from a thread of its own, walking a global
list with no lock; the echo node's main thread, woken by the first of them, shut its executors down at once, which
unregistered their guard conditions (the list freed) under that thread: the process ended on SIGSEGV (-11) in
``rcl_trigger_guard_condition`` in about one stop in 20 on a loaded machine (session 14, a core dump). The race
itself is not reproducible in a test; its precondition is: every executor's ``shutdown`` is checked here to run
with rclpy's handlers uninstalled (``echo_node.stop_signal_handlers``, which joins that thread first).

Twice in suites the idle node did not end within 60 s of SIGINT, its main thread still in rclpy's wait (the stack
dump below, session 16): the KeyboardInterrupt pending, the wake-up of the executor lost. The node's wait is bounded
(``echo_node.STOP_LOOK``); the ``lost wake-up`` cases play that loss (rclpy's handlers never installed: Python's own
handler only, set explicitly, which wakes nothing) and the node must still stop.
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from shaper_nodes.ros.launching import ChildProcess

pytestmark = pytest.mark.integration

REPO = pathlib.Path(__file__).resolve().parents[1]
#: s, generous bounds for a loaded 2-core machine (the waits end as soon as the state is reached)
UP, DOWN = 120.0, 60.0
#: printed by the checked node when an executor is shut down with rclpy's signal handlers still installed
TOO_EARLY = "executor shut down with rclpy's signal handlers installed"

# the echo node's main, with every executor's shutdown checked first (with ECHO_LOST_WAKEUP set, rclpy's signal
# handlers are never installed: a SIGINT leaves a KeyboardInterrupt pending and wakes no executor)
CHECKED = textwrap.dedent(f"""
    import faulthandler, os, signal, sys
    faulthandler.register(signal.SIGUSR1, all_threads=True)  # where it waits, if its stop hangs (the test asks)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options

    shutdown = SingleThreadedExecutor.shutdown

    def checked(self, *args, **kwargs):
        if get_current_signal_handlers_options() != SignalHandlerOptions.NO:
            print({TOO_EARLY!r}, flush=True)
            os._exit(3)
        print("executor shut down", flush=True)
        return shutdown(self, *args, **kwargs)

    SingleThreadedExecutor.shutdown = checked
    if os.environ.get("ECHO_LOST_WAKEUP"):
        # Python's own SIGINT handler, whatever the disposition inherited (a suite started in the background has
        # SIGINT ignored, and Python then installs none): a KeyboardInterrupt pending, no executor woken
        signal.signal(signal.SIGINT, signal.default_int_handler)
        init = rclpy.init

        def init_without_handlers(*args, **kwargs):
            kwargs["signal_handler_options"] = SignalHandlerOptions.NO
            return init(*args, **kwargs)

        rclpy.init = init_without_handlers
    from benchmarks.echo_node import main
    sys.exit(main(sys.argv))
""")


@pytest.mark.parametrize("lost", [False, True], ids=["woken", "lost wake-up"])
@pytest.mark.parametrize("take", [False, True], ids=["bare", "take loop"])
def test_the_echo_node_stops_on_sigint_after_rclpys_signal_handlers(domain_id, tmp_path, take, lost):
    log = tmp_path / "echo.log"
    cmd = [sys.executable, "-c", CHECKED, "--in", "/stop/echo_in", "--out", "/stop/echo_out"] + (["--take"] if take
                                                                                                   else [])
    env = {"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
           **({"ECHO_LOST_WAKEUP": "1"} if lost else {})}
    proc = ChildProcess(cmd, log, env=env, cwd=REPO).start()
    try:
        end = time.monotonic() + UP
        while "echoing" not in log.read_text() and proc.running():  # its log line: spinning, handlers installed
            assert time.monotonic() < end, log.read_text()
            time.sleep(0.05)
        assert proc.proc is not None
        proc.proc.send_signal(signal.SIGINT)
        try:
            proc.proc.wait(DOWN)
        except subprocess.TimeoutExpired:  # hung once in a suite with two hogs (session 15): every thread's stack
            proc.proc.send_signal(signal.SIGUSR1)
            end = time.monotonic() + 10.0  # faulthandler's dump in the log before the stop kills the node
            while "thread 0x" not in log.read_text().lower() and time.monotonic() < end:
                time.sleep(0.05)
            pytest.fail(f"no exit within {DOWN:g} s of SIGINT; the node's threads:\n{log.read_text()[-6000:]}")
    finally:
        code = proc.stop()
    text = log.read_text()
    assert code == 0, text
    assert TOO_EARLY not in text, text
    # both executors (the main one, and the side node's on the take loop) were shut down, and checked
    assert text.count("executor shut down") == (2 if take else 1), text
