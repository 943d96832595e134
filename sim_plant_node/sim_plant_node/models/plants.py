"""Simulated plants and tasks, free of ROS.

MckPlant
    Flexible joints, one m-c-k system per joint (seeds 000 and 002): the joint (base) position
    x1 is commanded, the tip x2 follows through a spring k and damper c with mass m,
        m x2'' = k (x1 - x2) + c (x1' - x2'),   x2 / x1 = (c s + k) / (m s^2 + c s + k).
    Between samples the base moves linearly from the previous command to the new one (a
    first-order hold, as an interpolating position controller does), and the plant is
    integrated exactly over each period with the matrix exponential of the system augmented
    with the base position and its (constant) slope. The tip acceleration is x2''.
ListPlant
    The four plants of the simulations of the Learning Input Shaping Technique (seed 003,
    "Simulations"), per joint, u the (shaped) command and x the tip, which carries the
    accelerometer (it measures x''):
        linear        m x'' + b x' + k (x - u) = 0                   (case 1, damper to ground)
        time_varying  m(t) x'' + b x' + k (x - u) = 0,               (case 2)
                      m(t) = m (1 + t) for t < 1 s, 2 m for t >= 1 s, t the time since the
                      current cycle's START (2 m when no cycle has started)
        hardening     m x'' + b x' + k (x - u) + k3 (x - u)^3 = 0    (case 3, k3 >= 0)
        saturation    m x'' + b x' = sat(Kp (u - x), f_max)          (case 4, P loop with an
                      actuator force limit: sat(f, f_max) = min(max(f, -f_max), f_max))
    The paper's values are m = 1 kg, b = 1 N s/m, k = Kp = 100 N/m: omega_n = 10 rad/s, zeta =
    0.05. The command moves linearly between samples (first-order hold, as for MckPlant) and
    the state is integrated with fixed-step classical Runge-Kutta (RK4), several substeps per
    period, all joints at once; a substep across a corner of the right-hand side (the force
    limit engaging or releasing, the end of the mass ramp) is redone in finer pieces.
    ``natural_frequency`` and ``damping_ratio`` are those of the linearised nominal system:
    x = u for the spring, m(0) = m for the time-varying mass, no force limit. The "base" of
    every model, case 4 included, is the command u and its slope (what /joint_states carries:
    the suite starts the residual-vibration window when those have settled; x is the tip).
    The defaults of k3 and f_max (:data:`LIST_STIFFNESS_CUBIC`, :data:`LIST_FORCE_LIMIT`) are
    chosen for the paper's plant and the example task of config/list_case*.yaml (1 m moves at
    1 m/s and 2 m/s^2, 1.5 s each): the cubic force equals the linear one at the quasi-static
    deflection of the acceleration phase, m a / k = 0.02 m, so k3 = k^3 / (m a)^2 =
    2.5e5 N/m^3 (unshaped, the peak deflection is 0.027 m, where the cubic force is 1.8 times
    the linear one); and f_max = 2.5 N is below the m a + b v = 3 N that following the
    reference needs at the end of each acceleration phase, so the limit clips the force during
    64 % of the acceleration phase unshaped and 19 % with a ZV shaper for 10 rad/s. See
    docs/list_plants.md.
make_plant
    Builds any of them from a model name ("mck", "list_linear", ...) and per-joint parameters.
CycleTask
    A repeated point-to-point task with a trapezoidal velocity profile, alternating between
    two poses, with a dwell after every move for the residual vibration to show: in
    :mod:`.cycle_task`, handed on here with its checks and profiles.
"""

from __future__ import annotations

import math

import numpy as np

from .base import PlantBase
from .cycle_task import PROFILES, CycleTask, TaskEvent, check_task, trapezoid, trapezoid_fraction
from .list_scalar import OneJoint, rk4_step

__all__ = ["LIST_FORCE_LIMIT", "LIST_GAIN", "LIST_MODELS", "LIST_STIFFNESS_CUBIC", "MASS_RAMP_TIME", "PLANT_MODELS",
           "PLANT_VALUES", "PROFILES", "CycleTask", "ListPlant", "MckMode", "MckPlant", "TaskEvent", "check_rate",
           "check_task", "make_plant", "mck_from_mode", "plant_values", "trapezoid", "trapezoid_fraction"]


