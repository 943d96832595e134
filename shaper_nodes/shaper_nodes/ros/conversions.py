"""Conversions between messages and the core's arrays and objects (the nodes' edge), written once:
modes and mode estimates, shapers, stamps and durations, trajectories.

Messages carry frequencies in Hz (``shaper_msgs/Mode.frequency_hz``); the core's :class:`Mode`
holds rad/s. Only :func:`mode_to_msg`, :func:`mode_from_msg` and :func:`estimate_msg` read or write
the message's frequency fields, so a change of the message lands here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

import numpy as np
from builtin_interfaces.msg import Duration, Time
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from shaper_msgs.msg import Mode as ModeMsg
from shaper_msgs.msg import ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_nodes.core.checks import MAX_JOINT_NAMES, InputError, finite_array, joint_permutation
from shaper_nodes.core.shaping import (
    DEFAULT_INSENSITIVITY,
    DEFAULT_MAX_GAIN,
    DEFAULT_VIBRATION_TOLERANCE,
    Mode,
    Shaper,
    ShaperError,
    design,
)
from shaper_nodes.core.shaping.stream import FIELDS, check_times
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_POINTS
from shaper_nodes.core.stamps import stamp_to_sec

#: rad per turn: Hz on the messages, rad/s in the core
TWO_PI = 2.0 * math.pi


class AnyMode(Protocol):
    """A mode as the core holds one (:class:`Mode`, an identified ``ModeFit``): rad/s and damping."""

    @property
    def omega(self) -> float: ...
    @property
    def zeta(self) -> float: ...


def mode_to_msg(mode: AnyMode) -> ModeMsg:
    """The core's mode (or an identified one: ``omega`` in rad/s, ``zeta``) as a shaper_msgs/Mode (Hz)."""
    return ModeMsg(frequency_hz=float(mode.omega) / TWO_PI, damping_ratio=float(mode.zeta))


def mode_from_msg(msg: ModeMsg) -> Mode:
    """A shaper_msgs/Mode (Hz) as the core's mode (rad/s).

    Raises
    ------
    ShaperError
        The frequency is not finite and > 0, or the damping ratio is out of range.
    """
    hz = float(msg.frequency_hz)
    if not (math.isfinite(hz) and hz > 0.0):
        raise ShaperError(f"mode frequency_hz must be finite and > 0 Hz, got {hz!r}")
    return Mode.from_hz(hz, float(msg.damping_ratio))


def mode_msg(hz: float, zeta: float) -> ModeMsg:
    """A shaper_msgs/Mode of natural frequency ``hz`` (Hz) and damping ratio ``zeta``, unchecked (a
    request as a client writes it; the receiver checks it)."""
    return ModeMsg(frequency_hz=float(hz), damping_ratio=float(zeta))


def msg_hz(msg: ModeMsg) -> float:
    """The natural frequency of a shaper_msgs/Mode, Hz (unchecked: a request's value as sent)."""
    return float(msg.frequency_hz)


def estimate_msg(source: str, modes: Sequence[AnyMode], omega_std: Sequence[float] = (),
                 zeta_std: Sequence[float] = (), stamp: Time | None = None) -> ModeEstimate:
    """A shaper_msgs/ModeEstimate of ``modes`` (the core's or identified ones, rad/s) with their one-sigma
    uncertainties (``omega_std`` in rad/s, ``zeta_std`` dimensionless; empty: not given), the
    frequencies and their uncertainties in Hz."""
    est = ModeEstimate(source=source, modes=[mode_to_msg(m) for m in modes])
    est.frequency_hz_std = [float(w) / TWO_PI for w in omega_std]
    est.damping_ratio_std = [float(z) for z in zeta_std]
    if stamp is not None:
        est.header.stamp = stamp
    return est


def estimate_modes(msg: ModeEstimate) -> list[tuple[float, float]]:
    """The (frequency Hz, damping ratio) pairs of a shaper_msgs/ModeEstimate, unchecked."""
    return [(float(m.frequency_hz), float(m.damping_ratio)) for m in msg.modes]


