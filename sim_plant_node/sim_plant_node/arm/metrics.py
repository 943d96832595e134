"""Per-move measures of the arm demo, free of ROS.

For one move, from what the demo records (flange IMU, link angles through forward
kinematics, the commanded joint positions):

- residual vibration: RMS and peak of the specific force's deviation from its mean (gravity
  and the sensor's bias removed) over a fixed window after the commanded motion ends, m/s^2
  (:func:`shaper_nodes.core.shaping.vibration.residual_vibration`);
- peak tool displacement in that window: the largest distance of the flange from where it
  comes to rest, mm;
- settling time: from the planned (unshaped) end of the move until the flange stays within
  :data:`SETTLE_TOLERANCE` of where it comes to rest, s;
- the shaper's delay: how much later the commanded motion ends than the planned one, s;
- path deviation: the largest distance of the commanded tool path (forward kinematics of the
  commanded joint positions) from the unshaped one, mm.

The windows select samples by their stamps with one rule, :func:`in_window`: a stamp within
:data:`STAMP_TOLERANCE` of an edge is on it. The residual window is [commanded end, + RESIDUAL_WINDOW): the
sample at the commanded end in, the one at the window's end out, whichever side of the edge rounding put it.
The offline arm's stamps are sums period by period and land a few 1e-15 s either side of the commanded end
(itself a command's stamp), so the bare ``t >= commanded_end`` took that sample on some moves and not on others;
the sim plant node and the DDS stamps (integer ns) count by samples, which this rule gives too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from shaper_nodes.core.shaping.vibration import ResidualVibration, residual_vibration, settle_time

#: the settling band of the flange, m: 0.05 mm, a little over the UR5e's specified pose
#: repeatability (+-0.03 mm, ISO 9283), so that a settled tool is as still as the arm can place it
SETTLE_TOLERANCE = 0.05e-3
#: length of the residual-vibration window after the commanded motion's end, s
RESIDUAL_WINDOW = 1.0
#: the position loop's transient after the commanded motion's end, s: the joints' servo (50 Hz, damping
#: 0.7) settles its tracking lag in a few of its periods; :func:`late_residual` starts after it
SERVO_TRANSIENT = 0.1
#: s: a stamp this close to a window's edge is on it (:func:`in_window`). A quarter of a nanosecond: integer-ns
#: stamps (DDS) select exactly as by their integers; far above the offline arm's rounding (its stamps are sums of
#: periods: a few ulps apart from the commanded end's, drifting at most ~500 ulps of t, < 2.5e-10 s below
#: t = 4096 s, across one window) and 4e6 times below the IMU's 1 ms between samples
STAMP_TOLERANCE = 2.5e-10


def in_window(times: np.ndarray, start: float, end: float, closed: str = "left") -> np.ndarray:
    """Which ``times`` (s) lie in [start, end) (``closed="left"``), (start, end] (``"right"``) or [start, end]
    (``"both"``), a stamp within :data:`STAMP_TOLERANCE` of an edge counted on it (module docstring)."""
    t = np.asarray(times, dtype=float)
    lo = t >= start - STAMP_TOLERANCE if closed in ("left", "both") else t > start + STAMP_TOLERANCE
    hi = t <= end + STAMP_TOLERANCE if closed in ("right", "both") else t < end - STAMP_TOLERANCE
    return lo & hi


def window_residual(times: np.ndarray, imu: np.ndarray, start: float, end: float) -> ResidualVibration:
    """RMS and peak of the IMU's deviation from its mean over [start, end) (:func:`in_window`'s rule), m/s^2."""
    t = np.asarray(times, dtype=float)
    sel = in_window(t, start, end)
    return residual_vibration(t[sel], np.asarray(imu, dtype=float)[sel], -math.inf, math.inf, remove_mean=True)


@dataclass(frozen=True)
class MoveMeasures:
    """One move's measures (units in the names)."""

    move: str
    residual_rms: float
    residual_peak: float
    peak_mm: float
    settling_s: float
    move_s: float
    delay_s: float
    path_deviation_mm: float

    @property
    def move_and_settle_s(self) -> float:
        return self.move_s + self.settling_s


def motion_end(times: np.ndarray, commanded: np.ndarray, tolerance: float = 1e-9) -> float:
    """The time the commanded positions stop changing (last change larger than ``tolerance``)."""
    c = np.asarray(commanded, dtype=float)
    moving = np.flatnonzero(np.any(np.abs(np.diff(c, axis=0)) > tolerance, axis=1))
    return float(times[moving[-1] + 1]) if moving.size else float(times[0])


