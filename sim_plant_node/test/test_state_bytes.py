"""The sim plant's tip state and reference written as bytes in place (node/sensors.StateBytes) are the messages the
node built before: rclpy reads back the same message, and the bytes are rclpy's outside the padding."""

from __future__ import annotations

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from shaper_nodes.ros.conversions import sec_to_time
from sim_plant_node.node.sensors import StateBytes

NAMES = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "j6"]


def _message(t: float, position: np.ndarray, velocity: np.ndarray | None) -> JointState:
    """The message as the node built it before (sim_plant.py's _integrate)."""
    msg = JointState(name=NAMES, position=position.tolist(),
                     velocity=[] if velocity is None else velocity.tolist())
    msg.header.stamp = sec_to_time(t)
    return msg


def _same_outside_padding(state: StateBytes, data: bytes, reference: bytes) -> None:
    cdr = state._cdr
    assert cdr is not None
    ref = bytearray(reference[:len(data)])
    for start, end in cdr.padding:
        ref[start:end] = data[start:end]
    assert bytes(ref) == data
    assert len(data) <= len(reference) <= len(data) + 16  # (Fast CDR may pad after an empty sequence)


def test_the_bytes_are_the_message_the_node_built():
    rng = np.random.default_rng(3)
    tip, ref = StateBytes(NAMES), StateBytes(NAMES)
    for k in range(200):
        t = k / 500.0 + (1e-10 if k % 7 == 3 else 0.0)
        position, velocity = rng.normal(0.0, 2.0, 6), rng.normal(0.0, 1.0, 6)
        if k % 50 == 10:  # the extremes of a float64
            position[k % 6] = np.finfo(float).max
            velocity[(k + 1) % 6] = -np.finfo(float).tiny
        for state, vel in ((tip, velocity), (ref, None)):
            data = state(t, position, vel)
            expected = _message(t, position, vel)
            got = deserialize_message(data, JointState)
            assert got == expected, (k, got, expected)
            _same_outside_padding(state, data, serialize_message(expected))


def test_a_change_of_sizes_makes_a_new_layout():
    state = StateBytes(NAMES[:2])
    for n, vel in ((2, None), (3, np.arange(3.0)), (2, None)):
        position = np.linspace(-1.0, 1.0, n)
        expected = JointState(name=NAMES[:2], position=position.tolist(), velocity=[] if vel is None else vel.tolist())
        expected.header.stamp = sec_to_time(1.5)
        assert deserialize_message(state(1.5, position, vel), JointState) == expected