def check_rate(rate: float) -> float:
    """The plants' check of the command (integration) rate: finite and > 0 Hz; returns it as a float."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
    return float(rate)


def mck_from_mode(omega: float, zeta: float, mass: float = 1.0) -> tuple[float, float, float]:
    """Mass (kg), damping (N s/m) and stiffness (N/m) of an m-c-k system with this mode."""
    k = mass * omega**2
    return mass, 2.0 * zeta * math.sqrt(k * mass), k


class _JointState:
    """The state layout both plants share, per joint: tip x, x', base (command) u, its slope."""

    state: np.ndarray

    @property
    def base_position(self) -> np.ndarray:
        """The base position / command u at the end of the last period (/joint_states), m or rad."""
        return self.state[:, 2].copy()

    @property
    def base_velocity(self) -> np.ndarray:
        """Slope of the base / command over the last period."""
        return self.state[:, 3].copy()

    @property
    def tip_position(self) -> np.ndarray:
        """Tip position x."""
        return self.state[:, 0].copy()

    @property
    def tip_velocity(self) -> np.ndarray:
        """Tip velocity x'."""
        return self.state[:, 1].copy()


class MckMode:
    """The mode of per-joint m-c-k parameters ``m``, ``c``, ``k`` (arrays)."""

    m: np.ndarray
    c: np.ndarray
    k: np.ndarray

    @property
    def natural_frequency(self) -> np.ndarray:
        """Undamped natural frequency of each joint's mode, rad/s."""
        return np.sqrt(self.k / self.m)

    @property
    def damping_ratio(self) -> np.ndarray:
        """Damping ratio of each joint's mode."""
        return self.c / (2.0 * np.sqrt(self.k * self.m))


class MckPlant(_JointState, MckMode, PlantBase):
    """Per-joint m-c-k flexible joints integrated exactly under a first-order-hold base motion.

    Parameters
    ----------
    mass, damping, stiffness : array_like
        Per joint, kg, N s/m and N/m (or the rotational equivalents), all > 0 (damping >= 0).
    rate : float
        Integration (command) rate, Hz.
    """

    def __init__(self, mass, damping, stiffness, rate: float) -> None:
        m = np.atleast_1d(np.asarray(mass, dtype=float))
        c = np.atleast_1d(np.asarray(damping, dtype=float))
        k = np.atleast_1d(np.asarray(stiffness, dtype=float))
        if not (m.shape == c.shape == k.shape):
            raise ValueError(f"mass, damping, stiffness sizes differ: {m.size}, {c.size}, {k.size}")
        if not (np.all(np.isfinite(m)) and np.all(np.isfinite(c)) and np.all(np.isfinite(k))):
            raise ValueError("plant parameters must be finite")
        if np.any(m <= 0) or np.any(k <= 0) or np.any(c < 0):
            raise ValueError("plant parameters need mass > 0, stiffness > 0, damping >= 0")
        self.m, self.c, self.k = m, c, k
        self.rate = check_rate(rate)
        self.dt = 1.0 / self.rate
        self.joints = m.size
        self._phi = np.stack([self._transition(*p) for p in zip(m, c, k, strict=True)])
        # state per joint: x2, v2, x1, r (base slope)
        self.state = np.zeros((self.joints, 4))
        self.cycle_time: float | None = None

    def _transition(self, m: float, c: float, k: float) -> np.ndarray:
        a = np.array(
            [
                [0.0, 1.0, 0.0, 0.0],
                [-k / m, -c / m, k / m, c / m],
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, 0.0, 0.0],
            ]
        )
        from scipy.linalg import expm  # on first use: scipy.linalg is 0.2-0.5 s of CPU at a process's start

        return expm(a * self.dt)


    def reset(self, position) -> None:
        """Put every joint at rest: base and tip at ``position``, no motion."""
        p = np.broadcast_to(np.asarray(position, dtype=float), (self.joints,))
        self.state = np.column_stack([p, np.zeros(self.joints), p, np.zeros(self.joints)])

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        """Advance one period while the base moves linearly to ``command``.

        ``cycle_time`` (s since the current cycle's START at the beginning of the period) is
        accepted for the same call as :class:`ListPlant` and has no effect on this plant.
        """
        u = np.asarray(command, dtype=float).reshape(self.joints)
        self.cycle_time = None if cycle_time is None else float(cycle_time) + self.dt
        self.state[:, 3] = (u - self.state[:, 2]) / self.dt
        self.state = np.einsum("jab,jb->ja", self._phi, self.state)
        self.state[:, 2] = u  # exact by construction; removes round-off drift

    @property
    def tip_acceleration(self) -> np.ndarray:
        """x2'' at the end of the last period (left limit), m/s^2 or rad/s^2."""
        x2, v2, x1, r = self.state.T
        return (self.k * (x1 - x2) + self.c * (r - v2)) / self.m


