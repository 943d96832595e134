"""Model-Reference Iterative Learning Control (MRILC, seed 000), free of ROS.

The plant P is uncertain, so a shaper designed on its nominal mode leaves vibration. The closed
loop of a feedback controller C and the nominal plant is the reference model

    G_m = C P_nom / (1 + C P_nom),

whose lightly damped mode is known exactly; the shaper (ZVD in the paper) is designed on it. A
feedforward effort u2, added to the controller's output u1, is learned over the iterations j of
a repeated task,

    u2_{j+1}(k) = Q(z) [u2_j(k) + L(z) e_j(k)],     e = y_m - y,     y_m = G_m r_s,

until the closed loop behaves like G_m and the shaper works again. With H = P / (1 + C P) (the
path from u2 to y), e_j = e_0 - H u2_j, so u2 converges when

    || Q(z) (1 - L(z) H(z)) ||_inf < 1                      (seed 000, eq. 11).

Everything here is sampled: r_s and u2 are held over each period T (zero-order hold) and the
continuous loop is discretised exactly, so the learner's G_m and H are those of the sampled loop
(the simulated plant integrates the same loop exactly, see sim_plant_node.models.pid_loop).

Learning laws (:class:`LawConfig`)
----------------------------------
p        L = gamma z (seed 000, eq. 10: u2_{j+1}(k) = u2_j(k) + gamma e_j(k + 1))
pd       L = gamma z + lambda (z - 1)
robust   beyond the paper: at every frequency, L(w) minimises the worst contraction
         max_p |1 - L(w) H_p(w)| over the plant set (the Chebyshev centre of the points
         1/H_p weighted by |H_p|), scaled by ``gain`` <= 1 for margin; applied between cycles
         as a zero-phase (non-causal) filter by FFT. With one plant it is the inverse of the
         nominal H. Where no L contracts every plant, it does not learn (L = 0 there).
Q is a zero-phase Butterworth low-pass (``q_cutoff_hz``, forward-backward, so its gain is
|Q|^2 and it adds no phase), or 1.

Injection points
----------------
effort   u2 is added to the controller output (the paper): the learning path is H = P/(1+CP).
command  the correction is added to the position setpoint after the shaper (robots that take
         only position setpoints): y = T (r_s + d) with T = CP/(1+CP), so the learning path is
         T = C H. The same correction expressed at the setpoint is d = u2 / C, so the learning
         gain must be divided by C: a P-type gamma that suits "effort" (10 for the paper) is
         far too large for "command", where T ~ 1 in the loop's bandwidth: gamma must be of
         order 1 and, since T's phase passes -90 degrees near the loop's resonance on soft
         plants, a Q filter below it is needed (for the paper's set: gamma 0.5, Q at 5 Hz).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.lazy import lazy_module
from shaper_nodes.core.shaping import Mode

if TYPE_CHECKING:
    import control as ct
    from scipy import optimize, signal
else:  # on first use: a process that only needs PAPER_CONTROLLER (a sim plant node) starts ~1 s sooner
    ct, optimize, signal = lazy_module("control"), lazy_module("scipy.optimize"), lazy_module("scipy.signal")

#: seed 000 eq. (13): PID with derivative filter, C(s) = 177.33 (s^2 + 319.1 s + 2.665e4) / (s (s + 3424))
PAPER_CONTROLLER = ([177.33, 177.33 * 319.1, 177.33 * 2.665e4], [1.0, 3424.0, 0.0])
#: seed 000: nominal plant and the nine plants of the uncertainty set
PAPER_NOMINAL = (10.0, 0.3)
PAPER_OMEGAS = (5.0, 10.0, 15.0)
PAPER_ZETAS = (0.15, 0.30, 0.45)
LAWS = ("p", "pd", "robust")
INJECTIONS = ("effort", "command")


class MrilcError(ValueError):
    """Invalid MRILC input or configuration, or a failed convergence check (the message says which)."""


# ----------------------------------------------------------------------------- models
def mck_plant(omega: float, zeta: float) -> ct.TransferFunction:
    """Base-driven m-c-k joint, x2/x1 = (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2) (seed 000 eq. 12)."""
    if not (math.isfinite(omega) and omega > 0 and math.isfinite(zeta) and 0 <= zeta < 1):
        raise MrilcError(f"plant needs omega > 0 rad/s and 0 <= zeta < 1, got omega {omega!r}, zeta {zeta!r}")
    return ct.tf([2 * zeta * omega, omega**2], [1.0, 2 * zeta * omega, omega**2])


def controller(numerator: Sequence[float] = PAPER_CONTROLLER[0], denominator: Sequence[float] = PAPER_CONTROLLER[1]
               ) -> ct.TransferFunction:
    """A proper continuous controller C(s) from its coefficients (highest power first)."""
    num = np.trim_zeros(np.asarray(numerator, dtype=float), "f")
    den = np.trim_zeros(np.asarray(denominator, dtype=float), "f")
    if num.size == 0 or den.size == 0 or not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
        raise MrilcError(f"controller coefficients must be finite and not all zero: {list(numerator)}"
                         f" / {list(denominator)}")
    if num.size > den.size:
        raise MrilcError(f"controller must be proper (numerator degree {num.size - 1} > denominator {den.size - 1})")
    return ct.tf(num, den)


def reference_model(c: ct.TransferFunction, p_nominal: ct.TransferFunction) -> ct.TransferFunction:
    """G_m = C P / (1 + C P) for the nominal plant (minimal realisation)."""
    g = ct.minreal(ct.feedback(c * p_nominal, 1), verbose=False)
    if not np.all(np.real(g.poles()) < 0):
        raise MrilcError("the reference model C P_nom / (1 + C P_nom) is unstable: the controller does not"
                         " stabilise the nominal plant")
    return g


def learning_path(c: ct.TransferFunction, p: ct.TransferFunction, injection: str = "effort") -> ct.TransferFunction:
    """From the injected signal to y: P/(1+CP) for "effort", CP/(1+CP) for "command"."""
    if injection not in INJECTIONS:
        raise MrilcError(f"injection must be one of {', '.join(INJECTIONS)}, got {injection!r}")
    return ct.feedback(p, c) if injection == "effort" else ct.feedback(c * p, 1)


def modes(system: ct.LTI, max_damping: float = 0.95) -> list[Mode]:
    """The oscillatory modes of a continuous system (complex pole pairs with zeta < max_damping),
    least damped first."""
    out = []
    for pole in np.asarray(system.poles()):
        if pole.imag > 0:
            wn = abs(pole)
            zeta = -pole.real / wn
            if zeta < max_damping:
                out.append(Mode(float(wn), float(zeta)))
    return sorted(out, key=lambda m: m.zeta)


def zoh_sampled(system: ct.LTI, period: float) -> ct.StateSpace:
    """Zero-order-hold discretisation (inputs held over each period, the loop exact)."""
    if not (math.isfinite(period) and period > 0):
        raise MrilcError(f"sample period must be > 0 s, got {period!r}")
    return ct.c2d(ct.ss(system), period, "zoh")


def _freq(system_d: ct.StateSpace, omega: npt.NDArray[np.float64]) -> npt.NDArray[np.complex128]:
    """Frequency response of a SISO discrete system at e^{j w T}."""
    response: npt.NDArray[np.complex128] = np.asarray(system_d(np.exp(1j * omega * system_d.dt)),
                                                      dtype=complex).reshape(-1)
    return response


class SampledFilter:
    """A SISO discrete system applied to whole signals (samples x channels) from rest: the
    convolution with its impulse response (Markov parameters, cached per length), by FFT."""

    def __init__(self, system_d: ct.StateSpace) -> None:
        self.a, self.b = np.asarray(system_d.A), np.asarray(system_d.B)[:, 0]
        self.c, self.d = np.asarray(system_d.C)[0], float(np.asarray(system_d.D)[0, 0])
        self.dc_gain = float(np.real(ct.dcgain(system_d)))
        self._h = np.zeros(0)

    def impulse(self, n: int) -> npt.NDArray[np.float64]:
        if self._h.size < n:
            h = np.empty(n)
            h[0] = self.d
            x = self.b.copy()
            for k in range(1, n):
                h[k] = self.c @ x
                x = self.a @ x
            self._h = h
        return self._h[:n]

    def __call__(self, x: npt.ArrayLike) -> npt.NDArray[np.float64]:
        x = np.asarray(x, dtype=float)
        h = self.impulse(x.shape[0])
        shape = (-1,) + (1,) * (x.ndim - 1)
        y: npt.NDArray[np.float64] = signal.fftconvolve(x, h.reshape(shape), axes=0)[: x.shape[0]]
        return y


# ----------------------------------------------------------------------------- laws
@dataclass(frozen=True)
class LawConfig:
    """How u2 is updated between cycles (see the module docstring)."""

    law: str = "p"
    gamma: float = 10.0            # p, pd: proportional learning gain (units of u2 per unit of e)
    lam: float = 0.0               # pd: derivative learning gain
    gain: float = 0.7              # robust: fraction of the minimax L applied (margin), (0, 1]
    q_cutoff_hz: float = 0.0       # Q low-pass cut-off, Hz (0 = Q = 1)
    q_order: int = 2

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise MrilcError(f"law must be one of {', '.join(LAWS)}, got {self.law!r}")
        for name in ("gamma", "lam", "gain", "q_cutoff_hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise MrilcError(f"{name} must be finite and >= 0, got {v!r}")
        if self.law == "robust" and not 0 < self.gain <= 1:
            raise MrilcError(f"robust law gain must be in (0, 1], got {self.gain!r}")
        if self.law != "robust" and self.gamma == 0 and self.lam == 0:
            raise MrilcError("gamma and lambda are both 0: nothing would be learned")
        if not 1 <= int(self.q_order) <= 8:
            raise MrilcError(f"q_order must be 1-8, got {self.q_order!r}")


def _q_sos(config: LawConfig, period: float) -> npt.NDArray[np.float64] | None:
    if config.q_cutoff_hz <= 0:
        return None
    nyquist = 0.5 / period
    if config.q_cutoff_hz >= nyquist:
        raise MrilcError(f"Q cut-off {config.q_cutoff_hz:g} Hz must be below the Nyquist frequency {nyquist:g} Hz")
    sos: npt.NDArray[np.float64] = signal.butter(int(config.q_order), config.q_cutoff_hz, fs=1.0 / period,
                                                 output="sos")
    return sos


def q_response(config: LawConfig, omega: npt.NDArray[np.floating[Any]], period: float) -> npt.NDArray[np.float64]:
    """|Q(e^{jwT})|^2: the zero-phase (forward-backward) Q filter's gain."""
    sos = _q_sos(config, period)
    if sos is None:
        return np.ones_like(omega)
    _, h = signal.sosfreqz(sos, worN=omega * period)
    gain: npt.NDArray[np.float64] = np.abs(h) ** 2
    return gain


