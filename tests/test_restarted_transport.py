"""The environment the suite gives a node it restarts after a ``kill -9`` (conftest's ``RESTARTED``) keeps the node
off Fast DDS's shared memory, and the node is still reached by the test's participants.

A restarted process on shared memory can stay deaf to every peer that outlived the crash (tests/conftest.py,
``RESTARTED``); the suite starts such nodes on UDP alone. That setting is easy to get wrong without a sign: under the
suite's discovery range LOCALHOST, rmw_fastrtps configures the transports itself (shared memory and UDP) and Fast
DDS's ``FASTDDS_BUILTIN_TRANSPORTS`` is not read, which is what sessions 19-20 ran with. Shown here, on real nodes:
a node started with ``RESTARTED`` maps no shared-memory segment of Fast DDS and answers the test's LOCALHOST
participant's service calls; a node given only ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` under LOCALHOST maps them (the
trap, so that a change of rmw that reads the variable shows here).
"""

from __future__ import annotations

import pathlib

import pytest
from conftest import RESTARTED, call_answered
from rcl_interfaces.srv import GetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

pytestmark = pytest.mark.integration

WAIT = 60.0  # s, generous: discovery on a loaded machine


def shared_memory_maps(pid: int) -> list[str]:
    """The process's mappings of Fast DDS shared-memory segments (files ``/dev/shm/fastrtps_*``)."""
    return [line for line in pathlib.Path(f"/proc/{pid}/maps").read_text().splitlines() if "/dev/shm/fast" in line]


def answered(ros_context, node_name: str) -> list[str]:
    """The node's ``use_sim_time`` got from its parameter service by the test's (LOCALHOST) participant."""
    node = Node("restarted_transport_peer", context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    try:
        client = node.create_client(GetParameters, f"/{node_name}/get_parameters")
        answer = call_answered(ex, client, GetParameters.Request(names=["use_sim_time"]),
                               f"/{node_name}/get_parameters", timeout=WAIT)
        return [str(v) for v in answer.values]
    finally:
        ex.shutdown()
        node.destroy_node()


def test_a_restarted_node_is_on_udp_alone_and_reached(start_node, ros_context):
    proc = start_node("shaper_nodes", "shaper_node", {"joint_names": ["j1"]}, env=RESTARTED)
    assert len(answered(ros_context, "shaper")) == 1  # reached over UDP: discovery and the answer
    assert proc.proc is not None and proc.running()
    assert shared_memory_maps(proc.proc.pid) == []


def test_the_builtin_transports_variable_alone_is_not_read_under_localhost(start_node, ros_context):
    proc = start_node("shaper_nodes", "shaper_node", {"joint_names": ["j1"]},
                      env={"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"})  # under the suite's LOCALHOST
    assert len(answered(ros_context, "shaper")) == 1
    assert proc.proc is not None and proc.running()
    assert shared_memory_maps(proc.proc.pid) != []  # shared memory all the same
