"""Recordings: rosbag2 folders with MCAP storage, read and written in one place, free of ROS.

Nothing in this package imports rclpy, message types, ``shaper_nodes.ros`` or
``shaper_nodes.nodes``; the recorder's subscriptions and bag_play's publishers (the rclpy glue)
stay in ``shaper_nodes.nodes``. The names below are exported here and imported on first use, so
that ``from shaper_nodes.recordings.cdr import ...`` (the sim plant's publishers) stays light.

Modules
-------
reader
    :class:`Bag`: open a recording (a rosbag2 folder or a bare .mcap file) and iterate its messages
    as CDR bytes, with a deserialiser per type; damaged and unclosed files are recovered.
bounds
    :class:`ReadLimits` and the checks made before anything is parsed or inflated: metadata.yaml's
    size (:func:`read_metadata`, the one entry point to a recording's metadata), chunk sizes and
    compression ratios (:func:`scan_mcap`, :func:`check_chunk`), bounded inflation (:func:`inflate`).
recovery
    A damaged or unclosed MCAP file read record by record (:func:`mcap_chunks`: its chunks' offsets).
damage
    :class:`Damage`, what a damaged or unclosed file lost, and how it is said (:func:`describe_damage`,
    :func:`describe_unclosed`).
writer
    :class:`BagWriter` (chunks closed and flushed by time, heartbeats, clean abandon),
    :class:`QueuedRecording` (the recorder's bounded queue and writer thread),
    :func:`rename_recording`.
typestore
    rosbags' Jazzy typestore plus this suite's message types (from the installed .msg files).
heartbeat
    The recorder's heartbeat in its recordings, and :func:`loss_bound`: what a recording that was
    not closed lost at most.
order
    :func:`shaper_after_end`: a shaper logged at a cycle's END instant goes after the END.
cdr
    Pure-Python CDR: messages serialized in place for publishers (the sim plant's JointState,
    Clock, Imu), and the fields of Imu and JointState parsed directly by the analyses.
cdr_arrays, cdr_trajectory
    std_msgs/Float64MultiArray and trajectory_msgs/JointTrajectory read from and written to serialized bytes
    (the shaper node's raw streamed inputs and outputs).
cdr_sensors
    Checked readers of serialized Imu and JointState (the stamp and the fields a reader uses).
errors
    :class:`BagError` (every refusal and failure to read) and :class:`ChunkTooLarge`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .bounds import (
        MIB,
        McapScan,
        ReadLimits,
        check_chunk,
        inflate,
        read_metadata,
        scan_mcap,
        size_text,
    )
    from .cdr import (
        ImuCdr,
        JointStateCdr,
        JointStateDecoder,
        SerializedMessage,
        clock_cdr,
        imu_fast,
        joint_state_efforts,
        joint_state_fast,
        joint_state_motion,
        stamp_parts,
    )
    from .damage import (
        Damage,
        describe_damage,
        describe_unclosed,
    )
    from .errors import (
        BagError,
        ChunkTooLarge,
    )
    from .heartbeat import (
        HEARTBEAT_NAME,
        HEARTBEAT_SUFFIX,
        HEARTBEAT_TYPE,
        Heartbeat,
        LossBound,
        is_heartbeat_topic,
        loss_bound,
        rates_between,
    )
    from .order import (
        MAX_TIE_GROUP,
        shaper_after_end,
    )
    from .reader import (
        Bag,
        ReadResult,
        TopicInfo,
        mcap_files,
    )
    from .recovery import (
        mcap_chunks,
    )
    from .typestore import (
        OWN_PACKAGES,
        default_typestore,
        msg_files,
        typestore_with_own_types,
    )
    from .writer import (
        COMPRESSIONS,
        BagWriter,
        QueuedRecording,
        describe_write_error,
        rename_recording,
    )

#: exported name -> the module that defines it
_HOME = {
    "BagError": "errors",
    "ChunkTooLarge": "errors",
    "MIB": "bounds",
    "ReadLimits": "bounds",
    "McapScan": "bounds",
    "check_chunk": "bounds",
    "inflate": "bounds",
    "read_metadata": "bounds",
    "scan_mcap": "bounds",
    "size_text": "bounds",
    "Bag": "reader",
    "ReadResult": "reader",
    "TopicInfo": "reader",
    "mcap_files": "reader",
    "Damage": "damage",
    "describe_damage": "damage",
    "describe_unclosed": "damage",
    "mcap_chunks": "recovery",
    "COMPRESSIONS": "writer",
    "BagWriter": "writer",
    "QueuedRecording": "writer",
    "describe_write_error": "writer",
    "rename_recording": "writer",
    "OWN_PACKAGES": "typestore",
    "default_typestore": "typestore",
    "msg_files": "typestore",
    "typestore_with_own_types": "typestore",
    "HEARTBEAT_NAME": "heartbeat",
    "HEARTBEAT_SUFFIX": "heartbeat",
    "HEARTBEAT_TYPE": "heartbeat",
    "Heartbeat": "heartbeat",
    "LossBound": "heartbeat",
    "is_heartbeat_topic": "heartbeat",
    "loss_bound": "heartbeat",
    "rates_between": "heartbeat",
    "MAX_TIE_GROUP": "order",
    "shaper_after_end": "order",
    "ImuCdr": "cdr",
    "JointStateCdr": "cdr",
    "JointStateDecoder": "cdr",
    "SerializedMessage": "cdr",
    "clock_cdr": "cdr",
    "imu_fast": "cdr",
    "joint_state_efforts": "cdr",
    "joint_state_fast": "cdr",
    "joint_state_motion": "cdr",
    "stamp_parts": "cdr",
}

__all__ = [
    "COMPRESSIONS",
    "HEARTBEAT_NAME",
    "HEARTBEAT_SUFFIX",
    "HEARTBEAT_TYPE",
    "MAX_TIE_GROUP",
    "MIB",
    "OWN_PACKAGES",
    "Bag",
    "BagError",
    "BagWriter",
    "ChunkTooLarge",
    "Damage",
    "Heartbeat",
    "ImuCdr",
    "JointStateCdr",
    "JointStateDecoder",
    "LossBound",
    "McapScan",
    "QueuedRecording",
    "ReadLimits",
    "ReadResult",
    "SerializedMessage",
    "TopicInfo",
    "check_chunk",
    "clock_cdr",
    "default_typestore",
    "describe_damage",
    "describe_unclosed",
    "describe_write_error",
    "imu_fast",
    "inflate",
    "is_heartbeat_topic",
    "joint_state_efforts",
    "joint_state_fast",
    "joint_state_motion",
    "loss_bound",
    "mcap_chunks",
    "mcap_files",
    "msg_files",
    "rates_between",
    "read_metadata",
    "rename_recording",
    "scan_mcap",
    "shaper_after_end",
    "size_text",
    "stamp_parts",
    "typestore_with_own_types",
]


def __getattr__(name: str) -> Any:
    """An exported name, its module imported on first use (PEP 562)."""
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{home}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))
