"""Synthetic recordings as a robot's own recorder would write them: standard types, no cycle events.

A base-driven flexible joint (natural frequency ``mode_hz``, damping ratio ``zeta``) follows
trapezoidal point-to-point moves back and forth with a dwell between them; the tip acceleration
(sensor_msgs/Imu, x axis, plus white noise and an optional constant offset such as gravity on z),
the joint positions (sensor_msgs/JointState) and optionally the commands
(std_msgs/Float64MultiArray) are written with rosbags' Writer into a rosbag2 folder with MCAP
storage. Used by the tests and the benchmark; messages are serialised once and their stamps and
values patched in (checked against rosbags' deserialiser in the tests), so that a million
messages are written in seconds.
"""

from __future__ import annotations

import math
import pathlib
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

if TYPE_CHECKING:
    from rosbags.rosbag2.storage_mcap import McapWriter


@dataclass(frozen=True)
class Truth:
    """What the synthetic recording holds: mode (Hz, ratio), move starts and ends (s)."""

    mode_hz: float
    zeta: float
    move_starts: tuple[float, ...]
    move_ends: tuple[float, ...]
    duration: float


def trapezoid(t: np.ndarray, distance: float, vmax: float, amax: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a rest-to-rest trapezoidal move starting at t = 0 (units of distance)."""
    d = abs(distance)
    ta = min(vmax / amax, math.sqrt(d / amax))
    v = amax * ta
    tc = max(d / v - ta, 0.0)
    total = 2 * ta + tc
    tt = np.clip(t, 0.0, total)
    pos = np.where(tt < ta, 0.5 * amax * tt**2,
                   np.where(tt < ta + tc, 0.5 * amax * ta**2 + v * (tt - ta),
                            d - 0.5 * amax * (total - tt) ** 2))
    vel = np.where(tt < ta, amax * tt, np.where(tt < ta + tc, v, amax * (total - tt)))
    vel = np.where((t < 0) | (t > total), 0.0, vel)
    s = math.copysign(1.0, distance)
    return s * pos, s * vel


def simulate(cycles: int = 6, rate: float = 500.0, mode_hz: float = 4.0, zeta: float = 0.02,
             distance: float = 0.5, vmax: float = 1.0, amax: float = 8.0, dwell: float = 2.5,
             noise: float = 0.01, offset: tuple[float, float, float] = (0.0, 0.0, 0.0), lead: float = 0.5,
             seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, Truth]:
    """Times (s), commanded positions (N,) and tip acceleration (N, 3) of back-and-forth moves."""
    from scipy.signal import StateSpace, lsim

    w = 2 * math.pi * mode_hz
    move = 2 * min(vmax / amax, math.sqrt(distance / amax)) + max(
        distance / (amax * min(vmax / amax, math.sqrt(distance / amax))) - min(vmax / amax, math.sqrt(distance / amax)),
        0.0)
    period = move + dwell
    duration = lead + cycles * period
    t = np.arange(int(round(duration * rate))) / rate
    u, ud = np.zeros_like(t), np.zeros_like(t)
    starts, ends = [], []
    for k in range(cycles):
        t0 = lead + k * period
        p, v = trapezoid(t - t0, distance if k % 2 == 0 else -distance, vmax, amax)
        u += p
        ud += v
        starts.append(t0)
        ends.append(t0 + move)
    # states x (tip), v (tip velocity); inputs u, u'; output the tip acceleration
    sys = StateSpace([[0.0, 1.0], [-w * w, -2 * zeta * w]], [[0.0, 0.0], [w * w, 2 * zeta * w]],
                     [[-w * w, -2 * zeta * w]], [[w * w, 2 * zeta * w]])
    _, acc, _ = lsim(sys, np.column_stack([u, ud]), t)
    rng = np.random.default_rng(seed)
    a = np.zeros((t.size, 3)) + np.asarray(offset, dtype=float)
    a[:, 0] += acc
    a += rng.normal(0.0, noise, a.shape)
    return t, u, a, Truth(mode_hz, zeta, tuple(starts), tuple(ends), duration)


class _Template:
    """A serialised message with the byte offsets of the fields to patch."""

    def __init__(self, store, msg, msgtype: str, sentinels: dict[str, float]) -> None:
        self.raw = bytes(store.serialize_cdr(msg, msgtype))
        self.offsets = {name: self.raw.index(struct.pack("<d", value)) for name, value in sentinels.items()}


def write_bag(path: str | pathlib.Path, t: np.ndarray, u: np.ndarray, a: np.ndarray, *, t0: float = 1.7e9,
              imu_topic: str = "/imu/data", joints_topic: str = "/joint_states", commands_topic: str | None = None,
              joint_names: tuple[str, ...] = ("joint_1",), imu_every: int = 1, joints_every: int = 1,
              finish: bool = True, joint_noise: float = 0.0, joint_resolution: float = 0.0,
              joint_seed: int = 2, custom_data: Mapping[str, str] | None = None) -> int:
    """Write the samples into a rosbag2 folder (MCAP); returns the number of messages written.

    ``t0`` (s) is added to every time (a robot's wall clock). Every joint of ``joint_names`` gets
    the position ``u``. ``imu_every``/``joints_every`` write every n-th sample only. With
    ``finish`` False the writer is abandoned without closing, as a killed recorder leaves it: the
    chunk it was filling, the summary, the footer and metadata.yaml are never written.
    The joint states are measured positions: ``u`` plus white noise of standard deviation
    ``joint_noise`` (rad or m; independent per joint, seeded by ``joint_seed``), rounded to
    multiples of ``joint_resolution`` (an encoder's step; 0: not rounded). The commands stay ``u``.
    ``custom_data`` goes into metadata.yaml's custom_data (e.g. ``{"robot": "cell_3"}``).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    Imu = store.types["sensor_msgs/msg/Imu"]
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Quat = store.types["geometry_msgs/msg/Quaternion"]
    Vec = store.types["geometry_msgs/msg/Vector3"]
    F64 = store.types["std_msgs/msg/Float64MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    hdr = Header(stamp=Time(sec=0, nanosec=0), frame_id="imu_link")
    imu = _Template(store, Imu(header=hdr, orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
                               orientation_covariance=np.full(9, -1.0), angular_velocity=Vec(x=0.0, y=0.0, z=0.0),
                               angular_velocity_covariance=np.zeros(9),
                               linear_acceleration=Vec(x=1.25e-300, y=2.5e-300, z=5e-300),
                               linear_acceleration_covariance=np.zeros(9)),
                    "sensor_msgs/msg/Imu", {"x": 1.25e-300})
    n = len(joint_names)
    sentinel = [1e-300 * (k + 3) for k in range(n)]
    js = _Template(store, JointState(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), name=list(joint_names),
                                     position=np.array(sentinel), velocity=np.zeros(0), effort=np.zeros(0)),
                   "sensor_msgs/msg/JointState", {"p": sentinel[0]})
    cmd = _Template(store, F64(layout=Layout(dim=[], data_offset=0), data=np.array(sentinel)),
                    "std_msgs/msg/Float64MultiArray", {"p": sentinel[0]})
    measured = np.repeat(np.asarray(u, dtype=float)[:, None], n, axis=1)
    if joint_noise > 0.0:
        measured += np.random.default_rng(joint_seed).normal(0.0, joint_noise, measured.shape)
    if joint_resolution > 0.0:
        measured = np.round(measured / joint_resolution) * joint_resolution
    stamp = struct.Struct("<iI")
    path = pathlib.Path(path)
    count = 0
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    for key, value in (custom_data or {}).items():
        writer.set_custom_data(key, value)
    writer.open()
    try:
        c_imu = writer.add_connection(imu_topic, "sensor_msgs/msg/Imu", typestore=store)
        c_js = writer.add_connection(joints_topic, "sensor_msgs/msg/JointState", typestore=store)
        c_cmd = writer.add_connection(commands_topic, "std_msgs/msg/Float64MultiArray",
                                      typestore=store) if commands_topic else None
        ns = np.round((t + t0) * 1e9).astype(np.int64)
        buf_i, buf_j, buf_c = bytearray(imu.raw), bytearray(js.raw), bytearray(cmd.raw)
        ox, oj, oc = imu.offsets["x"], js.offsets["p"], cmd.offsets["p"]
        pos = struct.Struct(f"<{n}d")
        acc3 = struct.Struct("<3d")
        for i in range(t.size):
            stamp_ns = int(ns[i])
            sec, nsec = divmod(stamp_ns, 1_000_000_000)
            if c_cmd is not None:
                pos.pack_into(buf_c, oc, *([float(u[i])] * n))
                writer.write(c_cmd, stamp_ns, bytes(buf_c))
                count += 1
            if i % joints_every == 0:
                stamp.pack_into(buf_j, 4, sec, nsec)
                pos.pack_into(buf_j, oj, *measured[i])
                writer.write(c_js, stamp_ns, bytes(buf_j))
                count += 1
            if i % imu_every == 0:
                stamp.pack_into(buf_i, 4, sec, nsec)
                acc3.pack_into(buf_i, ox, *a[i])
                writer.write(c_imu, stamp_ns, bytes(buf_i))
                count += 1
    finally:
        if finish:
            writer.close()
        else:  # what the process had handed to the OS is in the file; the rest is lost
            cast("McapWriter", writer.storage).bio.close()  # the storage plugin asked for: MCAP
    return count


def simulate_plants(modes_hz: tuple[float, ...] = (3.5, 5.0, 6.5), cycles: int = 4, zeta: float = 0.02,
                    **kwargs) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[Truth]]:
    """Several plants (or poses) in one recording: :func:`simulate` for each mode in turn, end to end.

    Each plant runs ``cycles`` (even, so the position comes back to where the next one starts)
    back-and-forth moves; the first has :func:`simulate`'s lead, the others none (the last rest of
    one plant is the lead of the next). Returns times (s), commanded positions, tip acceleration
    (N, 3) and one :class:`Truth` per plant, its times on the joint recording's clock.
    """
    if cycles % 2:
        raise ValueError(f"cycles must be even (the moves go back and forth), got {cycles}")
    ts, us, accs, truths = [], [], [], []
    shift = 0.0
    lead = float(kwargs.pop("lead", 0.5))
    for k, hz in enumerate(modes_hz):
        t, u, a, tr = simulate(cycles=cycles, mode_hz=hz, zeta=zeta, lead=lead if k == 0 else 0.0, seed=k + 1,
                               **kwargs)
        ts.append(t + shift)
        us.append(u)
        accs.append(a)
        truths.append(Truth(hz, zeta, tuple(s + shift for s in tr.move_starts), tuple(e + shift for e in tr.move_ends),
                            tr.duration))
        shift += tr.duration
    return np.concatenate(ts), np.concatenate(us), np.concatenate(accs), truths


@dataclass(frozen=True)
class SegmentationCheck:
    """How a recording with noisy joint states is analysed: noise (rad), quantisation step (rad), moves
    found and true, the largest error of the move starts and ends (s), the identified mode (Hz) and the
    true one, and the recommended family."""

    noise: float
    resolution: float
    moves_found: int
    moves_true: int
    start_error: float
    end_error: float
    mode_hz: float
    true_hz: float
    recommended: str

    @property
    def mode_error(self) -> float:
        """Relative error of the identified mode (fraction)."""
        return abs(self.mode_hz / self.true_hz - 1.0)


def check_segmentation(folder: str | pathlib.Path, noise: float, resolution: float = 0.0, cycles: int = 6,
                       mode_hz: float = 4.0, zeta: float = 0.02) -> SegmentationCheck:
    """Write a robot-style recording (joint states with ``noise`` rad and ``resolution`` rad steps, IMU
    with gravity, no commands, no cycle events) into ``folder`` and analyse it (for the tests and the
    table of docs/guide/analysis.md)."""
    from .analyze import Options, analyze
    from .streams import read_recording

    t, u, a, truth = simulate(cycles=cycles, mode_hz=mode_hz, zeta=zeta, offset=(0.0, 0.0, 9.81))
    t0 = 1.7e9
    path = pathlib.Path(folder) / f"noise_{noise:g}_res_{resolution:g}"
    write_bag(path, t, u, a, t0=t0, joint_names=("shoulder", "elbow"), joint_noise=noise, joint_resolution=resolution)
    an = analyze(read_recording(path), Options(learners=()))
    found = len(an.cycles)
    if found == len(truth.move_starts):
        se = max(abs(r.start - t0 - s) for r, s in zip(an.cycles, truth.move_starts, strict=True))
        ee = max(abs(r.motion_end - t0 - e) for r, e in zip(an.cycles, truth.move_ends, strict=True))
    else:
        se = ee = float("inf")
    best = an.recommendation.best if an.recommendation is not None else None
    return SegmentationCheck(noise, resolution, found, len(truth.move_starts), se, ee,
                             an.modes[0].hz if an.modes else float("nan"), mode_hz,
                             best.family if best is not None else "none")


@dataclass(frozen=True)
class FleetTruth:
    """A synthetic fleet: per robot its true mode (Hz, ratio), whether it drifts, from which recording."""

    modes_hz: dict[str, float]
    zetas: dict[str, float]
    drift_from: dict[str, int]  # robot -> index of its first drifted recording (only drifting robots)
    shift: float
    paths: dict[str, list[pathlib.Path]]


def write_fleet(folder: str | pathlib.Path, robots: int = 10, recordings: int = 20,
                drifting: Sequence[int] = (3, 7), shift: float = 0.10, drift_at: float = 0.5, cycles: int = 3,
                rate: float = 250.0, dwell: float = 1.5, noise: float = 0.02, spread: float = 0.005,
                seed: int = 0) -> FleetTruth:
    """Write a fleet's recordings: ``robots`` x ``recordings`` short robot-style recordings.

    Robot k (named ``robot_KK``, the name also in each recording's metadata custom_data) has a mode
    of 3 + 0.35 k Hz with damping ratio 0.02-0.04; every recording (``<folder>/robot_KK/rec_NNN``,
    one a day) varies it by white noise of relative standard deviation ``spread`` (a real robot's
    day-to-day spread) on top of the accelerometer noise ``noise`` m/s^2. The robots of ``drifting``
    have their mode moved by ``shift`` (fraction) from recording ``drift_at`` x ``recordings`` on
    (a payload change or wear). Each recording: ``cycles`` back-and-forth moves at ``rate`` Hz with
    ``dwell`` s between them, joint states with encoder noise, IMU with gravity.
    """
    rng = np.random.default_rng(seed)
    root = pathlib.Path(folder)
    modes: dict[str, float] = {}
    zetas: dict[str, float] = {}
    drift_from: dict[str, int] = {}
    paths: dict[str, list[pathlib.Path]] = {}
    first_drifted = int(round(drift_at * recordings))
    for k in range(robots):
        name = f"robot_{k:02d}"
        modes[name] = 3.0 + 0.35 * k
        zetas[name] = 0.02 + 0.02 * (k % 3) / 2
        if k in drifting:
            drift_from[name] = first_drifted
        paths[name] = []
        for n in range(recordings):
            hz = modes[name] * (1.0 + spread * rng.standard_normal())
            if k in drifting and n >= first_drifted:
                hz *= 1.0 + shift
            t, u, a, _ = simulate(cycles=cycles, rate=rate, mode_hz=hz, zeta=zetas[name], dwell=dwell, noise=noise,
                                  offset=(0.0, 0.0, 9.81), seed=int(rng.integers(1 << 31)))
            path = root / name / f"rec_{n:03d}"
            write_bag(path, t, u, a, t0=1.7e9 + 86400.0 * n + 600.0 * k, joint_names=("joint_1",),
                      joint_noise=1e-5, joint_seed=int(rng.integers(1 << 31)), custom_data={"robot": name})
            paths[name].append(path)
    return FleetTruth(modes, zetas, drift_from, shift, paths)
