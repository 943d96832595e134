"""Closed-loop plants: a base-driven m-c-k joint with a loop controller inside the plant (seeds 001, 002).

The reference r of the loop is the (shaped) command the sim plant receives; the controller
output u drives the base x1, the tip x2 is the plant output. As for the seed 000 loop
(``mck_pid``), /joint_states carries the output y (position), y' (velocity) and the control u
(effort), and ~/tip_state y and y'; ~/loop_state adds the measured output and the reference.
Per joint, x2 / x1 = (c s + k) / (m s^2 + c s + k) (c = 0: the undamped plant
w_R^2 / (s^2 + w_R^2) of seed 001). The controller runs ``substeps`` times per command
period (loop rate = rate x substeps); at each loop sample k

    y_k  = x2(t_k) + d_o(t_k)            plant output with the plant-output disturbance
    ym_k = y_k + n_k                     measured output (measurement noise: a step and white noise)
    u_k  = controller(r, ym_k, ...)      held over the loop sample (zero-order hold)

and the plant is integrated exactly over the sample (matrix exponential; the damper's c u'
impulse at a jump of u moves x2' by c / m times the jump). The reference is held over the
command period (the controller samples the setpoint as it arrives).

Models
------
delay_loop
    Seed 001's time-delay feedback controller in its IMC form: v_k = r - ym_k + yhat_k,
    u_k = A0 v_k + A1 v_{k-N} + A2 v_{k-2N}, yhat = G_PA u the internal model w_A^2 / (s^2 + w_A^2)
    discretised exactly like the plant; the delay T is rounded to N whole loop samples and the
    PPUSMD gains are computed for that T (exact delays on the sample grid).
qft_fb, qft_ffb
    Seed 002's controllers: u = Gr r + G (F r - ym), G of eq. (10) with gain 234.4 (qft_fb, Gr =
    0) or 166.7 (qft_ffb, Gr = 1), F = P0 (the nominal plant, from ``loop.nominal``). F and G are
    two digital blocks, each the zero-order-hold equivalent of its transfer function at the loop
    rate: F samples the reference, G the sampled error e_k = (F r)_k - ym_k. F's samples are then
    exactly those of P0 driven through the same hold as the plant, so on a plant equal to P0 the
    error is zero to rounding and the loop's output is the open loop's (Y/R = P0, as in the paper).
qft_open
    The open loop of seed 002 Fig. 1 with the same disturbance and noise inputs: u = r.

Disturbance and noise (per joint, from ``cycle_time`` s after each cycle's START; none before
the first START): d_o = ``disturbance_step`` once ``cycle_time >= disturbance_time``; n =
``noise_step`` once ``cycle_time >= noise_time`` plus white noise of ``noise_stddev``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shaper_nodes.core.closed_loop import ppusmd_gains, qft

from .base import PlantBase
from .plants import MckMode, _JointState, check_rate, plant_values

LOOP_MODELS = ("delay_loop", "qft_open", "qft_fb", "qft_ffb")
#: the loop parameters of the sim plant node: name -> (default, description)
LOOP_PARAMS: dict[str, tuple[object, str]] = {
    "loop.substeps": (1, "Loop models: controller samples per command period (loop rate = rate x substeps), >= 1."),
    "loop.assumed_frequency": (3.0, "delay_loop: assumed plant frequency w_A of the time-delay filter, rad/s, > 0."),
    "loop.delay": (math.pi / 9.0, "delay_loop: delay T of the filter, s (rounded to whole loop samples, >= 1)."),
    "loop.gain": (0.0, "qft_fb / qft_ffb: gain K of G (eq. 10); 0 = the paper's (234.4 fb, 166.7 ffb)."),
    "loop.nominal": ([1.0, 25.1327, 1.5791e4], "qft_*: nominal plant P0 = F as [m kg, c N s/m, k N/m]."),
    "loop.disturbance_step": (0.0, "Loop models: plant-output disturbance step, m (added to the output)."),
    "loop.disturbance_time": (0.0, "Loop models: time of the disturbance step after each cycle's START, s."),
    "loop.noise_step": (0.0, "Loop models: measurement-noise step, m (added to the measured output)."),
    "loop.noise_time": (0.0, "Loop models: time of the noise step after each cycle's START, s."),
    "loop.noise_stddev": (0.0, "Loop models: white measurement noise, m (one sigma, per loop sample)."),
    "loop.seed": (1, "Loop models: seed of the measurement-noise generator."),
}


#: loop parameters that must be finite, and those that must also be >= 0
_FINITE = ("loop.disturbance_step", "loop.noise_step")
_NON_NEGATIVE = ("loop.disturbance_time", "loop.noise_time", "loop.noise_stddev")


def check_loop_value(name: str, value: Any) -> Any:
    """The loop plants' check of the value of the loop parameter ``name`` (one of :data:`LOOP_PARAMS`);
    returns it as the plants use it (an int, a float, an array) or raises ``ValueError``."""
    if name == "loop.substeps":
        if isinstance(value, bool) or int(value) != value or int(value) < 1:
            raise ValueError(f"loop.substeps must be an integer >= 1, got {value!r}")
        return int(value)
    if name in _FINITE or name in _NON_NEGATIVE:
        v = float(value)
        if not math.isfinite(v) or (name in _NON_NEGATIVE and v < 0):
            raise ValueError(f"{name} must be finite{' and >= 0' if name in _NON_NEGATIVE else ''}, got {value!r}")
        return v
    if name in ("loop.assumed_frequency", "loop.delay"):
        v = float(value)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0 {'rad/s' if name == 'loop.assumed_frequency' else 's'},"
                             f" got {v!r}")
        return v
    if name == "loop.gain":
        v = float(value)
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"loop.gain must be finite and >= 0 (0: the paper's), got {v!r}")
        return v
    if name == "loop.nominal":
        nom = np.asarray(value, dtype=float).ravel()
        if nom.size != 3 or not np.all(np.isfinite(nom)) or nom[0] <= 0 or nom[1] < 0 or nom[2] <= 0:
            raise ValueError(f"loop.nominal must be [m > 0, c >= 0, k > 0], got {nom.tolist()}")
        return nom
    return value


def _zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = a.shape[0], b.shape[1]
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a, b
    from scipy.linalg import expm  # on first use: scipy.linalg is 0.2-0.5 s of CPU at a process's start

    e = expm(big * dt)
    return e[:n, :n], e[:n, n:]


class LoopPlant(_JointState, MckMode, PlantBase):
    """Base class: the m-c-k joints, the disturbance and noise inputs, the sample loop.

    State per joint as the other plants: tip x2, x2', base x1 (= u at the end of the last
    period), its mean slope over the period. Subclasses implement ``_control`` and ``_rest``.
    """

    model = "loop"
    #: the signals of ~/loop_state, per joint, in this order
    SIGNALS = ("output", "measured", "control", "reference")
    loop_signals: tuple[str, ...] = SIGNALS

    def __init__(self, mass, damping, stiffness, rate: float, params: dict) -> None:
        self.m = plant_values("mass", mass)
        n = self.m.size
        self.c = plant_values("damping", damping, n)
        self.k = plant_values("stiffness", stiffness, n)
        self.rate = check_rate(rate)
        p = {name: params.get(name, default) for name, (default, _) in LOOP_PARAMS.items()}
        self.substeps = check_loop_value("loop.substeps", p["loop.substeps"])
        for name in ("loop.disturbance_step", "loop.disturbance_time", "loop.noise_step", "loop.noise_time",
                     "loop.noise_stddev"):
            check_loop_value(name, p[name])
        self.params = p
        self.joints = n
        self.dt = 1.0 / self.rate
        self.h = self.dt / self.substeps
        a = np.zeros((n, 3, 3))
        a[:, 0, 1] = 1.0
        a[:, 1, 0], a[:, 1, 1], a[:, 1, 2] = -self.k / self.m, -self.c / self.m, self.k / self.m
        from scipy.linalg import expm  # on first use: scipy.linalg is 0.2-0.5 s of CPU at a process's start

        self._phi = np.stack([expm(ai * self.h) for ai in a])
        self._rng = np.random.default_rng(int(p["loop.seed"]))
        self.state = np.zeros((n, 4))
        self.cycle_time: float | None = None
        self.output = np.zeros(n)
        self.measured = np.zeros(n)
        self.control = np.zeros(n)
        self.reference = np.zeros(n)

    # --- interface shared with the open-loop plants
    @property
    def state(self) -> np.ndarray:
        return self._state

    @state.setter
    def state(self, value: np.ndarray) -> None:
        """Take over a plant state (a live model change): the controller rests at the tip position."""
        self._state = np.array(value, dtype=float).reshape(self.joints, 4)
        if hasattr(self, "_rng"):
            x2 = self._state[:, 0].copy()
            self.output, self.measured, self.reference = x2.copy(), x2.copy(), x2.copy()
            self.control = self._state[:, 2].copy()
            self._rest(x2)

    @property
    def base_position(self) -> np.ndarray:
        """The output y = x2 + d_o at the end of the last period (what /joint_states carries)."""
        return np.asarray(self.output, dtype=float).copy()

    @property
    def base_velocity(self) -> np.ndarray:
        """y' (= x2')."""
        return self._state[:, 1].copy()

    tip_position = base_position
    tip_velocity = base_velocity

    @property
    def effort(self) -> np.ndarray:
        """The controller output u (the base position x1) over the last loop sample."""
        return np.asarray(self.control, dtype=float).copy()

    @property
    def tip_acceleration(self) -> np.ndarray:
        x2, v2, x1, _ = self._state.T
        return (self.k * (x1 - x2) - self.c * v2) / self.m

    def reset(self, position) -> None:
        p = np.broadcast_to(np.asarray(position, dtype=float), (self.joints,)).copy()
        self._state = np.column_stack([p, np.zeros(self.joints), p, np.zeros(self.joints)])
        self.output, self.measured, self.control, self.reference = p.copy(), p.copy(), p.copy(), p.copy()
        self._rest(p)

    def step(self, command, cycle_time: float | None = None, velocity=None) -> None:
        r = np.asarray(command, dtype=float).reshape(self.joints)
        self.reference = r.copy()
        x1_start = self._state[:, 2].copy()
        for j in range(self.substeps):
            tau = None if cycle_time is None else cycle_time + j * self.h
            d = self._level("disturbance", tau)
            y = self._state[:, 0] + d
            ym = y + self._level("noise", tau)
            sigma = float(self.params["loop.noise_stddev"])
            if sigma > 0:
                ym = ym + self._rng.normal(0.0, sigma, self.joints)
            u = self._control(r, ym)
            # damper impulse at the jump of the base, then the exact flow with the base held
            self._state[:, 1] += self.c / self.m * (u - self._state[:, 2])
            self._state[:, 2] = u
            x = np.einsum("jab,jb->ja", self._phi, self._state[:, :3])
            self._state[:, :3] = x
            self._state[:, 2] = u
            self.output, self.measured, self.control = y, ym, u
        self._state[:, 3] = (self._state[:, 2] - x1_start) / self.dt
        self.cycle_time = None if cycle_time is None else float(cycle_time) + self.dt
        end = None if cycle_time is None else cycle_time + self.dt
        self.output = self._state[:, 0] + self._level("disturbance", end)

    def loop_state(self) -> np.ndarray:
        """Per joint: output y (with d_o), measured y + n, control u, reference r (:attr:`SIGNALS`)."""
        return np.concatenate([self.output, self.measured, self.control, self.reference])

    def _level(self, what: str, tau: float | None) -> float:
        if tau is None:
            return 0.0
        step, at = float(self.params[f"loop.{what}_step"]), float(self.params[f"loop.{what}_time"])
        return step if tau >= at - 1e-12 else 0.0

    # --- the controller
    def _control(self, r: np.ndarray, ym: np.ndarray) -> np.ndarray:
        return r.copy()

    def _rest(self, position: np.ndarray) -> None:
        """Controller states at rest with reference = output = base = ``position``."""


class DelayLoopPlant(LoopPlant):
    """Seed 001's time-delay feedback controller around the m-c-k joints (see the module docstring)."""

    model = "delay_loop"

    def __init__(self, mass, damping, stiffness, rate: float, params: dict) -> None:
        super().__init__(mass, damping, stiffness, rate, params)
        wa = check_loop_value("loop.assumed_frequency", self.params["loop.assumed_frequency"])
        t = check_loop_value("loop.delay", self.params["loop.delay"])
        self.delay_samples = max(1, int(round(t / self.h)))
        self.delay = self.delay_samples * self.h
        self.omega_a = wa
        self.gains = ppusmd_gains(wa, self.delay)  # raises when w_A T is a multiple of 2 pi
        am, bm = _zoh(np.array([[0.0, 1.0], [-wa**2, 0.0]]), np.array([[0.0], [wa**2]]), self.h)
        self._am, self._bm = am, bm[:, 0]
        self._model = np.zeros((self.joints, 2))
        self._line = np.zeros((self.joints, 2 * self.delay_samples + 1))  # v_k .. v_{k-2N}, ring
        self._head = 0
        self.reset(np.zeros(self.joints))

    def _rest(self, position: np.ndarray) -> None:
        if not hasattr(self, "_line"):
            return
        self._model = np.column_stack([position, np.zeros(self.joints)])
        self._line[:] = position[:, None]

    def _control(self, r: np.ndarray, ym: np.ndarray) -> np.ndarray:
        n, size = self.delay_samples, self._line.shape[1]
        v = r - ym + self._model[:, 0]
        self._head = (self._head + 1) % size
        self._line[:, self._head] = v
        a0, a1, a2 = self.gains
        u = a0 * v + a1 * self._line[:, (self._head - n) % size] + a2 * self._line[:, (self._head - 2 * n) % size]
        self._model = self._model @ self._am.T + np.outer(u, self._bm)
        return u