def minimax_learning_filter(paths: list[npt.NDArray[np.complex128]]
                            ) -> tuple[npt.NDArray[np.complex128], npt.NDArray[np.float64]]:
    """Per frequency, the L minimising max_p |1 - L H_p| over the frequency responses ``paths``
    (one array per plant), and that minimum (the best worst-case contraction)."""
    h = np.asarray(paths)  # plants x frequencies
    best_l = np.zeros(h.shape[1], dtype=complex)
    best = np.ones(h.shape[1])
    for i in range(h.shape[1]):
        hp = h[:, i]
        if np.all(np.abs(hp) < 1e-300):
            continue

        def worst(x: npt.NDArray[np.float64], hp: npt.NDArray[np.complex128] = hp) -> float:
            return float(np.max(np.abs(1.0 - (x[0] + 1j * x[1]) * hp)))

        # start from the inverse of the plant-set mean; the problem is convex in (Re L, Im L)
        l0 = 1.0 / np.mean(hp)
        res = optimize.minimize(worst, [l0.real, l0.imag], method="Nelder-Mead",
                                options={"xatol": 1e-9 * (abs(l0) + 1.0), "fatol": 1e-10, "maxiter": 2000})
        value = worst(res.x)
        if value < 1.0:
            best_l[i], best[i] = res.x[0] + 1j * res.x[1], value
    return best_l, best


