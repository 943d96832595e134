"""The type store: message definitions for writing and reading recordings.

rosbags' Jazzy typestore holds the standard types; this suite's own types (``shaper_msgs``) are
read from the installed .msg files (found through the ament index, no rclpy), so that the writer
embeds every definition in its recordings and the reader decodes bags that carry none (sqlite3
ones written without them).
"""

from __future__ import annotations

import pathlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


#: interface packages of this suite whose .msg files the type store reads
OWN_PACKAGES = ("shaper_msgs",)


def msg_files(package: str) -> list[pathlib.Path]:
    """Installed .msg files of an interface package (from the ament index)."""
    from ament_index_python.packages import get_package_share_directory

    return sorted(pathlib.Path(get_package_share_directory(package), "msg").glob("*.msg"))


def typestore_with_own_types() -> Typestore:
    """rosbags' Jazzy typestore plus this suite's message types.

    Raises
    ------
    LookupError
        An interface package of :data:`OWN_PACKAGES` is not installed (ament index).
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict = {}
    for package in OWN_PACKAGES:
        for path in msg_files(package):
            types.update(get_types_from_msg(path.read_text(), f"{package}/msg/{path.stem}"))
    store.register(types)
    return store


def default_typestore() -> Typestore:
    """rosbags' Jazzy store, with this suite's types when shaper_msgs is installed (for bags without
    definitions, e.g. sqlite3 ones written without them)."""
    try:
        return typestore_with_own_types()
    except Exception:
        from rosbags.typesys import Stores, get_typestore

        return get_typestore(Stores.ROS2_JAZZY)
