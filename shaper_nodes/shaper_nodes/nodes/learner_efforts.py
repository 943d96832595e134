"""The speed learner's watch of the measured joint efforts and speeds: ``/joint_states``' effort (joint torques, N m)
and velocity (rad/s) kept per sample, so that a move's largest |effort| and |velocity| per joint are known at its END.

A robot reports its joint efforts on ``/joint_states`` (ur_robot_driver: the joints' torques computed from the
motor currents; the simulated arm: the motor torques its position loops apply, N m), and the joints' measured
speeds (a robot's can overshoot its plan). :class:`EffortWatch` subscribes to them raw (the fast decoder of
:mod:`shaper_nodes.recordings.cdr`, no message object per sample; polled, so a fast stream wakes the node a bounded
number of times a second), keeps ``(stamp, names, efforts, velocities)`` of the last ``keep`` s (at most
:data:`MAX_SAMPLES`), and answers :meth:`EffortWatch.peaks`: the largest |effort| and |velocity| of each of a move's
joints between two stamps. Efforts or velocities not one per name are not kept (a robot that reports no efforts:
no peak, and the learner says so); bytes that are not a JointState are dropped with a throttled error. The
ROS-free rules the peaks go to are :func:`shaper_nodes.core.learning.speed.peak_check` (the limits) and
:func:`shaper_nodes.core.learning.speed_peaks.allowed_factor` (the prediction before a raise).
"""

from __future__ import annotations

import collections
import math
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from shaper_nodes.recordings.cdr import JointStateDecoder, joint_state_motion, little_endian
from shaper_nodes.ros.lockstep_reader import STREAM_QOS, subscribe_draining

__all__ = ["MAX_SAMPLES", "EffortWatch"]

#: most joint state samples kept (a bound whatever the stream's rate)
MAX_SAMPLES = 400_000


class EffortWatch:
    """The efforts on ``topic`` of the last ``keep`` s (module docstring).

    Parameters
    ----------
    node : rclpy Node
        The subscriber.
    topic : str
        The joint states (sensor_msgs/JointState; efforts N m, or N for a prismatic joint).
    keep : float
        How long samples are kept, s of their stamps (the longest cycle).
    """

    def __init__(self, node: Any, topic: str, keep: float) -> None:
        self.node, self.topic, self.keep = node, topic, float(keep)
        self.latest = -math.inf  # the newest stamp with efforts, s
        self._newest = -math.inf  # the newest stamp kept, s
        self._samples: collections.deque[tuple[float, tuple[str, ...], tuple[float, ...] | None,
                                               tuple[float, ...] | None]] = collections.deque(maxlen=MAX_SAMPLES)
        self._decode = JointStateDecoder()
        subscribe_draining(node, JointState, topic, self._on_raw, STREAM_QOS)

    def _on_raw(self, raw: bytes) -> None:
        decode = self._decode
        try:
            if not little_endian(raw):
                raise ValueError("not little-endian CDR")
            t, names, _ = decode(raw)
            vel, eff = joint_state_motion(raw, decode.positions_end)
        except (ValueError, struct.error) as err:  # (UnicodeDecodeError is a ValueError)
            self.node.get_logger().error(f"{self.topic}: a message dropped: {err}", throttle_duration_sec=5.0)
            return
        n = len(names)
        if not n or (len(eff) != n and len(vel) != n):
            return
        self._samples.append((t, names, eff if len(eff) == n else None, vel if len(vel) == n else None))
        if len(eff) == n:
            self.latest = max(self.latest, t)
        if t > self._newest:
            self._newest = t
            old = t - self.keep
            while self._samples[0][0] < old:
                self._samples.popleft()

    def peaks(self, joints: Sequence[str], start: float, end: float) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The largest |effort| and the largest |velocity| of each of ``joints`` in the samples stamped in
        [``start``, ``end``] s, in their order (None: no sample there carries all of them)."""
        want = list(joints)
        out: list[np.ndarray | None] = [None, None]
        order: list[int] = []
        names: tuple[str, ...] = ()
        for t, n, eff, vel in self._samples:
            if t < start or t > end:
                continue
            if n is not names:
                index = {name: i for i, name in enumerate(n)}
                if not all(j in index for j in want):
                    continue
                names, order = n, [index[j] for j in want]
            for k, values in enumerate((eff, vel)):
                if values is not None:
                    row = np.abs(np.asarray([values[i] for i in order], dtype=float))
                    best = out[k]
                    out[k] = row if best is None else np.maximum(best, row)  # (a nan stays: a violation)
        return out[0], out[1]