@dataclass
class LearningFilter:
    """The learning law applied to whole cycles: ``update(u2, e)`` -> Q [u2 + L e]."""

    config: LawConfig
    period: float
    design_omega: npt.NDArray[np.float64] | None = None  # robust: frequencies of the minimax design, rad/s
    design_l: npt.NDArray[np.complex128] | None = None  # robust: L there (already scaled by gain)
    _q: npt.NDArray[np.float64] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self._q = _q_sos(self.config, self.period)
        if self.config.law == "robust" and (self.design_omega is None or self.design_l is None):
            raise MrilcError("the robust law needs its design (use design_learning_filter)")

    def response(self, omega: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.complex128]:
        """L(e^{jwT}) at the frequencies ``omega`` (rad/s)."""
        z = np.exp(1j * omega * self.period)
        c = self.config
        l_z: npt.NDArray[np.complex128]
        if c.law == "p":
            l_z = c.gamma * z
            return l_z
        if c.law == "pd":
            l_z = c.gamma * z + c.lam * (z - 1.0)
            return l_z
        assert self.design_omega is not None and self.design_l is not None  # robust: checked on construction
        w = np.clip(np.abs(omega), self.design_omega[0], self.design_omega[-1])
        lw = np.log(self.design_omega)
        re = np.interp(np.log(w), lw, self.design_l.real)
        im = np.interp(np.log(w), lw, self.design_l.imag)
        l_z = np.where(omega >= 0, re + 1j * im, re - 1j * im)
        return l_z

    def apply_l(self, e: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """L e over a cycle (samples x channels)."""
        e = np.asarray(e, dtype=float)
        c = self.config
        if c.law in ("p", "pd"):
            ahead = np.concatenate([e[1:], e[-1:]], axis=0)  # e(k + 1), the last sample held
            l_e: npt.NDArray[np.float64] = c.gamma * ahead + c.lam * (ahead - e)
            return l_e
        n = e.shape[0]
        m = 1 << int(math.ceil(math.log2(max(2 * n, 2))))
        omega = 2 * math.pi * np.fft.rfftfreq(m, self.period)
        spectrum = np.fft.rfft(e, n=m, axis=0) * self.response(omega)[:, None]
        out: npt.NDArray[np.float64] = np.fft.irfft(spectrum, n=m, axis=0)[:n]
        return out

    def update(self, u2: npt.ArrayLike, e: npt.ArrayLike) -> npt.NDArray[np.float64]:
        out = np.asarray(u2, dtype=float) + self.apply_l(e)
        if self._q is not None and out.shape[0] > 3 * (2 * self._q.shape[0] + 1):
            out = signal.sosfiltfilt(self._q, out, axis=0)
        return out


def frequency_grid(period: float, omega_min: float, points: int = 400) -> npt.NDArray[np.float64]:
    """Log-spaced frequencies from omega_min to just below the Nyquist frequency, rad/s."""
    nyquist = math.pi / period
    if not 0 < omega_min < nyquist:
        raise MrilcError(f"omega_min must be in (0, {nyquist:g}) rad/s, got {omega_min!r}")
    return np.logspace(math.log10(omega_min), math.log10(nyquist * 0.999), points)


def design_learning_filter(config: LawConfig, period: float, paths_d: list[ct.StateSpace],
                           omega_min: float) -> LearningFilter:
    """The learning filter for ``config``; the robust law is designed here on the sampled
    learning paths of the plant set (``paths_d``)."""
    if config.law != "robust":
        return LearningFilter(config, period)
    omega = frequency_grid(period, omega_min)
    l_best, _ = minimax_learning_filter([_freq(h, omega) for h in paths_d])
    return LearningFilter(config, period, omega, config.gain * l_best)


# ----------------------------------------------------------------------------- convergence check
@dataclass(frozen=True)
class ConvergenceReport:
    """sup_w |Q (1 - L H_p)| per plant over [omega_min, Nyquist), and the worst case."""

    ok: bool
    per_plant: dict[str, float]
    worst_plant: str | None  # None only when no plant was checked
    worst_omega: float      # rad/s
    worst_value: float

    def describe(self) -> str:
        verdict = "converges" if self.ok else "does NOT converge"
        return (f"{verdict}: max |Q(1 - L H)| = {self.worst_value:.6f} for plant {self.worst_plant}"
                f" at {self.worst_omega:.4g} rad/s ({self.worst_omega / (2 * math.pi):.4g} Hz)")


def check_convergence(learning: LearningFilter, paths_d: dict[str, ct.StateSpace], omega_min: float,
                      points: int = 2000) -> ConvergenceReport:
    """Seed 000's condition (11), ||Q (1 - L H)||_inf < 1, for every plant's sampled learning path.

    At w = 0 the value is exactly 1 whenever the controller has an integrator (H(0) = 0): the
    feedback loop removes a constant error by itself. The check therefore runs from
    ``omega_min`` > 0 (the learner uses 2 pi / (cycle duration), the lowest frequency a cycle
    resolves) to the Nyquist frequency.
    """
    omega = frequency_grid(learning.period, omega_min, points)
    lq = learning.response(omega)
    q = q_response(learning.config, omega, learning.period)
    per: dict[str, float] = {}
    worst: tuple[str | None, float, float] = (None, -1.0, 0.0)
    for name, h in paths_d.items():
        g = q * np.abs(1.0 - lq * _freq(h, omega))
        i = int(np.argmax(g))
        per[name] = float(g[i])
        if g[i] > worst[1]:
            worst = (name, float(g[i]), float(omega[i]))
    return ConvergenceReport(worst[1] < 1.0, per, worst[0], worst[2], worst[1])


def gain_bound(paths_d: dict[str, ct.StateSpace], period: float, omega_min: float, points: int = 2000) -> float:
    """The largest P-type gamma (L = gamma z, Q = 1) that passes the check for every plant:
    min over plants and frequencies of 2 Re(z H) / |H|^2 (0 if some Re(z H) <= 0)."""
    omega = frequency_grid(period, omega_min, points)
    z = np.exp(1j * omega * period)
    bound = math.inf
    for h in paths_d.values():
        zh = z * _freq(h, omega)
        bound = min(bound, float(np.min(2 * np.maximum(zh.real, 0.0) / np.maximum(np.abs(zh) ** 2, 1e-300))))
    return bound


# ----------------------------------------------------------------------------- the loop model
@dataclass
class MrilcModel:
    """Everything the learner derives from its configuration, checked before learning starts.

    Parameters
    ----------
    c : controller; nominal : nominal plant; plant_set : name -> plant (the uncertainty set the
    check covers; the nominal plant is always added); period : sample period, s; injection :
    "effort" or "command"; law : LawConfig; omega_min : lowest frequency of the check, rad/s.
    """

    c: ct.TransferFunction
    nominal: ct.TransferFunction
    plant_set: dict[str, ct.TransferFunction]
    period: float
    injection: str = "effort"
    law: LawConfig = field(default_factory=LawConfig)
    omega_min: float = 1.0

    def __post_init__(self) -> None:
        self.g_m = reference_model(self.c, self.nominal)
        self.mode = modes(self.g_m)[0] if modes(self.g_m) else None
        self.g_m_d = zoh_sampled(self.g_m, self.period)
        self.reference_filter = SampledFilter(self.g_m_d)
        plants = {"nominal": self.nominal, **self.plant_set}
        self.paths_d = {name: zoh_sampled(learning_path(self.c, p, self.injection), self.period)
                        for name, p in plants.items()}
        self.learning = design_learning_filter(self.law, self.period, list(self.paths_d.values()), self.omega_min)
        self.convergence = check_convergence(self.learning, self.paths_d, self.omega_min)

    def require_convergence(self) -> None:
        """Raise MrilcError naming the worst plant and frequency if the check fails."""
        if not self.convergence.ok:
            hint = ""
            if self.law.law == "p" and self.law.q_cutoff_hz == 0:
                bound = gain_bound(self.paths_d, self.period, self.omega_min)
                hint = (f"; the largest P-type gamma that passes is {bound:.4g}" if bound > 0 else
                        "; no P-type gamma passes without a Q filter (the path's phase passes -90 degrees)")
            raise MrilcError(f"learning refused: the law {self.law.law} (gamma {self.law.gamma:g}) "
                             f"{self.convergence.describe()}{hint}")

    def reference_response(self, r_s: npt.ArrayLike, rest: npt.ArrayLike | None = None) -> npt.NDArray[np.float64]:
        """y_m over a cycle (samples x joints) of the reference model at rest at ``rest`` (per
        joint; default the first reference sample) when the cycle starts."""
        r_s = np.asarray(r_s, dtype=float)
        r0 = r_s[:1] if rest is None else np.asarray(rest, dtype=float).reshape(1, -1)
        y_m: npt.NDArray[np.float64] = r0 * self.reference_filter.dc_gain + self.reference_filter(r_s - r0)
        return y_m


def paper_plant_set(omegas: Sequence[float] = PAPER_OMEGAS, zetas: Sequence[float] = PAPER_ZETAS
                    ) -> dict[str, ct.TransferFunction]:
    """The plants of a grid of modes, named 'w=5 zeta=0.15' etc."""
    return {f"w={w:g} zeta={z:g}": mck_plant(w, z) for w in omegas for z in zetas}


def rms(x: npt.ArrayLike) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2))) if x.size else 0.0
