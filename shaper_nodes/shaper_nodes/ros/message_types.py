"""Message classes by their ROS type names, for the nodes that publish or subscribe to recorded types.

The recordings package (:mod:`shaper_nodes.recordings`) knows types by name only; the recorder's
subscriptions and bag_play's publishers need the Python classes, imported here on demand.
"""

from __future__ import annotations

import importlib
from typing import Any


def message_class(type_name: str) -> Any:
    """The Python class of a ROS type name such as ``sensor_msgs/msg/Imu``."""
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
