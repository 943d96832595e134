# Copyright 2026 The shaper_nodes authors. Licensed under the Apache License, Version 2.0.
"""A stop signal that lands while rclpy's C++ calls back into Python comes out of pybind11 as a TypeError whose
cause is the Stopped the handler raised (seen in a full run: calibrate ended in a traceback, its goal not
cancelled); calibrate's waits find the Stopped in the chain and raise it."""

from __future__ import annotations

import signal

from shaper_nodes.nodes.calibrate_stops import Stopped, stop_in


def test_a_stop_carried_as_the_cause_of_another_error_is_found():
    stop = Stopped(signal.SIGTERM)
    try:
        try:
            raise stop
        except Stopped as inner:
            raise TypeError("Unable to convert function return value to a Python type!") from inner
    except TypeError as err:
        assert stop_in(err) is stop
        assert stop_in(err).status == 128 + signal.SIGTERM


def test_an_error_without_a_stop_is_not_one_and_a_loop_ends():
    err = ValueError("other")
    assert stop_in(err) is None
    a, b = RuntimeError("a"), RuntimeError("b")
    a.__context__, b.__context__ = b, a  # a cycle of contexts ends the walk
    assert stop_in(a) is None


def test_a_ctrl_c_carried_as_the_context_of_another_error_is_found_and_a_stop_is_one():
    """send_goal's waits look for any KeyboardInterrupt (Ctrl-C); calibrate's Stopped is one too."""
    from shaper_nodes.core.interrupts import interrupt_in

    ctrl_c = KeyboardInterrupt()
    try:
        try:
            raise ctrl_c
        except KeyboardInterrupt:
            raise TypeError("Unable to convert function return value to a Python type!")  # noqa: B904 (context)
    except TypeError as err:
        assert interrupt_in(err, KeyboardInterrupt) is ctrl_c
        assert interrupt_in(err, Stopped) is None
    stop = Stopped(signal.SIGINT)
    assert interrupt_in(TypeError("x"), KeyboardInterrupt) is None
    assert interrupt_in(stop, KeyboardInterrupt) is stop


def _signals_restored(test):
    """Run ``test`` with stop_on_signals installed, pytest's own handlers put back after."""
    import functools

    @functools.wraps(test)
    def run(*args, **kwargs):
        saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            from shaper_nodes.core.interrupts import stop_on_signals

            stop_on_signals()
            return test(*args, **kwargs)
        finally:
            for sig, handler in saved.items():
                signal.signal(sig, handler)
    return run


@_signals_restored
def test_a_stop_inside_signals_held_comes_when_the_block_ends_and_only_once():
    """What a spin_once does inside the block (a take and its callbacks) completes; the Stopped comes after it."""
    import os

    import pytest

    from shaper_nodes.core.interrupts import signals_held

    done = []
    with pytest.raises(Stopped) as stop, signals_held():
        os.kill(os.getpid(), signal.SIGTERM)
        for k in range(1000):  # the handler runs between two of these bytecodes: noted, not raised
            done.append(k)
    assert len(done) == 1000 and stop.value.status == 128 + signal.SIGTERM
    os.kill(os.getpid(), signal.SIGINT)  # once: a second signal is not raised again
    with signals_held():
        done.append(-1)


@_signals_restored
def test_a_stop_held_while_the_block_fails_is_raised_from_the_failure():
    import os

    import pytest

    from shaper_nodes.core.interrupts import signals_held

    with pytest.raises(Stopped) as stop, signals_held():
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(1000))
        raise TypeError("Unable to convert function return value to a Python type!")
    assert isinstance(stop.value.__cause__, TypeError) and stop.value.status == 128 + signal.SIGINT


@_signals_restored
def test_a_stop_outside_signals_held_is_raised_where_the_main_thread_is():
    import os

    import pytest

    with pytest.raises(Stopped):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(100000))
