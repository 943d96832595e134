"""Stamps and durations in seconds: the one conversion of a ``sec``/``nanosec`` pair.

A builtin_interfaces/Time or Duration from rclpy, a message rosbags decoded from a recording, or any
object with integer ``sec`` and ``nanosec`` attributes is taken; nothing of ROS is imported.
"""

from __future__ import annotations

from typing import Any

__all__ = ["stamp_to_sec"]


def stamp_to_sec(stamp: Any) -> float:
    """``stamp.sec + 1e-9 * stamp.nanosec``, s (a header stamp, a ``time_from_start``)."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)
