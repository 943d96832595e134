"""Fixtures for launch-free integration tests: real nodes over real DDS, isolated per test.

Every test gets its own ROS domain (so leftovers of one test never talk to the next), a fresh
rclpy Context for in-process nodes, and a helper that starts installed node executables as
subprocesses on that domain and stops them at teardown.
"""

from __future__ import annotations

import itertools
import os

import pytest
import rclpy

from shaper_nodes.ros.launching import NodeProcess

_counter = itertools.count()


@pytest.fixture
def domain_id() -> int:
    base = int(os.environ.get("ROS_DOMAIN_ID", "30"))
    return 1 + (base + next(_counter)) % 200


@pytest.fixture
def ros_context(domain_id):
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    yield ctx
    ctx.try_shutdown()


@pytest.fixture
def start_node(domain_id, tmp_path):
    procs: list[NodeProcess] = []

    def start(package: str, executable: str, params: dict | None = None) -> NodeProcess:
        log = tmp_path / f"{executable}-{len(procs)}.log"
        proc = NodeProcess(package, executable, params or {}, log_path=log,
                           env={"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
        procs.append(proc.start())
        return proc

    yield start
    for proc in reversed(procs):
        proc.stop()


class Starter:
    """start_node, remembering the processes so that a run's nodes can be stopped before the next."""

    def __init__(self, start_node):
        self.start_node, self.procs = start_node, []

    def __call__(self, package, executable, params):
        proc = self.start_node(package, executable, params)
        self.procs.append(proc)
        return proc

    def stop_all(self):
        for proc in reversed(self.procs):
            assert proc.stop() == 0
        self.procs = []


@pytest.fixture
def starter(start_node) -> Starter:
    """Like start_node, with ``stop_all()`` to stop the nodes started so far."""
    return Starter(start_node)