def shaper_to_msg(shaper: Shaper, source: str, revision: int, stamp: Time | None = None) -> ShaperMsg:
    """The core shaper as a shaper_msgs/Shaper."""
    msg = ShaperMsg()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.family = shaper.family
    msg.amplitudes = shaper.amplitudes.tolist()
    msg.times = shaper.times.tolist()
    msg.design_modes = [mode_to_msg(m) for m in shaper.modes]
    msg.derivative_order = int(shaper.params.get("derivative_order", 0))
    # 0 where the family does not use the parameter (in requests 0 means the family default)
    msg.vibration_tolerance = float(shaper.params.get("vibration_tolerance", 0.0))
    msg.insensitivity = float(shaper.params.get("insensitivity", 0.0))
    msg.source = source
    msg.revision = int(revision)
    return msg


def shaper_from_msg(msg: ShaperMsg, max_gain: float = DEFAULT_MAX_GAIN) -> Shaper:
    """Design or validate the shaper a shaper_msgs/Shaper asks for (a custom one within ``max_gain``);
    its design modes in Hz (``Mode.frequency_hz``). The shaper node then checks it as it checks a
    design from its parameters (``core.shaping.policy.check_design``).

    ``vibration_tolerance`` and ``insensitivity`` equal to 0 mean the family default (5 % and
    0.4); any other value is passed on and checked by the design (families that do not use a
    parameter ignore it).

    Raises
    ------
    ShaperError
        If the request is invalid; the message names the problem.
    """
    modes = tuple(mode_from_msg(m) for m in msg.design_modes)
    family = msg.family.strip().lower() or ("custom" if len(msg.amplitudes) else "")
    if not family:
        raise ShaperError("family is empty")
    if family != "custom" and (len(msg.amplitudes) or len(msg.times)):
        raise ShaperError(f"amplitudes/times given for family {family!r}; use family 'custom'")
    return design(
        family,
        modes,
        derivative_order=int(msg.derivative_order) if family == "zvdn" else 1,
        vibration_tolerance=_or_default(msg.vibration_tolerance, DEFAULT_VIBRATION_TOLERANCE),
        insensitivity=_or_default(msg.insensitivity, DEFAULT_INSENSITIVITY),
        amplitudes=[float(a) for a in msg.amplitudes] if family == "custom" else None,
        times=[float(t) for t in msg.times] if family == "custom" else None,
        max_gain=max_gain,
    )


def _or_default(value: float, default: float) -> float:
    """A message parameter: 0 means the family default; anything else (NaN too) is checked later."""
    x = float(value)
    return default if x == 0.0 else x


# ----------------------------------------------------------------------------- stamps and durations
# (any object with ``sec`` and ``nanosec`` is taken, so messages read from a bag by rosbags too)


def duration_to_sec(d: Duration) -> float:
    """A builtin_interfaces/Duration in s."""
    return stamp_to_sec(d)


#: the nanoseconds a builtin_interfaces/Duration or Time holds (int32 seconds)
_NS_RANGE = (-(2**31) * 1_000_000_000, 2**31 * 1_000_000_000)


def sec_to_duration(t: float) -> Duration:
    """``t`` s as a builtin_interfaces/Duration (rounded to the nanosecond); ValueError beyond its
    int32 seconds (never a wrapped time)."""
    ns = int(round(t * 1e9))
    if not _NS_RANGE[0] <= ns < _NS_RANGE[1]:
        raise ValueError(f"{t!r} s is not representable as a builtin_interfaces/Duration (int32 seconds)")
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def time_to_sec(t: Time) -> float:
    """A builtin_interfaces/Time (a header stamp) in s."""
    return stamp_to_sec(t)


def ns_to_time(ns: int) -> Time:
    """``ns`` nanoseconds as a builtin_interfaces/Time."""
    ns = int(ns)
    if not _NS_RANGE[0] <= ns < _NS_RANGE[1]:
        raise ValueError(f"{ns} ns is not representable as a builtin_interfaces/Time (int32 seconds)")
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def sec_to_time(t: float) -> Time:
    """``t`` s as a builtin_interfaces/Time (rounded to the nanosecond)."""
    return ns_to_time(int(round(t * 1e9)))


