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
