"""The feedforward profile of the sim plant node (``~/set_feedforward``), free of ROS.

A profile is indexed by the sample within the cycle and installed at the next START (at once when no
cycle runs): "command" profiles are added to the shaped setpoint (every model), "effort" profiles to
the controller output (a model whose :attr:`~sim_plant_node.models.base.Plant.injections` has it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["Feedforward", "check_profile"]

#: an injection and its samples x joints
Profile = tuple[str, np.ndarray]


def check_profile(msg: Any, injections: Sequence[str], joint_names: list[str], rate: float) -> Profile:
    """The (injection, samples x joints) of a shaper_msgs/FeedforwardProfile ``msg`` for a model that takes
    ``injections``, ``joint_names`` at ``rate`` Hz; ValueError naming what does not fit."""
    if msg.injection not in ("effort", "command"):
        raise ValueError(f"injection must be 'effort' or 'command', got {msg.injection!r}")
    if msg.injection not in injections:
        raise ValueError("an effort profile needs plant.model 'mck_pid' (no controller output to add it to)")
    if list(msg.joint_names) != joint_names:
        raise ValueError(f"joint names {list(msg.joint_names)} do not match the plant's {joint_names}")
    if not (math.isfinite(msg.sample_period) and abs(msg.sample_period * rate - 1.0) < 1e-6):
        raise ValueError(f"sample period {msg.sample_period!r} s does not match the plant's {1.0 / rate:g} s")
    data = np.asarray(msg.data, dtype=float)
    n = len(joint_names)
    if data.size % n:
        raise ValueError(f"{data.size} values are not a whole number of samples of {n} joints")
    if not np.all(np.isfinite(data)):
        raise ValueError(f"non-finite value at index {int(np.argmax(~np.isfinite(data)))}")
    return msg.injection, data.reshape(-1, n)


class Feedforward:
    """The installed profile and the one waiting for the next START."""

    def __init__(self) -> None:
        self.pending: Profile | None = None
        self.active: Profile | None = None  # (injection, samples x joints) of this cycle

    def set(self, profile: Profile, at_once: bool) -> tuple[int, bool]:
        """Take ``profile`` (an empty one removes the profile) from the next START, or ``at_once`` (no cycle
        runs); returns its samples and whether it waits for the next START."""
        self.pending = profile
        if at_once:
            self.start()
        samples = self.pending[1].shape[0] if self.pending else (self.active[1].shape[0] if self.active else 0)
        return samples, self.pending is not None

    def request(self, msg: Any, injections: Sequence[str], joint_names: list[str], rate: float,
                at_once: bool) -> tuple[bool, str]:
        """The ``~/set_feedforward`` request's profile ``msg``, checked (:func:`check_profile`) and taken
        (:meth:`set`): whether it was taken, and the answer's message."""
        try:
            profile = check_profile(msg, injections, joint_names, rate)
        except ValueError as err:
            return False, str(err)
        samples, waits = self.set(profile, at_once)
        return True, (f"{msg.injection} profile of {samples} samples (iteration {msg.iteration})"
                      + (" from the next START" if waits else " installed"))

    def start(self) -> None:
        """A cycle starts: the pending profile (if any) becomes the installed one."""
        if self.pending is not None:
            self.active, self.pending = (None if self.pending[1].size == 0 else self.pending), None

    def sample(self, k: int | None) -> Profile | None:
        """The installed profile's sample ``k`` of the cycle (None outside it, or no cycle: ``k`` None)."""
        if self.active is None or k is None:
            return None
        return (self.active[0], self.active[1][k]) if 0 <= k < self.active[1].shape[0] else None
