"""Each move's residual split, from the simulated arm's own state: what the sim plant node reports per move.

:class:`ResidualWatch` looks at the setpoint the arm holds every period. A period whose setpoint differs from the
last one's (by more than 1e-9 rad on a joint, :func:`~.metrics.motion_end`'s rule) may be where the commanded motion
ends: the arm's state before it is kept (the state at the commanded end). Once :data:`~.metrics.RESIDUAL_WINDOW` s
have passed with the setpoint unchanged, the move's split comes out: its servo and vibration parts
(:func:`~.residual_parts.parts_of`, the arm linearised about the held setpoint, cached per setpoint and payload)
and the arm's own residual over the same window (the noise-free specific force of the arm's IMU, mean removed), on
the IMU's samples in [commanded end, commanded end + window): the sample at the commanded end (the last of the period
before) in, the one at the window's end out, as :func:`shaper_nodes.core.shaping.vibration.residual_vibration` has
a window, counted by sample rather than by float stamps (the offline arm's stamps, summed period by period, land a
rounding error either side of the commanded end, so :func:`~.residual_parts.residual_parts` on them has that first
sample on some moves and not on others).

A move whose setpoint changes again, whose payload changes or whose arm is reset within the window gives no split;
nor does a goal that holds its end less than the window (the next goal's motion comes first). The work is bounded:
one linearisation per new setpoint (kept, up to :data:`CACHE_SIZE` setpoints), then one solve and the window's
exponentials per move; its wall time is in the split (``seconds``).

It is the simulator's truth: a real robot has no such report (its state is not measured).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .metrics import RESIDUAL_WINDOW
from .residual_parts import LinearArm, Parts, linear_cached, parts_of

__all__ = ["CACHE_SIZE", "CHANGE_TOLERANCE", "ResidualWatch", "Split"]

#: linearisations kept (setpoint and payload); the oldest goes first
CACHE_SIZE = 64
#: rad: a setpoint that differs from the last by more on a joint is a commanded motion (metrics.motion_end's rule)
CHANGE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Split:
    """One move's residual split.

    Attributes
    ----------
    window_start, window_end : float
        The residual window: the commanded motion's end and RESIDUAL_WINDOW s later, s of the node's time.
    goal : ndarray
        The setpoint held, rad.
    parts : Parts
        The servo part, the vibration part and the two together (RMS, mean removed, m/s^2).
    own_rms, own_peak : float
        The arm's own residual over the same samples (the IMU's noise-free specific force), RMS and peak, m/s^2.
    seconds : float
        Wall time the split took (the linearisation too, for a new setpoint), s.
    """

    window_start: float
    window_end: float
    goal: np.ndarray
    parts: Parts
    own_rms: float
    own_peak: float
    seconds: float


class ResidualWatch:
    """Watches an :class:`~.plant.ArmPlant` period by period (module docstring).

    Call :meth:`before` with the setpoint just before the plant steps a period, :meth:`after` just after. Per period
    it compares six floats and keeps a reference to the period's IMU samples; a period of a motion also copies the
    arm's state (the commanded end may be there); the split's work comes once per move.
    """

    def __init__(self, plant: Any, window: float = RESIDUAL_WINDOW) -> None:
        self.plant = plant
        self.window = float(window)
        self._periods = int(round(self.window * plant.rate))
        self._dt = 1.0 / (plant.rate * plant.substeps)  # between IMU samples, s
        self._samples = int(round(self.window * plant.rate * plant.substeps))  # IMU samples in the window
        self._last: list[float] | None = None
        self._last_force: np.ndarray | None = None  # the IMU's last sample, m/s^2 (noise-free)
        #: the commanded end, if one is pending: (t_start s, held setpoint, the arm's state, the IMU's sample there,
        #: the model's spec (its payload) and the physics time)
        self._mark: tuple[float, list[float], np.ndarray, np.ndarray, Any, float] | None = None
        self._window: list[list[Any]] = []  # each period's IMU samples since the mark
        self._cache: dict[Any, LinearArm] = {}

    def before(self, t_start: float, command: np.ndarray) -> None:
        """The period that starts at ``t_start`` (s) holds ``command`` (rad)."""
        # (compared as Python floats: cheaper than numpy's reductions on six numbers)
        c = command.tolist()
        last, self._last = self._last, c
        if last is None or self._last_force is None or c == last or max(
                abs(a - b) for a, b in zip(c, last, strict=True)) <= CHANGE_TOLERANCE:
            return
        plant = self.plant
        self._mark = (t_start, c, plant.state, self._last_force, plant.model.spec, plant.arm.time)
        self._window = []

    def after(self) -> Split | None:
        """The period was stepped: its IMU samples; the move's split once its window has passed (else None)."""
        samples = self.plant.imu_samples
        self._last_force = samples[-1][1]
        if self._mark is None:
            return None
        self._window.append(samples)
        if len(self._window) < self._periods:
            return None
        mark, window = self._mark, self._window
        self._mark, self._window = None, []
        physics = [t for period in window for t, _, _ in period]
        spec = self.plant.model.spec
        if physics[0] <= mark[5] or any(b <= a for a, b in itertools.pairwise(physics)):
            return None  # the arm was reset within the window: its state is not the window's
        if (spec.payload_mass, spec.payload_offset) != (mark[4].payload_mass, mark[4].payload_offset):
            return None  # the payload changed within the window
        return self._split(mark, [mark[3], *(f for period in window for _, f, _ in period)])

    def _split(self, mark: tuple, forces_list: list[np.ndarray]) -> Split:
        from shaper_nodes.core.shaping.vibration import residual_vibration

        t0 = time.perf_counter()
        t_start, held, state = mark[0], np.array(mark[1]), mark[2]
        payload = (mark[4].payload_mass, mark[4].payload_offset)
        forces = np.asarray(forces_list[:self._samples])
        times = np.arange(len(forces)) * self._dt  # from the commanded end
        if len(self._cache) >= CACHE_SIZE and (held.tobytes(), payload) not in self._cache:
            del self._cache[next(iter(self._cache))]
        parts = parts_of(linear_cached(self.plant.model, held, self._cache), state, times)
        own = residual_vibration(times, forces, -math.inf, math.inf, remove_mean=True)
        return Split(t_start, t_start + self.window, held, parts, own.rms, own.peak, time.perf_counter() - t0)
