"""The residual-vibration record of a finished cycle, checked before it is identified from (free of ROS).

:func:`check_record` takes the accelerometer samples of a cycle's residual window
(:class:`~shaper_nodes.core.cycles.CycleResult`) and refuses what cannot be identified from: too few samples, a gap,
non-finite or disordered stamps (:class:`~shaper_nodes.core.identification.IdentificationError`), a silent, stuck
or non-finite sensor (:class:`SensorFault`) and a saturated one (:class:`SaturatedRecord`). The identifier node
(nodes/identifier.py) buffers the records it passes.
"""

from __future__ import annotations

import numpy as np

from shaper_nodes.core.cycles import CycleResult
from shaper_nodes.core.identification import IdentificationError
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL, out_of_range, sensor_fault

__all__ = ["MAX_GAP_PERIODS", "SaturatedRecord", "SensorFault", "check_record"]

#: a gap between two accelerometer samples longer than this many median periods marks the
#: cycle's data as incomplete
MAX_GAP_PERIODS = 5.0


class SensorFault(IdentificationError):
    """A cycle whose accelerometer data cannot come from a working sensor (silent, stuck, non-finite)."""


class SaturatedRecord(SensorFault):
    """A cycle with accelerometer samples at or beyond the sensor's range; ``count`` of them."""

    def __init__(self, message: str, count: int) -> None:
        super().__init__(message)
        self.count = count


def check_record(result: CycleResult, min_samples: int, max_abs_accel: float = MAX_ABS_ACCEL
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The residual-vibration record of a finished cycle: (times (N,), accel (N, k)).

    Raises
    ------
    IdentificationError
        Too few samples in the window, or a gap in the samples; :class:`SensorFault` when the cycle's
        samples cannot come from a working sensor (none, non-finite, or every axis one value through
        the cycle: :func:`~shaper_nodes.core.learning.samples.sensor_fault`), and its subclass
        :class:`SaturatedRecord` if any sample of the cycle is at or beyond ``max_abs_accel`` (m/s^2,
        the sensor's range).
    """
    t, a = result.accel_times, result.accel
    fault = sensor_fault(a)  # over the whole cycle, motion included
    if fault is not None:
        raise SensorFault(f"cycle {result.cycle}: sensor fault: {fault}")
    sel = (t >= result.residual.window_start) & (t < result.residual.window_end)
    t, a = t[sel], a[sel]
    if t.size < min_samples:
        raise IdentificationError(
            f"cycle {result.cycle}: {t.size} accelerometer samples in the residual window"
            f" [{result.residual.window_start:.3f}, {result.residual.window_end:.3f}) s, need {min_samples}")
    if not np.all(np.isfinite(a)):
        raise IdentificationError(f"cycle {result.cycle}: non-finite accelerometer samples")
    saturated = out_of_range(result.accel, max_abs_accel)
    if saturated is not None:
        raise SaturatedRecord(f"cycle {result.cycle}: saturated accelerometer: "
                              + saturated.describe("accelerometer", "m/s^2", "sensor.max_abs_accel"), saturated.count)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        raise IdentificationError(f"cycle {result.cycle}: accelerometer stamps not strictly increasing")
    gap, period = float(dt.max()), float(np.median(dt))
    if gap > MAX_GAP_PERIODS * period:
        raise IdentificationError(
            f"cycle {result.cycle}: a {gap * 1e3:.1f} ms gap in the accelerometer data"
            f" (median period {period * 1e3:.2f} ms): data incomplete or stale")
    return t, a