def path_deviation(path: np.ndarray, reference: np.ndarray) -> float:
    """Largest distance of the points of ``path`` (N, 3) from the polyline ``reference`` (M, 3), same units."""
    p = np.asarray(path, dtype=float)
    a = np.asarray(reference, dtype=float)
    if a.shape[0] == 1:
        return float(np.max(np.linalg.norm(p - a[0], axis=1)))
    seg_a, seg_b = a[:-1], a[1:]
    d = seg_b - seg_a
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-300)
    worst = 0.0
    for chunk in np.array_split(p, max(1, p.shape[0] // 256)):
        rel = chunk[:, None, :] - seg_a[None, :, :]
        u = np.clip(np.sum(rel * d[None], axis=2) / length2[None], 0.0, 1.0)
        dist = np.linalg.norm(rel - u[..., None] * d[None], axis=2)
        worst = max(worst, float(np.max(np.min(dist, axis=1))))
    return worst


def measure_move(move: str, planned_start: float, planned_duration: float, commanded_end: float, window_end: float,
                 imu_times: np.ndarray, imu: np.ndarray, tool_times: np.ndarray, tool: np.ndarray,
                 path: np.ndarray | None = None, reference_path: np.ndarray | None = None) -> MoveMeasures:
    """The measures of one move (module docstring); times in s, tool positions in m, imu (N, 3) m/s^2."""
    res = window_residual(imu_times, imu, commanded_end, commanded_end + RESIDUAL_WINDOW)
    planned_end = planned_start + planned_duration
    sel = in_window(tool_times, planned_end, window_end, "both")
    t, p = tool_times[sel], tool[sel]
    dist = np.linalg.norm(p - p[-1], axis=1) if p.shape[0] else np.zeros(0)
    residual = in_window(t, commanded_end, commanded_end + RESIDUAL_WINDOW)
    peak = float(np.max(dist[residual])) if np.any(residual) else float("nan")
    settled = settle_time(t, dist[:, None], planned_end, SETTLE_TOLERANCE) if t.size else planned_end
    deviation = (path_deviation(path, reference_path) if path is not None and reference_path is not None
                 else float("nan"))
    return MoveMeasures(move, res.rms, res.peak, 1e3 * peak, settled - planned_end, planned_duration,
                        commanded_end - planned_end, 1e3 * deviation)


def late_residual(imu_times: np.ndarray, imu: np.ndarray, commanded_end: float) -> float:
    """RMS of the IMU's deviation from its mean over the residual window without its first
    :data:`SERVO_TRANSIENT` s, m/s^2: the modes' ringing, without the position loop's transient
    (which no input shaper removes: it follows the end of any commanded motion)."""
    return window_residual(imu_times, imu, commanded_end + SERVO_TRANSIENT, commanded_end + RESIDUAL_WINDOW).rms


class NoiseFloor(NamedTuple):
    """The noise floor of an accelerometer's residual RMS and the one rule's threshold above it, m/s^2
    (:func:`noise_floor`)."""

    floor: float  #: F = sqrt(3) x the noise: the RMS of the norm of three axes of white noise
    scatter: float  #: s = F / sqrt(6 N): the scatter of that RMS over one window of N samples per axis
    threshold: float  #: F + 2 s: a residual measured above it is above the floor


def noise_floor(noise: float, imu_rate: float = 1000.0) -> NoiseFloor:
    """The one rule (docs/guide/learning.md, "Above the noise floor: one rule") for an accelerometer with white
    noise ``noise`` m/s^2 per axis: the floor F = sqrt(3) x ``noise``, plus twice one window's scatter of it,
    s = F / sqrt(6 N) (N = RESIDUAL_WINDOW x ``imu_rate`` samples per axis); all 0 with no noise. The one copy
    of the formula: the demo's report, the DDS client and the reproductions call it."""
    floor = math.sqrt(3.0) * noise
    scatter = floor / math.sqrt(6.0 * RESIDUAL_WINDOW * imu_rate)
    return NoiseFloor(floor, scatter, floor + 2.0 * scatter)


def inverse_dynamics_peaks(model, times: np.ndarray, positions: np.ndarray, every: int = 5) -> np.ndarray:
    """Largest |torque| per joint, N m, the rigid arm needs to follow a commanded joint trajectory:
    M(q) q'' + C(q, q') q' + g(q), with q' and q'' by finite differences of the commanded positions
    (``model``: an :class:`~sim_plant_node.arm.dynamics.ArmModel`; every ``every``-th sample)."""
    t = np.asarray(times, dtype=float)
    q = np.asarray(positions, dtype=float)
    if t.size < 3:
        return np.abs(np.array([model.gravity(x) for x in q])).max(axis=0) if t.size else np.zeros(model.n)
    qd = np.gradient(q, t, axis=0)
    qdd = np.gradient(qd, t, axis=0)
    peaks = np.zeros(q.shape[1])
    for i in range(0, t.size, max(1, int(every))):
        m = np.triu(model.mass(q[i]))
        tau = (m + np.triu(m, 1).T) @ qdd[i] + model.nonlinear(q[i], qd[i])
        peaks = np.maximum(peaks, np.abs(tau))
    return peaks
