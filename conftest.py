"""Hooks for every test directory (pytest.ini's testpaths): the ROS domains of parallel workers, the
cyclic garbage collector, and the CPU report (``SHAPER_CPU_LOG``, off unless set)."""

from __future__ import annotations

import gc
import json
import os
import resource
import subprocess
import time

import pytest

#: ROS domains the tests use: 1 + (k % DOMAINS) for k = the base and up (tests/conftest.py's domain_id)
DOMAINS = 200


def worker_domains(base: int, worker: str | None, workers: int) -> tuple[int, int]:
    """The first domain number (before ``1 + k % DOMAINS``) and the stride of an xdist worker's domains.

    Worker ``gw<i>`` of ``workers`` takes ``base + i``, ``base + i + stride``, ``base + i + 2 stride``, ...
    where the stride is the smallest divisor of :data:`DOMAINS` not below ``workers``: as the stride divides
    the range, ``k % DOMAINS`` keeps ``k``'s remainder modulo the stride, so two workers never share a domain,
    wrapped or not. Without xdist (``worker`` None) the base with stride 1, as before workers.

    Parameters
    ----------
    base : int
        ``ROS_DOMAIN_ID`` of the run (``./run test`` sets one per run).
    worker : str or None
        xdist's ``PYTEST_XDIST_WORKER`` ("gw0", "gw1", ...), None without xdist.
    workers : int
        xdist's ``PYTEST_XDIST_WORKER_COUNT``.

    Returns
    -------
    tuple of int
        (first domain number, stride).
    """
    if worker is None:
        return base, 1
    index = int(worker.removeprefix("gw"))
    stride = next((d for d in range(max(workers, 1), DOMAINS + 1) if DOMAINS % d == 0), 0)
    if not 0 <= index < workers or stride == 0:
        raise pytest.UsageError(f"xdist worker {worker} of {workers}: at most {DOMAINS} workers, one domain each")
    return base + index, stride


def pytest_configure(config: pytest.Config) -> None:
    """On an xdist worker, give its tests and the processes they start a domain of their own.

    ``ROS_DOMAIN_ID`` becomes the worker's first domain (what the unit tests that make an rclpy context read,
    and what a started process inherits), and ``SHAPER_DOMAIN_STRIDE`` the step between the worker's domains
    (tests/conftest.py's ``domain_id``). Nothing changes without xdist.
    """
    first, stride = worker_domains(int(os.environ.get("ROS_DOMAIN_ID", "30")), os.environ.get("PYTEST_XDIST_WORKER"),
                                   int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    os.environ["ROS_DOMAIN_ID"] = str(first)
    os.environ["SHAPER_DOMAIN_STRIDE"] = str(stride)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On xdist workers, deal the integration tests (``tests/``) out evenly, first in each worker's share.

    ``--dist worksteal`` gives worker i the i-th of W contiguous slices of the collection, and an idle worker
    later takes queued tests from a busy one. The integration tests are the long ones (seconds to minutes
    each, waiting on discovery, processes and simulated time): in pytest's order (``tests/`` last) they
    would all be one worker's slice, run one at a time until the others had run out of unit tests. So the
    collection becomes W slices, each with every W-th integration test followed by a W-th of the unit tests
    (in their order, so a module's tests stay together). A run in one process keeps pytest's order.
    """
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if not os.environ.get("PYTEST_XDIST_WORKER") or workers < 2:
        return
    integration = config.rootpath / "tests"
    long = [item for item in items if integration in item.path.parents]
    short = [item for item in items if integration not in item.path.parents]
    n = len(short)
    shares = [long[w::workers] + short[w * n // workers:(w + 1) * n // workers] for w in range(workers)]
    items[:] = [item for share in shares for item in share]


#: environment variable naming the CPU log (shaper_nodes.ros.launching.CPU_LOG_ENV; read here without importing it)
CPU_LOG_ENV = "SHAPER_CPU_LOG"


def _cpu(who: int) -> tuple[float, float]:
    usage = resource.getrusage(who)
    return usage.ru_utime, usage.ru_stime


def pytest_sessionstart(session: pytest.Session) -> None:
    """With ``SHAPER_CPU_LOG`` set, every process the tests start is reaped by ``os.wait4`` and logged.

    ``subprocess.Popen`` becomes ``shaper_nodes.ros.launching.UsagePopen`` for the session, so the processes of
    ``subprocess.run`` (the CLIs the walkthrough and the demo tests run) are logged like the nodes of
    ``NodeProcess`` (which always uses it); processes started by those processes (the demo's nodes, a
    conductor's) log themselves, as the variable is inherited. Off (nothing changed) when unset.
    """
    if os.environ.get(CPU_LOG_ENV):
        from shaper_nodes.ros.launching import UsagePopen

        subprocess.Popen = UsagePopen  # type: ignore[misc]


def _log_test_cpu(item: pytest.Item, began: float, before: tuple[tuple[float, float], ...]) -> None:
    """Append the test's line to the CPU log: the CPU (user, system, s) this pytest process spent in the test's
    protocol (set-up, call, teardown: the test's own computing, its in-process nodes and their DDS threads) and
    that of the processes it reaped meanwhile, with the wall time."""
    after = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)
    (su, ss), (cu, cs) = ((a[0] - b[0], a[1] - b[1]) for a, b in zip(after, before, strict=True))
    line = json.dumps({"kind": "test", "test": item.nodeid, "pid": os.getpid(),
                       "wall": round(time.monotonic() - began, 3), "user": round(su, 4), "sys": round(ss, 4),
                       "children_user": round(cu, 4), "children_sys": round(cs, 4)})
    fd = os.open(os.environ[CPU_LOG_ENV], os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, (line + "\n").encode())
    finally:
        os.close(fd)


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

    With ``SHAPER_CPU_LOG`` set, the test's CPU (this process's and its reaped children's) is logged after the
    protocol, before the collection (:func:`_log_test_cpu`).
    """
    logging = bool(os.environ.get(CPU_LOG_ENV))
    if logging:
        began, before = time.monotonic(), (_cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN))
    yield
    if logging:
        _log_test_cpu(item, began, before)
    if nextitem is None or nextitem.parent is not item.parent:
        gc.unfreeze()
    gc.collect()
    gc.freeze()
