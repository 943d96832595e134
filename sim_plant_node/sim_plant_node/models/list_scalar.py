"""ListPlant's period for one joint in Python floats: the same arithmetic as the array code, bit for bit.

:meth:`.plants.ListPlant.step` integrates all joints at once with NumPy arrays; with one joint (every LIST
case of seed 003) each of its 17 or more right-hand side evaluations a period is a dozen NumPy calls on
arrays of one element, a few us each, so the plant's period cost some hundred us. This module does the
same period with Python floats: the same operations in the same order (IEEE-754 doubles either way: +, -,
*, / and the comparisons round alike), the force limit with the comparisons NumPy's ``clip`` makes, and the
hardening spring's cube through NumPy's own ``power`` loop (a libm or SIMD ``pow``, not ``e * e * e``), so
the states equal the array code's to the last bit (``sim_plant_node/test/test_list_plants.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["OneJoint", "rk4_step"]


def _clip(f: float, low: float, high: float) -> float:
    """``np.clip`` of a float64, as its loop compares: max(f, low) then min(., high), NaN kept."""
    if f != f:
        return f
    f = f if f > low else low
    return f if f < high else high


def _sign(d: float) -> float:
    """``np.sign`` of a float64 (NaN for NaN)."""
    return 1.0 if d > 0 else -1.0 if d < 0 else 0.0 if d == 0 else math.nan


def rk4_step(f: Callable[..., Any], x: Any, v: Any, u0: Any, r: Any, s: float, h: float,
             cycle_time: float | None) -> tuple[Any, Any]:
    """One classical Runge-Kutta step of length h from s (s into the period) of x'' = f(x, v, u, t), the setpoint u
    ramping from u0 at rate r: on floats (:class:`OneJoint`) or arrays (:class:`.plants.ListPlant`) alike, the same
    operations in the same order, so the two give the same numbers bit for bit."""
    t0 = None if cycle_time is None else cycle_time + s
    tm = None if cycle_time is None else cycle_time + s + 0.5 * h
    t1 = None if cycle_time is None else cycle_time + s + h
    ua, um, ub = u0 + r * s, u0 + r * (s + 0.5 * h), u0 + r * (s + h)
    a1 = f(x, v, ua, t0)
    v2 = v + 0.5 * h * a1
    a2 = f(x + 0.5 * h * v, v2, um, tm)
    v3 = v + 0.5 * h * a2
    a3 = f(x + 0.5 * h * v2, v3, um, tm)
    v4 = v + h * a3
    a4 = f(x + h * v3, v4, ub, t1)
    return (x + (h / 6.0) * (v + 2.0 * v2 + 2.0 * v3 + v4),
            v + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4))


class OneJoint:
    """The period of a one-joint :class:`~.plants.ListPlant` (``plant``'s parameters read once: they do not
    change after it is made)."""

    def __init__(self, plant: Any, ramp_time: float, refine: int) -> None:
        self.plant = plant
        self.model = plant.model
        self.m, self.c, self.k = float(plant.m[0]), float(plant.c[0]), float(plant.k[0])
        self.k3, self.kp, self.f_max = float(plant.k3[0]), float(plant.kp[0]), float(plant.f_max[0])
        self.ramp_time = ramp_time
        self.refine = refine
        self._cube = np.zeros(1)  # the hardening spring's e^3, through NumPy's power loop as the array code

    def mass_at(self, tau: float | None) -> float:
        if self.model != "time_varying":
            return self.m
        if tau is None:
            return 2.0 * self.m
        return self.m * (1.0 + min(max(tau, 0.0), self.ramp_time) / self.ramp_time)

    def force(self, x: float, u: float) -> float:
        if self.model == "saturation":
            return _clip(self.kp * (u - x), -self.f_max, self.f_max)
        e = u - x
        if self.model == "hardening":
            cube = self._cube
            cube[0] = e
            np.power(cube, 3, out=cube)
            return self.k * e + self.k3 * float(cube[0])
        return self.k * e

    def accel(self, x: float, v: float, u: float, tau: float | None) -> float:
        return (self.force(x, u) - self.c * v) / self.mass_at(tau)

    def rk4(self, x: float, v: float, u0: float, r: float, s: float, h: float,
            cycle_time: float | None) -> tuple[float, float]:
        """:meth:`.plants.ListPlant._rk4` in floats (the same :func:`rk4_step`)."""
        return rk4_step(self.accel, x, v, u0, r, s, h, cycle_time)

    def _side(self, x: float, u: float) -> float:
        f = self.kp * (u - x)
        return _sign(f - _clip(f, -self.f_max, self.f_max))

    def corner(self, x0: float, x1: float, u0: float, u1: float, cycle_time: float | None, s: float,
               h: float) -> bool:
        """:meth:`.plants.ListPlant._corner` in floats."""
        if self.model == "saturation":
            a, b = self._side(x0, u0), self._side(x1, u1)
            return a != b
        if self.model == "time_varying" and cycle_time is not None:
            return cycle_time + s < self.ramp_time < cycle_time + s + h
        return False

    def step(self, command, cycle_time: float | None) -> None:
        """:meth:`.plants.ListPlant.step` for one joint (its state and ``cycle_time`` written as it writes them)."""
        p = self.plant
        u1 = float(np.asarray(command, dtype=float).reshape(1)[0])
        state = p.state
        u0, x, v = float(state[0, 2]), float(state[0, 0]), float(state[0, 1])
        dt = p.dt
        r = (u1 - u0) / dt
        h = dt / p.substeps
        for i in range(p.substeps):
            s = i * h
            xn, vn = self.rk4(x, v, u0, r, s, h, cycle_time)
            if self.corner(x, xn, u0 + r * s, u0 + r * (s + h), cycle_time, s, h):
                hh = h / self.refine
                for j in range(self.refine):
                    x, v = self.rk4(x, v, u0, r, s + j * hh, hh, cycle_time)
            else:
                x, v = xn, vn
        p.state = np.array([[x, v, u1, r]])
        p.cycle_time = None if cycle_time is None else float(cycle_time) + dt