class QftLoopPlant(LoopPlant):
    """Seed 002's feedback ('qft_fb') and feedforward-feedback ('qft_ffb') controllers, or the open
    loop ('qft_open'), around the m-c-k joints (see the module docstring)."""

    def __init__(self, model: str, mass, damping, stiffness, rate: float, params: dict) -> None:
        super().__init__(mass, damping, stiffness, rate, params)
        if model not in ("qft_open", "qft_fb", "qft_ffb"):
            raise ValueError(f"model must be qft_open, qft_fb or qft_ffb; got {model!r}")
        self.model = model
        if model == "qft_open":
            return
        gain = check_loop_value("loop.gain", self.params["loop.gain"])
        gain = gain or (qft.GAIN_FB if model == "qft_fb" else qft.GAIN_FFB)
        nom = check_loop_value("loop.nominal", self.params["loop.nominal"])
        self.gain, self.gr = gain, (1.0 if model == "qft_ffb" else 0.0)
        import control

        f = control.ss(qft.plant_tf(qft.MckParams(*nom)))
        g = control.ss(qft.controller_tf(gain))
        af, bf, cf, df = (np.asarray(x, dtype=float) for x in (f.A, f.B, f.C, f.D))
        ag, bg, cg, dg = (np.asarray(x, dtype=float) for x in (g.A, g.B, g.C, g.D))
        # two digital blocks, each the zero-order-hold equivalent of its transfer function at the loop rate:
        # F samples the reference, G the sampled error F r - y_measured
        self._af, self._bf = _zoh(af, bf, self.h)
        self._ag, self._bg = _zoh(ag, bg, self.h)
        self._cf, self._df = cf[0], float(df[0, 0])
        self._cg, self._dg = cg[0], float(dg[0, 0])
        # rest: F at steady state with output p; G's integrator holding (1 - Gr) p
        self._xf_unit = -np.linalg.solve(af, bf[:, 0])
        self._xf_unit /= float(self._cf @ self._xf_unit + self._df)
        from scipy.linalg import null_space  # on first use

        ns = null_space(ag)[:, 0]
        self._xg_unit = ns / float(self._cg @ ns)
        self._xf = np.zeros((self.joints, af.shape[0]))
        self._xg = np.zeros((self.joints, ag.shape[0]))
        self.reset(np.zeros(self.joints))

    def _rest(self, position: np.ndarray) -> None:
        if not hasattr(self, "_xg"):
            return
        self._xf = np.outer(position, self._xf_unit)
        self._xg = np.outer((1.0 - self.gr) * position, self._xg_unit)

    def _control(self, r: np.ndarray, ym: np.ndarray) -> np.ndarray:
        if self.model == "qft_open":
            return r.copy()
        e = self._xf @ self._cf + self._df * r - ym
        u = self._xg @ self._cg + self._dg * e + self.gr * r
        self._xf = self._xf @ self._af.T + np.outer(r, self._bf[:, 0])
        self._xg = self._xg @ self._ag.T + np.outer(e, self._bg[:, 0])
        return u


def make_loop_plant(model: str, mass, damping, stiffness, rate: float, params: dict) -> LoopPlant:
    """A loop plant by model name (one of :data:`LOOP_MODELS`), every parameter checked."""
    if model == "delay_loop":
        return DelayLoopPlant(mass, damping, stiffness, rate, params)
    if model in LOOP_MODELS:
        return QftLoopPlant(model, mass, damping, stiffness, rate, params)
    raise ValueError(f"loop model must be one of {', '.join(LOOP_MODELS)}; got {model!r}")