#: the ListPlant models (seed 003 cases 1 to 4)
LIST_MODELS = ("linear", "time_varying", "hardening", "saturation")
#: every plant model a node can ask :func:`make_plant` for
PLANT_MODELS = ("mck", *("list_" + m for m in LIST_MODELS))
#: time-varying mass: m(t) = m (1 + t / MASS_RAMP_TIME) until MASS_RAMP_TIME (s), then 2 m
MASS_RAMP_TIME = 1.0
#: default cubic stiffness (N/m^3): k^3 / (m a)^2 for m = 1 kg, k = 100 N/m, a = 2 m/s^2
LIST_STIFFNESS_CUBIC = 2.5e5
#: default proportional gain of the saturation case, N/m (omega_n = 10 rad/s with m = 1 kg)
LIST_GAIN = 100.0
#: default actuator force limit of the saturation case, N
LIST_FORCE_LIMIT = 2.5
#: RK4 substeps are chosen so that h * (sqrt(k/m) + b/m) stays at or below this
_RK4_STEP = 0.02
#: a substep across a corner of the right-hand side (where RK4 loses its order: the force limit
#: engaging or releasing, the end of the mass ramp) is redone in this many pieces
_CORNER_REFINE = 16


def _per_joint(name: str, value, joints: int | None, unit: str, *, positive: bool = True,
               allow_inf: bool = False) -> np.ndarray:
    """``value`` as a float array of ``joints`` entries (one value is spread), checked."""
    v = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if joints is not None and v.size == 1:
        v = np.full(joints, v[0])
    if v.size == 0 or (joints is not None and v.size != joints):
        need = "at least one value" if joints is None else f"1 or {joints} values"
        raise ValueError(f"{name} needs {need}, got {v.size}")
    ok = ~np.isnan(v) & (np.isfinite(v) | allow_inf)
    ok &= (v > 0) if positive else (v >= 0)
    if not np.all(ok):
        rule = "> 0" if positive else ">= 0"
        raise ValueError(f"{name} must be {'' if allow_inf else 'finite and '}{rule} {unit}, got {v.tolist()}")
    return v


#: the per-joint parameters of the plants: name -> (unit, must be > 0 (else >= 0), may be infinite)
PLANT_VALUES: dict[str, tuple[str, bool, bool]] = {
    "mass": ("kg", True, False),
    "damping": ("N s/m", False, False),
    "stiffness": ("N/m", True, False),
    "stiffness_cubic": ("N/m^3", False, False),
    "gain": ("N/m", True, False),
    "force_limit": ("N", True, True),
}


def plant_values(name: str, value, joints: int | None = None) -> np.ndarray:
    """The per-joint parameter ``name`` (one of :data:`PLANT_VALUES`) as a float array of ``joints``
    entries (one value is spread; any number of values if None), checked as the plants check it."""
    unit, positive, allow_inf = PLANT_VALUES[name]
    return _per_joint(name, value, joints, unit, positive=positive, allow_inf=allow_inf)


