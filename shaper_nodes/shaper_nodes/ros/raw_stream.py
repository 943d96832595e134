"""Streamed inputs on serialized messages: the shaper node's array input and the JointTrajectory points of
its stream topic (bytes in, the core's rules, bytes out), and the scheduler's joint states
(:class:`RawJointStates`).

The array input (std_msgs/Float64MultiArray at ``command_rate``, 1 kHz and more) is taken by a
subscription with ``raw=True``: its callback gets the serialized ``bytes``, read by
:class:`~shaper_nodes.recordings.cdr_arrays.Float64ArrayCodec` without building a message object;
the shaped samples are written into a serialized message of the input's layout (``data_offset``
passed through) and published as ``bytes`` (``Publisher.publish`` calls ``publish_raw``). Most of a
hop's cost in rclpy is the conversion of messages to and from Python objects, which this path does
not pay (docs/results/benchmarks.md).

The rules are the core's, unchanged (:class:`~shaper_nodes.core.shaping.stream.CommandStream`:
one sample per message, or a block of samples when the layout has two dimensions, see
:func:`~shaper_nodes.core.lockstep.block_rows`); bytes that are not a well-formed little-endian CDR
Float64MultiArray are refused as ``malformed`` with the reason the codec gives, before any filter.

The stream topic's trajectory_msgs/JointTrajectory (one or a few points per message) is taken the same
way (:class:`RawTrajectories`): read by
:class:`~shaper_nodes.recordings.cdr_trajectory.JointTrajectoryCodec` into plain tuples, checked and put
in the configured joint order by the same conversion as a message object
(:func:`~shaper_nodes.ros.conversions.trajectory_arrays`: every refusal and its text as before), shaped
by :meth:`CommandStream.shape_points`, and written back as the message the node sent before (the header
with its stamp normalised, the configured joint names, each point's time_from_start normalised, the
fields shaped; effort, never shaped, left out).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from shaper_nodes.core.checks import MAX_JOINT_NAMES, InputError, joint_permutation
from shaper_nodes.core.lockstep import block_rows
from shaper_nodes.core.shaping.stream import CommandStream, normal_stamp
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
from shaper_nodes.recordings.cdr import JointStateDecoder, little_endian
from shaper_nodes.recordings.cdr_arrays import CdrError, Float64ArrayCodec
from shaper_nodes.recordings.cdr_trajectory import JointTrajectoryCodec, TooManyNames, TooManyPoints

from .conversions import trajectory_arrays

_STAMP = struct.Struct("<iI")


class RawArrays:
    """The shaper node's array input and output as serialized Float64MultiArray (module docstring).

    One caller at a time (the array subscription's callback, on one executor's thread): the codec's
    buffers are not locked; the filters are, by the stream's lock.

    Parameters
    ----------
    stream : CommandStream
        The streamed commands' filters and rules.
    """

    def __init__(self, stream: CommandStream) -> None:
        self.stream = stream
        self.codec = Float64ArrayCodec()

    def shape(self, raw: bytes) -> bytes:
        """The serialized answer to the serialized message ``raw``: its samples shaped, its layout kept.

        Raises
        ------
        InputError
            ``malformed`` (not a well-formed Float64MultiArray), or the core's refusals (wrong size,
            non-finite, beyond the limits, a block too large, ...); nothing is to be published then.
        """
        codec = self.codec
        got = codec.read_sample(raw)  # the usual message: one sample of the last layout
        if got is not None:  # (data_offset, values...): the values as a tuple, not copied again
            return codec.write_sample(got[0], self.stream.shape_values(got[1:]))
        try:
            sizes, data = codec.decode(raw)
        except CdrError as err:
            raise InputError("malformed", str(err)) from None
        stream = self.stream
        if sizes:  # a layout: one sample, or a block of samples
            rows = block_rows(sizes, len(data), stream.joints, stream.max_samples)
            if rows > 1:
                return codec.encode(stream.shape_block(data, rows))
        return codec.encode(stream.shape_array(data.tolist() if isinstance(data, np.ndarray) else data))


class RawTrajectories:
    """The shaper node's stream topic as serialized trajectory_msgs/JointTrajectory (module docstring).

    One caller at a time (the stream subscription's callback): the codec's buffers are not locked; the
    filters are, by the stream's lock.

    Parameters
    ----------
    stream : CommandStream
        The streamed commands' filters and rules.
    joint_names : sequence of str
        The configured joints, in the order of the filters' channels and of the answer.
    """

    def __init__(self, stream: CommandStream, joint_names: Sequence[str]) -> None:
        self.stream = stream
        self.joint_names = tuple(joint_names)
        self.codec = JointTrajectoryCodec()

    def shape(self, raw: bytes) -> bytes:
        """The serialized answer to the serialized JointTrajectory ``raw``: its points shaped.

        Raises
        ------
        InputError
            ``malformed`` (not a well-formed JointTrajectory), ``too_large`` (more points than
            MAX_TRAJECTORY_POINTS or names than MAX_JOINT_NAMES, before any is read), or the refusals of the
            message path (unknown or missing joints, fields on some points only, wrong sizes, non-finite
            values, times out of order, a stamp that goes back, outputs beyond the limits, ...); nothing is
            to be published then.
        """
        try:
            msg = self.codec.decode(raw, MAX_TRAJECTORY_POINTS, MAX_JOINT_NAMES)
        except TooManyPoints as err:
            raise InputError("too_large", str(err)) from None
        except TooManyNames as err:  # the message path's refusal and its text, from the count (only len is read)
            joint_permutation(self.joint_names, cast(Sequence[str], range(err.count)))
            raise InputError("too_large", str(err)) from None
        except CdrError as err:
            raise InputError("malformed", str(err)) from None
        # the message path's conversion and checks, on the decoded tuples (the same attribute names)
        times, fields = trajectory_arrays(cast(Any, msg), self.joint_names, require_times=False,
                                          limit=self.stream.max_abs)
        stamp = normal_stamp(msg.stamp.sec, msg.stamp.nanosec)
        durations = [normal_stamp(p.time_from_start.sec, p.time_from_start.nanosec) for p in msg.points]
        shaped = self.stream.shape_points(times, fields, stamp)
        return self.codec.encode(stamp, msg.frame_id, self.joint_names, durations,
                                 {f: v.tolist() for f, v in shaped.items()})


class RawJointStates:
    """sensor_msgs/JointState taken serialized: the names, positions and header stamp only.

    For the scheduler's ``/joint_states`` feed (500 Hz and more): read by
    :class:`~shaper_nodes.recordings.cdr.JointStateDecoder`, which skips the names when they are the
    previous message's; velocities and efforts are not read (nor checked: a message cut after its
    positions is read). Bytes that are not a well-formed
    little-endian CDR JointState (truncated, a name not UTF-8, positions past the end) are refused as
    ``malformed``.
    """

    def __init__(self) -> None:
        self._decoder = JointStateDecoder()

    def decode(self, raw: bytes) -> tuple[tuple[str, ...], tuple[float, ...], tuple[int, int]]:
        """(names, positions in rad or m, header stamp as (sec, nanosec)) of the serialized ``raw``.

        Raises
        ------
        InputError
            ``malformed``, the message naming the problem.
        """
        if not little_endian(raw):
            head = bytes(raw[:2]).hex(" ") or "none"
            raise InputError("malformed", f"not a little-endian CDR JointState (encapsulation {head},"
                             f" {len(raw)} bytes)")
        try:
            _, names, positions = self._decoder(raw)
            sec, nanosec = _STAMP.unpack_from(raw, 4)
        except struct.error as err:
            raise InputError("malformed", f"truncated JointState ({len(raw)} bytes: {err})") from None
        except UnicodeDecodeError as err:
            raise InputError("malformed", f"a JointState name is not UTF-8 ({err.reason})") from None
        return names, positions, (sec, nanosec)
