"""rosbag2 folders with MCAP storage, written with the pure-Python ``rosbags`` library.

rosbag2_py is not on PyPI, so recordings are written with rosbags' Writer (metadata.yaml plus
an MCAP file with ros2msg schemas). Message definitions of standard types come from rosbags'
Jazzy typestore; those of this suite's own types (shaper_msgs) are read from the installed
.msg files, so that ``ros2 bag info`` and independent readers (``mcap`` with
``mcap-ros2-support``) can decode every message.
"""

from __future__ import annotations

import importlib
import pathlib
from typing import Any

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

OWN_PACKAGES = ("shaper_msgs",)


def msg_files(package: str) -> list[pathlib.Path]:
    """Installed .msg files of an interface package (from the ament index)."""
    from ament_index_python.packages import get_package_share_directory

    return sorted(pathlib.Path(get_package_share_directory(package), "msg").glob("*.msg"))


def typestore_with_own_types() -> Typestore:
    """rosbags' Jazzy typestore plus this suite's message types."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict = {}
    for package in OWN_PACKAGES:
        for path in msg_files(package):
            types.update(get_types_from_msg(path.read_text(), f"{package}/msg/{path.stem}"))
    store.register(types)
    return store


def message_class(type_name: str) -> Any:
    """The Python class of a ROS type name such as ``sensor_msgs/msg/Imu``."""
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


class BagWriter:
    """A rosbag2 folder with MCAP storage; add topics as they appear, write CDR bytes."""

    def __init__(self, path: str | pathlib.Path) -> None:
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise FileExistsError(f"recording folder {self.path} exists already")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._store = typestore_with_own_types()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}

    def add_topic(self, topic: str, type_name: str) -> None:
        if topic not in self._connections:
            if type_name not in self._store.fielddefs:
                raise KeyError(f"no message definition for {type_name}")
            self._connections[topic] = self._writer.add_connection(topic, type_name, typestore=self._store)
            self.counts[topic] = 0

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        self._writer.write(self._connections[topic], int(timestamp_ns), data)
        self.counts[topic] += 1

    def close(self) -> None:
        self._writer.close()