# ----------------------------------------------------------------------------- trajectories
#: the fields of a JointTrajectoryPoint that are shaped (positions always; the others when given)
TRAJ_FIELDS = FIELDS


#: joint orders already seen, (configured, received) -> the permutation (read-only); see _permutation
_PERMUTATIONS: dict[tuple[tuple[str, ...], tuple[str, ...]], np.ndarray] = {}
#: most entries of _PERMUTATIONS (a stream's joint order seldom changes; the cache starts afresh when full)
_MAX_PERMUTATIONS = 16


def _permutation(configured: Sequence[str], received: Sequence[str]) -> np.ndarray:
    """:func:`joint_permutation`, remembered for the joint orders that passed it (a stream sends the same
    names in every message: comparing them is cheaper than checking them again)."""
    if len(received) > MAX_JOINT_NAMES:
        return joint_permutation(configured, received)  # refused before any work on the names
    key = (tuple(configured), tuple(received))
    perm = _PERMUTATIONS.get(key)
    if perm is None:
        perm = joint_permutation(configured, received)
        perm.flags.writeable = False
        if len(_PERMUTATIONS) >= _MAX_PERMUTATIONS:
            _PERMUTATIONS.clear()
        _PERMUTATIONS[key] = perm
    return perm


def trajectory_arrays(msg: JointTrajectory, joint_names: Sequence[str], require_times: bool,
                      limit: float = math.inf) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A JointTrajectory as arrays in the configured joint order: (times (N,) s, {field: (N, joints)}).

    Joints may come in any order. Every point needs positions; velocities and accelerations are
    taken when every point has them. Times must increase strictly when ``require_times`` or when
    there are several points.

    Raises
    ------
    InputError
        Unknown, missing or duplicate joints, no points, a field on some points only, wrong sizes,
        non-finite values or non-increasing times (the error's ``kind`` names the class).
    """
    if len(msg.points) > MAX_TRAJECTORY_POINTS:  # before any work on them
        raise InputError("too_large", f"{len(msg.points)} points exceed the limit of {MAX_TRAJECTORY_POINTS}")
    perm = _permutation(joint_names, msg.joint_names)
    if not msg.points:
        raise InputError("empty", "trajectory has no points")
    n = len(joint_names)
    times = np.array([duration_to_sec(p.time_from_start) for p in msg.points])
    check_times(times, require_times)
    fields: dict[str, np.ndarray] = {}
    for f in TRAJ_FIELDS:
        present = [len(getattr(p, f)) > 0 for p in msg.points]
        if f == "positions" and not all(present):
            raise InputError("empty", "every point needs positions")
        if any(present) and not all(present):
            raise InputError("inconsistent_fields", f"{f} given for some points but not all")
        if all(present):
            rows = [finite_array(f"point {i} {f}", getattr(p, f), size=n, limit=limit)
                    for i, p in enumerate(msg.points)]
            fields[f] = np.vstack(rows)[:, perm]
    return times, fields


def trajectory_msg(header: Header, joint_names: Sequence[str], times: Sequence[Duration] | np.ndarray,
                   fields: Mapping[str, np.ndarray], pause: Callable[[], None] | None = None,
                   every: int = 100) -> JointTrajectory:
    """A JointTrajectory with one point per row of ``fields`` (arrays (N, joints)); ``times`` are the
    points' time_from_start, as Durations or in s. ``pause``, if given, is called after every ``every``
    points (a background thread building a long trajectory gives the interpreter to the others)."""
    out = JointTrajectory(header=header, joint_names=list(joint_names))
    rows = {f: v.tolist() for f, v in fields.items()}
    for k, t in enumerate(times):
        pt = JointTrajectoryPoint(time_from_start=t if isinstance(t, Duration) else sec_to_duration(float(t)))
        for f, v in rows.items():
            setattr(pt, f, v[k])
        out.points.append(pt)
        if pause is not None and k % every == every - 1:
            pause()
    return out
