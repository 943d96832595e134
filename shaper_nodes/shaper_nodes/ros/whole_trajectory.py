"""Whole-trajectory shaping as the shaper node does it, and the same in a worker process.

:class:`WholeShaping` is everything a whole trajectory is shaped and checked with (the node's
joints and rate, the active FIR, the limits); :meth:`WholeShaping.shape` turns a JointTrajectory
into the shaped one or raises :class:`~shaper_nodes.core.checks.InputError`.

The trajectory topic path runs it in a worker process on the serialized messages
(:class:`TrajectoryWorker`): the node takes the input as bytes (a raw subscription), the worker
decodes, shapes, checks and encodes, and the node publishes the bytes it gets back. So the node's
own interpreter does no per-point work at all for that path, and its stream does not wait while a
long trajectory is shaped; in a thread of the node it would (Python runs one thread at a time:
docs/design/shaping.md, "What leaves the shaper"). The service and the action need the message objects
in the node (rclpy converts their requests and answers itself), so they shape in the node's side
thread.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

import numpy as np
from trajectory_msgs.msg import JointTrajectory

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.lifetime import die_with_parent
from shaper_nodes.core.shaping import SparseFir, shape_trajectory
from shaper_nodes.core.shaping.limits import JointLimits
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS, check_extent

from .conversions import duration_to_sec, trajectory_arrays, trajectory_msg

#: most values of one field of a whole trajectory's input (its points x joints: 100,000 points of a 6-joint arm,
#: 85,714 of a 7-joint one), refused before any per-point work; the points alone are bounded by
#: :data:`~shaper_nodes.core.shaping.trajectory.MAX_TRAJECTORY_POINTS`
MAX_TRAJECTORY_VALUES = 600_000


@dataclass(frozen=True)
class WholeShaping:
    """What a whole trajectory is shaped and checked with (picklable, for the worker)."""

    joint_names: tuple[str, ...]
    rate: float
    fir: SparseFir
    limits: JointLimits
    max_abs: float
    max_samples: int

    def check_size(self, msg: JointTrajectory) -> None:
        """Refuse a trajectory too large to shape before any work on its points: more than
        :data:`~shaper_nodes.core.shaping.trajectory.MAX_TRAJECTORY_POINTS` points, more than
        :data:`MAX_TRAJECTORY_VALUES` points x joints (the message's joint names or the node's, the larger),
        or a span from its first to its last point that resamples to more than ``max_samples`` samples at
        the rate (with the shaper's length). Reads the number of points and two points' times only.

        Raises
        ------
        InputError
            ``too_large``, with the sizes and the limit.
        """
        points, joints = len(msg.points), max(len(msg.joint_names), len(self.joint_names))
        if points > MAX_TRAJECTORY_POINTS or points * joints > MAX_TRAJECTORY_VALUES:
            raise InputError("too_large", f"{points} points x {joints} joints exceed the limits of"
                             f" {MAX_TRAJECTORY_POINTS} points and {MAX_TRAJECTORY_VALUES} values (points x joints)")
        if points:
            ends = np.array([duration_to_sec(msg.points[0].time_from_start),
                             duration_to_sec(msg.points[-1].time_from_start)])
            if np.all(ends >= 0.0):  # a negative time is refused with its point's index by the full check
                check_extent(ends, self.rate, self.fir.length, self.max_samples)

    def shape(self, msg: JointTrajectory, pause: Callable[[], None] | None = None) -> JointTrajectory:
        """``msg`` shaped and checked: its size first (:meth:`check_size`), then resampled at the rate,
        convolved, differentiated, held against the limits (positions, velocities, accelerations) and
        the time range. Raises InputError."""
        self.check_size(msg)
        times, fields = trajectory_arrays(msg, self.joint_names, require_times=True, limit=self.max_abs)
        result = shape_trajectory(times, fields["positions"], self.fir, self.rate, fields.get("velocities"),
                                  max_samples=self.max_samples)
        self.limits.check_trajectory(result.times, result.positions, result.velocities, result.accelerations)
        return trajectory_msg(msg.header, self.joint_names, result.times,
                              {"positions": result.positions, "velocities": result.velocities,
                               "accelerations": result.accelerations}, pause=pause)


#: what the worker answers: ("shaped", bytes, points) or ("refused", kind, message)
Answer = tuple[str, object, object]


def shape_serialized(how: WholeShaping, data: bytes) -> Answer:
    """In the worker: the serialized JointTrajectory ``data`` shaped, as serialized bytes."""
    from rclpy.serialization import deserialize_message, serialize_message

    try:
        msg = deserialize_message(data, JointTrajectory)
    except Exception as err:  # a message that does not decode is refused, never a dead worker
        return "refused", "unsupported", f"the trajectory does not decode ({type(err).__name__})"
    try:
        out = how.shape(msg)
    except InputError as err:
        return "refused", err.kind, str(err)
    return "shaped", serialize_message(out), len(out.points)


def _worker_init(parent: int) -> None:
    """The worker's start: it ends with the node (``kill -9`` of the node leaves no worker), one BLAS thread."""
    die_with_parent(signal.SIGKILL, parent)  # nothing of the worker's needs a clean stop
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core's work; the node has the other


class TrajectoryWorker:
    """One worker process that shapes serialized trajectories (see the module docstring).

    It is started with the first request (spawned, so it shares nothing with the node's threads)
    and restarted if it died; :meth:`close` stops it. It ends with the node's process even when that is
    killed with ``kill -9`` (``prctl(PR_SET_PDEATHSIG)``, core/lifetime.py). The kernel sends that signal when
    the *thread* that started the worker ends: :meth:`submit` starts it (concurrent.futures starts a spawned
    pool's workers in ``submit``), so call it from a thread that lives as long as the node (the node's side
    thread does), never from a short-lived one.
    """

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None

    def _executor(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_init, initargs=(os.getpid(),))
        return self._pool

    def submit(self, how: WholeShaping, data: bytes) -> Future[Answer]:
        try:
            return self._executor().submit(shape_serialized, how, data)
        except BrokenProcessPool:  # the worker died (killed, out of memory): a new one
            self.close()
            return self._executor().submit(shape_serialized, how, data)

    def shape(self, how: WholeShaping, data: bytes, timeout: float) -> Answer:
        """Shape ``data`` in the worker, waiting at most ``timeout`` s; a dead or late worker is an
        answer too (refused, with the reason)."""
        try:
            return self.submit(how, data).result(timeout=timeout)
        except BrokenProcessPool:
            self.close()
            return "refused", "unsupported", "the trajectory worker process died while shaping it"
        except TimeoutError:
            self.close()
            return "refused", "too_large", f"the trajectory worker did not finish within {timeout:g} s"

    def close(self) -> None:
        if self._pool is not None:
            pool, self._pool = self._pool, None
            # a worker busy with a long request is not waited for (concurrent.futures has no public call
            # for this before Python 3.14's terminate_workers)
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                if proc.is_alive():
                    proc.kill()
            pool.shutdown(wait=False, cancel_futures=True)
