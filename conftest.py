"""Hooks for every test directory (pytest.ini's testpaths): the cyclic garbage collector."""

from __future__ import annotations

import gc

import pytest


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Collect a test's garbage once pytest is done with the test, then freeze what survives.

    rclpy's objects sit in reference cycles (a node with its time source, parameter service and
    callbacks; an executor with its tasks), so they are freed by the cyclic collector, which runs
    whenever allocations trigger it: left to that, a finished test's nodes and executors were
    finalized in the middle of a later test's executor wait, and once that crashed the whole run
    (SIGSEGV in the collector under rclpy's ``EventHandler.is_ready``, CI of 2026-11-26). Collected
    here, they go at a known point, between tests, with no wait set in use.

    What survives is frozen (``gc.freeze``: left out of later collections), so each collection
    scans only what the tests since made. This runs after the whole run protocol, not in a
    fixture's teardown: until the protocol ends pytest still holds the test's fixture values
    (``item.funcargs``), and a frozen rclpy Context is never finalized, its DDS participant never
    destroyed (a fixture that froze there leaked one per test and a quiet run had two failures).
    Module- and class-scoped fixtures are freed when the next test is in another module or class,
    so the frozen objects are given back to the collector (``gc.unfreeze``) before that collection.
    """
    yield
    if nextitem is None or nextitem.parent is not item.parent:
        gc.unfreeze()
    gc.collect()
    gc.freeze()
