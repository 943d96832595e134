"""The sim plant node's sensor outputs: /joint_states as the encoders report it, and the accelerometer.

:class:`Sensors` applies the sensor parameters (``imu.*`` and ``joint_states.*``: encoder noise and
quantum, accelerometer and gyro noise and bias, the IMU's frame) to what the model gives
(:meth:`~sim_plant_node.models.base.Plant.joint_state`, :meth:`~sim_plant_node.models.base.Plant.imu`)
and publishes it, /joint_states and the Imu as serialized bytes written in place (``JointStateCdr``, ``ImuCdr`` of
:mod:`shaper_nodes.recordings.cdr`; no message object per sample). :class:`StateBytes` writes the plant's other
JointState outputs (the tip state, the reference) the same way. ``sim_plant_node/test/test_imu_bytes.py`` and
``test_state_bytes.py`` hold the bytes equal to rclpy's ``serialize_message`` of the messages the node built before.
:class:`WriteBatch` keeps a lockstep plant's per-step writes of a few periods and writes them together, in order.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from shaper_nodes.core.cycles import CycleMonitor
from shaper_nodes.recordings.cdr import ImuCdr, JointStateCdr, stamp_parts

from ..models.base import Plant
from .parameters import ImuParams, JointStatesParams

__all__ = ["BATCH_PERIODS", "Sensors", "StateBytes", "WriteBatch", "writer"]

#: periods whose per-step writes a lockstep plant writes together at most (:class:`WriteBatch`): 20 ms of simulated
#: time at the arm's 500 Hz, a tenth of ``lockstep.lead``'s default
BATCH_PERIODS = 10


def writer(publisher: Any) -> Callable[[bytes], None]:
    """The write of serialized bytes to ``publisher`` (an rclpy publisher), a per-step stream's: its handle's own,
    without what rclpy's ``Publisher.publish`` does at every call besides (its handle taken as a context, the
    argument told from a message object): about half of a write's Python time. The node's thread is the only one
    that writes and destroys the publisher. A stand-in without a handle is written with its ``publish``."""
    handle = getattr(publisher, "handle", None)
    return publisher.publish if handle is None else handle.publish_raw


class WriteBatch:
    """A lockstep plant's per-step writes, kept and written together: those of ``periods`` periods at most, and
    all of them whenever the node does anything else (:meth:`flush`: before a cycle event, an action's feedback,
    an ask of the shaper, a hold by a reader, and at the end of every callback that stepped).

    The same messages go out in the same order, each to its writer; only when changes, by at most ``periods``
    periods of simulated time (milliseconds of wall time at the plant's lockstep rates). Why: a write to a reader costs
    the writing thread 5.5-7 us against 1.5 with none, and interleaved with the stepping each one found the reader's
    DDS receive thread asleep; written together (issue 34, session 11, with a drained reader): the plant's main thread
    0.87x and the reader's process 0.85x of their CPU per simulated s, though a write timed alone inside a batch
    costs about what it did (the gain is around the writes: fewer wake-ups of the reader on the two cores the plant
    shares, and, presumably, Fast DDS's code and the port's memory kept in cache for a burst; not measured apart).

    Parameters
    ----------
    periods : int
        Periods kept at most (>= 1).
    """

    def __init__(self, periods: int = BATCH_PERIODS) -> None:
        if periods < 1:
            raise ValueError(f"periods must be >= 1, got {periods!r}")
        self.periods = periods
        self._pending: list[tuple[Callable[[Any], None], Any]] = []
        self._kept = 0  # periods kept

    def deferred(self, write: Callable[[Any], None]) -> Callable[[Any], None]:
        """``write`` (of serialized bytes or a message) kept until the batch is written."""
        append = self._pending.append
        return lambda data: append((write, data))

    def period(self) -> None:
        """A period's writes are in: written with the kept ones once ``periods`` periods are."""
        self._kept += 1
        if self._kept >= self.periods:
            self.flush()

    def flush(self) -> None:
        """Write everything kept, in order."""
        pending, self._kept = self._pending, 0
        try:
            for write, data in pending:
                write(data)
        finally:
            pending.clear()  # (the list the deferred writes append to)

    def __len__(self) -> int:
        """Writes kept."""
        return len(self._pending)


class StateBytes:
    """A sensor_msgs/JointState of fixed ``names`` as serialized (CDR) bytes, its numbers rewritten in place: the
    bytes rclpy serializes for ``JointState(name=names, position=..., velocity=...)`` (outside the padding),
    without building a message object.

    Parameters
    ----------
    names : list of str
        The message's ``name``.
    """

    def __init__(self, names: list[str]) -> None:
        self.names = list(names)
        self._cdr: JointStateCdr | None = None  # made for the array lengths of the last message

    def __call__(self, t: float, position: np.ndarray, velocity: np.ndarray | None = None) -> bytes:
        """The message stamped ``t`` s with ``position`` (rad or m) and ``velocity`` (None: empty), serialized."""
        sizes = (len(position), 0 if velocity is None else len(velocity), 0)
        cdr = self._cdr
        if cdr is None or cdr.sizes != sizes:
            cdr = self._cdr = JointStateCdr(self.names, *sizes)
        cdr.position[:] = position
        if velocity is not None:
            cdr.velocity[:] = velocity
        cdr.set_stamp(*stamp_parts(t))
        return cdr.data()


class Sensors:
    """The encoders and the accelerometer of the simulated robot.

    Parameters
    ----------
    joint_names : list of str
        The joints, in /joint_states' order.
    imu : ImuParams
        The accelerometer's settings (``imu.*``; ``imu.seed`` seeds the noise generator).
    joint_states : JointStatesParams
        The encoders' settings (``joint_states.*``).
    imu_pub : rclpy publisher
        Where the Imu messages go (as serialized bytes).
    monitor : CycleMonitor
        Takes every accelerometer sample (the per-cycle residual vibration).
    batch : WriteBatch, optional
        Keeps the Imu writes (lockstep); None: each written at once.
    """

    def __init__(self, joint_names: list[str], imu: ImuParams, joint_states: JointStatesParams, imu_pub: Any,
                 monitor: CycleMonitor, batch: WriteBatch | None = None) -> None:
        self.joint_names = joint_names
        self.rng = np.random.default_rng(int(imu.seed))
        self._imu_write = writer(imu_pub) if batch is None else batch.deferred(writer(imu_pub))
        self._monitor = monitor
        self.changed(imu, joint_states)
        # /joint_states and the IMU are published as serialized bytes, their numbers rewritten in place
        # (shaper_nodes.recordings.cdr): the same messages, without building message objects
        self._imu = ImuCdr(self._imu_frame)  # (imu.frame_id is read-only)
        self._imu.orientation_covariance[0] = -1.0  # no orientation
        self._imu_gyro_sigma: float | None = None  # the gyro covariance written in it
        self._acc_sigma_written: float | None = None  # the accelerometer's
        self._js_cdr: JointStateCdr | None = None  # made for the array lengths the plant reports

    def changed(self, imu: ImuParams, joint_states: JointStatesParams) -> None:
        """Take the sensor settings ``imu`` and ``joint_states`` (read at every sample: kept here)."""
        self._imu_bias = np.asarray(imu.bias, dtype=float)[:3]
        self._gyro_bias = np.asarray(imu.gyro_bias, dtype=float)[:3]
        self._imu_sigma = float(imu.noise_stddev)
        self._gyro_sigma = float(imu.gyro_noise_stddev)
        self._imu_frame = str(imu.frame_id)
        self._js_sigma = float(joint_states.noise_stddev)
        self._js_quantum = float(joint_states.resolution)

    def joint_state(self, plant: Plant, t: float) -> bytes:
        """The serialized /joint_states message at ``t`` s: reported positions, velocities, efforts (if any)."""
        position, velocity, effort = plant.joint_state()
        position = self.reported(position)
        sizes = (position.size, velocity.size, 0 if effort is None else effort.size)
        js = self._js_cdr
        if js is None or js.sizes != sizes:  # (a plant model changed live may report efforts or not)
            js = self._js_cdr = JointStateCdr(self.joint_names, *sizes)
        js.position[:] = position
        js.velocity[:] = velocity
        if effort is not None:
            js.effort[:] = effort
        js.set_stamp(*stamp_parts(t))
        return js.data()

    def joint_state_message(self, plant: Plant, stamp: Any) -> JointState:
        """The /joint_states message of ``plant``'s present state, stamped ``stamp`` (builtin_interfaces/Time)."""
        position, velocity, effort = plant.joint_state()
        msg = JointState(name=self.joint_names, position=self.reported(position).tolist(), velocity=velocity.tolist(),
                         effort=(np.zeros(0) if effort is None else effort).tolist())
        msg.header.stamp = stamp
        return msg

    def reported(self, position: np.ndarray) -> np.ndarray:
        """Joint positions as the encoders report them: noise and quantisation as the parameters say."""
        sigma, quantum = self._js_sigma, self._js_quantum
        if sigma > 0:
            position = position + self.rng.normal(0.0, sigma, position.size)
        if quantum > 0:
            position = np.round(position / quantum) * quantum
        return position

    def publish_imu(self, t: float, acc: np.ndarray, rate: np.ndarray | None) -> None:
        """One Imu message at ``t``: specific force ``acc`` (m/s^2), angular rate ``rate`` (rad/s; None: none)."""
        acc = acc + self._imu_bias
        sigma = self._imu_sigma
        if sigma > 0:
            acc += self.rng.normal(0.0, sigma, 3)
        imu = self._imu
        imu.set_stamp(*stamp_parts(t))
        if rate is None:
            imu.angular_velocity_covariance[0] = -1.0
        else:
            gyro_sigma = self._gyro_sigma
            rate = rate + self._gyro_bias
            if gyro_sigma > 0:
                rate += self.rng.normal(0.0, gyro_sigma, 3)
            imu.angular_velocity[:] = rate
            if gyro_sigma != self._imu_gyro_sigma:
                imu.angular_velocity_covariance[:] = 0.0
                imu.angular_velocity_covariance[::4] = gyro_sigma**2
                self._imu_gyro_sigma = gyro_sigma
        imu.linear_acceleration[:] = acc
        if sigma != self._acc_sigma_written:
            imu.linear_acceleration_covariance[::4] = sigma**2
            self._acc_sigma_written = sigma
        self._imu_write(imu.data())
        self._monitor.add_accel(t, acc)
