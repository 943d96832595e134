"""The suite's QoS profiles, chosen on purpose and defined once.

LATCHED
    RELIABLE + TRANSIENT_LOCAL, depth 1: state that a late joiner must get (the active shaper,
    the mode estimate). Subscribers use the same profile.
IMU_QOS
    The accelerometer stream: best effort as sensors publish, volatile, but a deep queue (5000
    samples): a node that computes between callbacks (identification, learning) must not drop
    the samples that arrive meanwhile, and with the default sensor-data depth (5) a busy machine
    drops samples and the measured residual depends on the load.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
IMU_QOS = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.VOLATILE)

__all__ = ["IMU_QOS", "LATCHED"]
