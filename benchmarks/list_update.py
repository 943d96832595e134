"""Time of one LIST update (:meth:`shaper_nodes.core.learning.list.learner.ListLearner.update`) against a floor.

Data: one 10 s cycle of a 3-axis accelerometer at 1 kHz: a base-excited 8 Hz, 3 % damped mode
moved 0.5 m by a trapezoid (1 m/s, 4 m/s^2, MOTION_END at 0.75 s), simulated exactly
(``cont2discrete`` with ``foh``), its tip acceleration along a fixed direction, plus gravity on
z and white noise of 0.01 m/s^2 per axis. One unshaped cycle makes the reference (timed once,
as ``make reference``: it includes the mode identification); the timed update is a shaped
cycle with the initial guess 20 % off.

Methods:

``ListLearner.update``
    The full update: validation, completeness checks, projection on the reference's axis,
    resampling, zero-phase high-pass of the window (the cycle and the reference's two
    copies), least squares for rho, and the learning rule. The learner is restored from its
    saved state before every pass (not timed), so every pass does the same work.
``floor: filtfilt + hilbert``
    ``scipy.signal.filtfilt`` (2nd-order Butterworth high-pass, 2 Hz) and
    ``scipy.signal.hilbert`` over the same (10000, 3) array: the least any analytic-signal
    comparison of the cycle must spend, the baseline of the ratio.

Timing: the methods run round-robin ``repeats`` times; each one's best pass is reported, and
the median.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from scipy.signal import butter, cont2discrete, dlsim, filtfilt, hilbert

from shaper_nodes.core.learning.list import ListConfig, ListLearner, ListParams
from shaper_nodes.core.shaping import Mode


def _trapezoid(t: np.ndarray, distance: float, vmax: float, amax: float) -> tuple[np.ndarray, float]:
    """Position (m) of a trapezoidal move at times t (s), and its duration (s)."""
    ta = vmax / amax
    duration = distance / vmax + ta
    s = np.where(t <= ta, 0.5 * amax * t**2, np.where(
        t <= duration - ta, 0.5 * amax * ta**2 + vmax * (t - ta), distance - 0.5 * amax * (duration - t) ** 2))
    return np.where(t <= 0.0, 0.0, np.where(t >= duration, distance, s)), duration


def cycle_data(hz: float = 8.0, zeta: float = 0.03, rate: float = 1000.0, seconds: float = 10.0,
               params: ListParams | None = None, seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(times s, (N, 3) acceleration m/s^2, MOTION_END s) of one cycle shaped by ``params``."""
    w = 2.0 * math.pi * hz
    plant = cont2discrete((np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]]), np.array([[0.0], [w * w]]),
                           np.array([[-w * w, -2.0 * zeta * w]]), np.array([[w * w]])), 1.0 / rate, method="foh")
    t = np.arange(int(round(seconds * rate))) / rate
    move = lambda tt: _trapezoid(tt, 0.5, 1.0, 4.0)[0]  # noqa: E731
    u = move(t) if params is None else sum(a * move(t - ti) for a, ti in zip(*params.impulses(), strict=True))
    y = dlsim(plant, u, t)[1][:, 0]
    axis = np.array([0.6, 0.7, 0.3]) / np.linalg.norm([0.6, 0.7, 0.3])
    rng = np.random.default_rng(seed)
    accel = y[:, None] * axis + np.array([0.0, 0.0, 9.81]) + 0.01 * rng.standard_normal((t.size, 3))
    return t, accel, _trapezoid(np.zeros(1), 0.5, 1.0, 4.0)[1]


def run(*, hz: float = 8.0, zeta: float = 0.03, rate: float = 1000.0, seconds: float = 10.0, repeats: int = 20,
        progress: Callable[[str], None] = lambda s: None) -> dict:
    """Run the benchmark; returns the figures as a dictionary."""
    config = ListConfig()
    learner = ListLearner(config, ListParams.from_mode(Mode.from_hz(1.2 * hz, 1.2 * zeta)))
    t, ref_accel, motion_end = cycle_data(hz, zeta, rate, seconds)
    start = time.perf_counter()
    first = learner.update(t, ref_accel, motion_end, seconds, None)
    reference_s = time.perf_counter() - start
    if first.action != "reference":
        raise RuntimeError(f"benchmark reference cycle rejected: {first.reason}")
    used = learner.params
    _, accel, _ = cycle_data(hz, zeta, rate, seconds, used, seed=1)
    state = learner.to_dict()
    sos_b, sos_a = butter(2, config.highpass_hz, btype="highpass", fs=rate)

    def update() -> None:
        fresh = ListLearner.from_dict(state)
        begin = time.perf_counter()
        fresh.update(t, accel, motion_end, seconds, used)
        timings["ListLearner.update"].append(time.perf_counter() - begin)

    def floor() -> None:
        begin = time.perf_counter()
        hilbert(filtfilt(sos_b, sos_a, accel, axis=0), axis=0)
        timings["floor: filtfilt + hilbert"].append(time.perf_counter() - begin)

    timings: dict[str, list[float]] = {"ListLearner.update": [], "floor: filtfilt + hilbert": []}
    update()  # warm-up (caches, imports)
    floor()
    timings = {k: [] for k in timings}
    for r in range(repeats):
        progress(f"LIST update: pass {r + 1}/{repeats}")
        update()
        floor()
    check = ListLearner.from_dict(state).update(t, accel, motion_end, seconds, used)
    best = {k: min(v) for k, v in timings.items()}
    return {
        "data": {"seconds": seconds, "rate_hz": rate, "axes": 3, "samples": int(t.size), "mode_hz": hz,
                 "damping_ratio": zeta},
        "repeats": repeats, "reference_s": reference_s,
        "update_action": check.action, "update_m": check.m,
        "methods": [{"method": k, "best_s": best[k], "median_s": float(np.median(v)),
                     "ratio_to_floor": best[k] / best["floor: filtfilt + hilbert"]} for k, v in timings.items()],
    }


def print_table(result: dict) -> None:
    """The figures as a table."""
    d = result["data"]
    print(f"LIST update: one {d['seconds']:g} s cycle of {d['axes']}-axis data at {d['rate_hz']:g} Hz"
          f" ({d['samples']} samples, {d['mode_hz']:g} Hz mode), best of {result['repeats']}")
    head = f"  {'method':<30}{'best ms':>9}{'median ms':>11}{'vs floor':>10}"
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in result["methods"]:
        print(f"  {m['method']:<30}{1e3 * m['best_s']:>9.2f}{1e3 * m['median_s']:>11.2f}{m['ratio_to_floor']:>10.2f}")
    print(f"  make reference (identification included, once): {1e3 * result['reference_s']:.1f} ms;"
          f" the timed update: {result['update_action']}, M {result['update_m']:.4g} m/s^2")


if __name__ == "__main__":
    print_table(run())