class ListPlant(_JointState, PlantBase):
    """The plants of the LIST simulations (seed 003), per joint, integrated with RK4.

    See the module docstring for the equations. State per joint, as MckPlant's: tip x, tip
    velocity x', command u at the end of the last period, and the command slope over it.

    Parameters
    ----------
    model : str
        "linear", "time_varying", "hardening" or "saturation".
    mass : array_like
        m, kg, > 0, per joint (one value for all); for "time_varying" the mass at the START of
        a cycle, which doubles linearly over MASS_RAMP_TIME (1 s) and then stays.
    damping : array_like
        b, N s/m, >= 0, a damper to ground (on x', not on x' - u').
    stiffness : array_like
        k, N/m, > 0 (unused by "saturation").
    rate : float
        Command rate, Hz; the plant advances 1 / rate per step.
    stiffness_cubic : array_like
        k3, N/m^3, >= 0 ("hardening" only; 0 gives the linear plant).
    gain : array_like
        Kp, N/m, > 0 ("saturation" only).
    force_limit : array_like
        f_max, N, > 0, may be inf ("saturation" only).
    substeps : int, optional
        RK4 steps per period; by default enough that h (sqrt(k/m) + b/m) <= 0.02 (Kp in place of
        k for "saturation"), at least 4. A substep across a corner is redone in 16 pieces. For the
        paper's plant at 200 Hz and above, positions and velocities agree with an adaptive
        8th-order solver within 3e-8 of their peak.
    """

    def __init__(self, model: str, mass, damping, stiffness, rate: float, *,
                 stiffness_cubic=LIST_STIFFNESS_CUBIC, gain=LIST_GAIN, force_limit=LIST_FORCE_LIMIT,
                 substeps: int | None = None) -> None:
        if model not in LIST_MODELS:
            raise ValueError(f"model must be one of {', '.join(LIST_MODELS)}; got {model!r}")
        self.model = model
        self.m = plant_values("mass", mass)
        n = self.m.size
        self.c = plant_values("damping", damping, n)
        self.k = plant_values("stiffness", stiffness, n)
        self.k3 = plant_values("stiffness_cubic", stiffness_cubic, n)
        self.kp = plant_values("gain", gain, n)
        self.f_max = plant_values("force_limit", force_limit, n)
        self.rate = check_rate(rate)
        self.dt = 1.0 / self.rate
        self.joints = n
        if substeps is None:
            k_lin = self.kp if model == "saturation" else self.k
            speed = float(np.max(np.sqrt(k_lin / self.m) + self.c / self.m))
            substeps = max(4, math.ceil(self.dt * speed / _RK4_STEP))
        if int(substeps) < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps!r}")
        self.substeps = int(substeps)
        self.state = np.zeros((self.joints, 4))
        self.cycle_time: float | None = None
        # one joint: the same period in Python floats, bit for bit (NumPy's calls on one-element arrays cost more)
        self._one = OneJoint(self, MASS_RAMP_TIME, _CORNER_REFINE) if n == 1 else None

    # ----------------------------------------------------------------- model
    def mass_at(self, cycle_time: float | None) -> np.ndarray:
        """Mass of each joint at ``cycle_time`` s after the cycle's START (None: no cycle), kg."""
        if self.model != "time_varying":
            return self.m
        if cycle_time is None:
            return 2.0 * self.m
        return self.m * (1.0 + min(max(cycle_time, 0.0), MASS_RAMP_TIME) / MASS_RAMP_TIME)

    def force(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Force on the mass, without the damper, N: spring, or saturated P controller."""
        if self.model == "saturation":
            return np.clip(self.kp * (u - x), -self.f_max, self.f_max)
        e = u - x
        if self.model == "hardening":
            return self.k * e + self.k3 * e**3
        return self.k * e

    def _accel(self, x: np.ndarray, v: np.ndarray, u: np.ndarray, tau: float | None) -> np.ndarray:
        return (self.force(x, u) - self.c * v) / self.mass_at(tau)

    @property
    def natural_frequency(self) -> np.ndarray:
        """Undamped natural frequency of the linearised nominal system, rad/s."""
        return np.sqrt((self.kp if self.model == "saturation" else self.k) / self.m)

    @property
    def damping_ratio(self) -> np.ndarray:
        """Damping ratio of the linearised nominal system."""
        return self.c / (2.0 * np.sqrt((self.kp if self.model == "saturation" else self.k) * self.m))

    # ----------------------------------------------------------------- stepping
    def reset(self, position) -> None:
        """Put every joint at rest: command and tip at ``position``, no motion."""
        p = np.broadcast_to(np.asarray(position, dtype=float), (self.joints,))
        self.state = np.column_stack([p, np.zeros(self.joints), p, np.zeros(self.joints)])

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        """Advance one period while the command moves linearly to ``command``.

        Parameters
        ----------
        command : array_like
            The command u at the end of the period, one value per joint, m.
        cycle_time : float, optional
            Time since the current cycle's START at the beginning of the period, s (the
            time-varying mass depends on it); None when no cycle has started.
        """
        if self._one is not None:
            self._one.step(command, cycle_time)
            return
        u1 = np.asarray(command, dtype=float).reshape(self.joints)
        u0 = self.state[:, 2].copy()
        r = (u1 - u0) / self.dt
        x, v = self.state[:, 0].copy(), self.state[:, 1].copy()
        h = self.dt / self.substeps
        for i in range(self.substeps):
            s = i * h
            xn, vn = self._rk4(x, v, u0, r, s, h, cycle_time)
            if self._corner(x, xn, u0 + r * s, u0 + r * (s + h), cycle_time, s, h):
                # RK4 drops to low order across a corner of the right-hand side: redo the substep finely
                hh = h / _CORNER_REFINE
                for j in range(_CORNER_REFINE):
                    x, v = self._rk4(x, v, u0, r, s + j * hh, hh, cycle_time)
            else:
                x, v = xn, vn
        self.state = np.column_stack([x, v, u1, r])
        self.cycle_time = None if cycle_time is None else float(cycle_time) + self.dt

    def _rk4(self, x: np.ndarray, v: np.ndarray, u0: np.ndarray, r: np.ndarray, s: float, h: float,
             cycle_time: float | None) -> tuple[np.ndarray, np.ndarray]:
        """One classical Runge-Kutta step of length h from s (s into the period): :func:`.list_scalar.rk4_step`."""
        return rk4_step(self._accel, x, v, u0, r, s, h, cycle_time)

    def _corner(self, x0: np.ndarray, x1: np.ndarray, u0: np.ndarray, u1: np.ndarray, cycle_time: float | None,
                s: float, h: float) -> bool:
        """Whether the substep crosses a corner: the force limit engaging or releasing, the mass ramp's end."""
        if self.model == "saturation":
            def side(x: np.ndarray, u: np.ndarray) -> np.ndarray:
                f = self.kp * (u - x)
                return np.sign(f - np.clip(f, -self.f_max, self.f_max))
            return bool(np.any(side(x0, u0) != side(x1, u1)))
        if self.model == "time_varying" and cycle_time is not None:
            return cycle_time + s < MASS_RAMP_TIME < cycle_time + s + h
        return False

    @property
    def applied_force(self) -> np.ndarray:
        """Spring or (saturated) controller force at the end of the last period, N."""
        x, _, u, _ = self.state.T
        return self.force(x, u)

    @property
    def tip_acceleration(self) -> np.ndarray:
        """x'' at the end of the last period, m/s^2 (what the accelerometer measures)."""
        x, v, u, _ = self.state.T
        return self._accel(x, v, u, self.cycle_time)


def make_plant(model: str, mass, damping, stiffness, rate: float, *, stiffness_cubic=LIST_STIFFNESS_CUBIC,
               gain=LIST_GAIN, force_limit=LIST_FORCE_LIMIT) -> MckPlant | ListPlant:
    """A plant by model name (one of :data:`PLANT_MODELS`), every parameter checked.

    The parameters of the other models are checked as well, so that a value that would be
    refused by one model is refused whichever model is active.
    """
    if model not in PLANT_MODELS:
        raise ValueError(f"model must be one of {', '.join(PLANT_MODELS)}; got {model!r}")
    list_plant = ListPlant(model[len("list_"):] if model != "mck" else "linear", mass, damping, stiffness, rate,
                           stiffness_cubic=stiffness_cubic, gain=gain, force_limit=force_limit)
    if model != "mck":
        return list_plant
    return MckPlant(list_plant.m, list_plant.c, list_plant.k, rate)
