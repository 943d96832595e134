"""The arrays an analysis works on (:class:`Signal`, :class:`Events`, :class:`Shapers`) and the message
types of the roles (split out of :mod:`.streams`, which re-exports them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

IMU, JOINT_STATE = "sensor_msgs/msg/Imu", "sensor_msgs/msg/JointState"
ARRAY, TRAJECTORY = "std_msgs/msg/Float64MultiArray", "trajectory_msgs/msg/JointTrajectory"
EVENT, SHAPER = "shaper_msgs/msg/CycleEvent", "shaper_msgs/msg/Shaper"



@dataclass
class Events:
    """Cycle events: order in the recording, time (s), kind, cycle, start and goal positions, the joints, and the
    stamp of the cycle's START each carries (s; NaN: absent, as in recordings older than the field)."""

    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    kind: list[int] = field(default_factory=list)
    cycle: list[int] = field(default_factory=list)
    start: list[tuple[float, ...]] = field(default_factory=list)
    goal: list[tuple[float, ...]] = field(default_factory=list)
    joint_names: list[tuple[str, ...]] = field(default_factory=list)
    start_stamp: list[float] = field(default_factory=list)


@dataclass
class Shapers:
    """Active-shaper messages: order, time it became active (s), family, impulses, source, revision."""

    seq: list[int] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    family: list[str] = field(default_factory=list)
    amplitudes: list[tuple[float, ...]] = field(default_factory=list)
    times: list[tuple[float, ...]] = field(default_factory=list)
    source: list[str] = field(default_factory=list)
    revision: list[int] = field(default_factory=list)


@dataclass
class Signal:
    """Samples of one topic: order in the recording, time (s) and values (N, k)."""

    topic: str
    seq: np.ndarray
    t: np.ndarray
    values: np.ndarray
    names: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.t.size)
