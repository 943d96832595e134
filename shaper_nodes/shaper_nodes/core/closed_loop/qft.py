"""Model-reference input shaping with a quantitative (QFT) feedforward-feedback controller (seed 002).

The uncertain m-c-k plant (x2 / x1, base x1 driven by the controller, tip x2 the output)

    P(s) = (c s + k) / (m s^2 + c s + k),

nominal m = 1 kg, c = 25.1327 N s/m, k = 1.5791e4 N/m (w_n = 40 pi rad/s, zeta = 0.1), each
parameter uncertain by 35 %: m in [0.65, 1.35] kg, c in [16.336, 33.929] N s/m, k in [1.0264,
2.1318] x 1e4 N/m. The controller of eq. (10)

    G(s) = K / s (s / 7.661 + 1) / (s^2 / 3439^2 + 2 (0.565) s / 3439 + 1),

K = 234.4 for the feedback design (Fig. 2) and 166.7 for the feedforward-feedback design
(Fig. 4); prefilter F = M = P0 and feedforward Gr = M / P0 = 1. The closed loops are

    feedback             Y/R = P G F / (1 + P G),           |M - Y/R| = |P0 / (1 + P G)|        (7)
    feedforward-feedback Y/R = (P Gr + P G F) / (1 + P G),  |M - Y/R| = |(P0 - P) / (1 + P G)|  (9)

and the model-matching specification is |M - Y/R| < delta_m = 0.1 (-20 dB). QFT bounds: on the
Nichols chart of the nominal open loop L0 = G P0, at each working frequency and open-loop phase,
the magnitudes of L0 for which some plant of the template violates the specification: with
a = P / P0 and R the right-hand side, |1 + L0 a| >= R is a quadratic in |L0|, solved exactly per
plant. Section 3.2's disturbance and noise specifications: |1 / (1 + PG)| (plant-output
disturbance), |P / (1 + PG)| (plant-input disturbance), |PG / (1 + PG)| (noise).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.lazy import lazy_module

if TYPE_CHECKING:
    import control
else:  # on first use: the sim plant node imports this module for its loop plants, which never need it
    control = lazy_module("control")

#: nominal plant, kg, N s/m, N/m
NOMINAL = (1.0, 25.1327, 1.5791e4)
#: the paper's corners (35 % uncertainty): m, c, k
CORNERS_M = (0.65, 1.35)
CORNERS_C = (16.336, 33.929)
CORNERS_K = (1.0264e4, 2.1318e4)
#: working frequencies of the design, rad/s
WORKING_FREQUENCIES = (10.0, 50.0, 100.0, 120.0, 150.0, 200.0, 500.0)
#: controller gains of eq. (10): feedback (Fig. 2) and feedforward-feedback (Fig. 4)
GAIN_FB = 234.4
GAIN_FFB = 166.7
#: model-matching tolerance delta_m (-20 dB)
DELTA_M = 0.1
#: the designs; "open" is the open loop of Fig. 1 (Y/R = P)
DESIGNS = ("fb", "ffb", "open")
#: the paper's statement: the feedback design violates its bounds at these working frequencies on purpose
PAPER_FB_VIOLATIONS = (120.0, 150.0)


class QftError(ValueError):
    """Invalid QFT input; the message names the problem."""


@dataclass(frozen=True)
class MckParams:
    """One plant of the set: mass (kg), damping (N s/m), stiffness (N/m)."""

    m: float
    c: float
    k: float

    @property
    def omega_n(self) -> float:
        return math.sqrt(self.k / self.m)

    @property
    def zeta(self) -> float:
        return self.c / (2.0 * math.sqrt(self.k * self.m))

    def label(self) -> str:
        return f"m={self.m:g} c={self.c:g} k={self.k:g}"


def nominal() -> MckParams:
    return MckParams(*NOMINAL)


def corners() -> list[MckParams]:
    """The eight corners of the parameter box, in the order m, c, k (low first)."""
    return [MckParams(m, c, k) for m, c, k in itertools.product(CORNERS_M, CORNERS_C, CORNERS_K)]


def plant_grid(points: int = 5) -> list[MckParams]:
    """``points`` values per parameter across the box (for templates), corners included."""
    if points < 2:
        raise QftError(f"template grid needs at least 2 points per parameter, got {points}")
    ms, cs, ks = (np.linspace(lo, hi, points) for lo, hi in (CORNERS_M, CORNERS_C, CORNERS_K))
    return [MckParams(float(m), float(c), float(k)) for m, c, k in itertools.product(ms, cs, ks)]


def plant_tf(p: MckParams) -> control.TransferFunction:
    """P(s) = (c s + k) / (m s^2 + c s + k)."""
    return control.tf([p.c, p.k], [p.m, p.c, p.k])


def controller_tf(gain: float) -> control.TransferFunction:
    """G(s) of eq. (10) with the constant gain ``gain`` (234.4 feedback, 166.7 feedforward-feedback)."""
    if not (math.isfinite(gain) and gain > 0):
        raise QftError(f"controller gain must be finite and > 0, got {gain!r}")
    wp, zp = 3439.0, 0.565
    return control.tf([gain / 7.661, gain], [1.0, 0.0]) * control.tf([1.0], [1.0 / wp**2, 2.0 * zp / wp, 1.0])


def design_gain(design: str) -> float:
    if design not in DESIGNS:
        raise QftError(f"design must be one of {', '.join(DESIGNS)}; got {design!r}")
    return GAIN_FB if design == "fb" else GAIN_FFB


def _freq(sys: control.TransferFunction, omega: npt.ArrayLike) -> npt.NDArray[np.complex128]:
    return np.asarray(sys(1j * np.asarray(omega, dtype=float)), dtype=np.complex128).ravel()


def closed_loop(design: str, p: MckParams, gain: float | None = None) -> control.TransferFunction:
    """Y/R of a design ('fb', 'ffb', 'open') on plant p, F = P0, Gr = 1."""
    gain = design_gain(design) if gain is None else gain
    pp, p0 = plant_tf(p), plant_tf(nominal())
    if design == "open":
        return pp
    g = controller_tf(gain)
    num = pp * g * p0 + (pp if design == "ffb" else 0)
    return control.minreal(num / (1 + pp * g), verbose=False)


def matching_error(design: str, p: MckParams, omega: npt.ArrayLike, gain: float | None = None) -> np.ndarray:
    """|M - Y/R| at the frequencies ``omega`` (rad/s), M = P0, evaluated in closed form (7) / (9)."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    pw, p0w = _freq(plant_tf(p), w), _freq(plant_tf(nominal()), w)
    if design == "open":
        return np.abs(p0w - pw)
    gw = _freq(controller_tf(design_gain(design) if gain is None else gain), w)
    num = p0w if design == "fb" else p0w - pw
    return np.abs(num / (1.0 + pw * gw))


def loop_specs(design: str, p: MckParams, omega: npt.ArrayLike, gain: float | None = None) -> dict[str, np.ndarray]:
    """Section 3.2's magnitudes at ``omega``: output disturbance |1/(1+PG)|, input disturbance
    |P/(1+PG)|, noise |PG/(1+PG)| (for 'open': 1, |P|, 0)."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    pw = _freq(plant_tf(p), w)
    if design == "open":
        return {"output_disturbance": np.ones_like(w), "input_disturbance": np.abs(pw),
                "noise": np.zeros_like(w)}
    lw = pw * _freq(controller_tf(design_gain(design) if gain is None else gain), w)
    return {"output_disturbance": np.abs(1.0 / (1.0 + lw)), "input_disturbance": np.abs(pw / (1.0 + lw)),
            "noise": np.abs(lw / (1.0 + lw))}


@dataclass(frozen=True)
class MatchRow:
    """|M - Y/R| of one plant at each frequency, and the frequencies where it exceeds delta."""

    plant: MckParams
    errors: tuple[float, ...]
    violations: tuple[float, ...]


def matching_table(design: str, omega: npt.ArrayLike = WORKING_FREQUENCIES, plants: list[MckParams] | None = None,
                   delta: float = DELTA_M, gain: float | None = None) -> list[MatchRow]:
    """Per plant (default: the eight corners), |M - Y/R| at each frequency and where it exceeds delta."""
    if not (math.isfinite(delta) and delta > 0):
        raise QftError(f"delta_m must be finite and > 0, got {delta!r}")
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise QftError(f"frequencies must be finite and > 0 rad/s, got {w.tolist()}")
    rows = []
    for p in plants or corners():
        e = matching_error(design, p, w, gain)
        rows.append(MatchRow(p, tuple(float(x) for x in e),
                             tuple(float(wi) for wi, x in zip(w, e, strict=True) if x > delta)))
    return rows


def worst_case(design: str, omega: npt.ArrayLike, plants: list[MckParams] | None = None,
               gain: float | None = None) -> np.ndarray:
    """max over plants of |M - Y/R| at each frequency."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    worst: np.ndarray = np.max([matching_error(design, p, w, gain) for p in plants or plant_grid(5)], axis=0)
    return worst


# ------------------------------------------------------------------------------------------------
# templates and bounds on the Nichols chart


def nichols(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phase (deg, unwrapped into (-360, 0]) and magnitude (dB) of complex values."""
    values = np.asarray(values, dtype=complex)
    phase = np.degrees(np.angle(values))
    phase = np.where(phase > 0, phase - 360.0, phase)
    return phase, 20.0 * np.log10(np.abs(values))


def template(omega: float, plants: list[MckParams] | None = None) -> np.ndarray:
    """The plant values P(j omega) over the parameter box (complex array)."""
    return np.array([_freq(plant_tf(p), [omega])[0] for p in plants or plant_grid(7)])


def bounds(spec: str, omega: float, phases_deg: np.ndarray, delta: float = DELTA_M,
           plants: list[MckParams] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """QFT bound of spec (7) ('fb') or (9) ('ffb') at one frequency: for each open-loop phase of
    L0 = G P0, the lowest and highest |L0| (dB) that some plant of the template forbids (NaN where none).
    The allowed region is above the upper edge (or below the lower one)."""
    if spec not in ("fb", "ffb"):
        raise QftError(f"spec must be 'fb' (eq. 7) or 'ffb' (eq. 9); got {spec!r}")
    plants = plants or plant_grid(7)
    p0 = _freq(plant_tf(nominal()), [omega])[0]
    pw = template(omega, plants)
    a = pw / p0
    r = np.broadcast_to((np.abs(p0) if spec == "fb" else np.abs(p0 - pw)) / delta, pw.shape)
    ph = np.radians(np.asarray(phases_deg, dtype=float))[:, None]
    # |1 + l |a| e^{j theta}| >= r  <=>  l^2 |a|^2 + 2 l |a| cos(theta) + 1 - r^2 >= 0
    theta = ph + np.angle(a)[None, :]
    cos = np.cos(theta)
    disc = cos**2 - 1.0 + r[None, :] ** 2
    root = np.sqrt(np.maximum(disc, 0.0))
    hi = (-cos + root) / np.abs(a)[None, :]
    lo = np.maximum((-cos - root) / np.abs(a)[None, :], 0.0)
    bad = (disc > 0) & (hi > 0)
    with np.errstate(divide="ignore"):
        upper = np.where(bad.any(axis=1), 20 * np.log10(np.max(np.where(bad, hi, 0.0), axis=1)), np.nan)
        low = np.where(bad, lo, np.inf).min(axis=1)
        lower = np.where(bad.any(axis=1), np.where(low > 0, 20 * np.log10(np.maximum(low, 1e-300)), -np.inf), np.nan)
    return lower, upper


@dataclass(frozen=True)
class Margins:
    """Stability margins of L = P G for one plant: gain margin (factor), phase margin (deg), gain
    crossover (rad/s), and whether the closed loop is stable (its poles)."""

    plant: MckParams
    gain_margin: float
    phase_margin: float
    crossover: float
    stable: bool


def margins(design: str, plants: list[MckParams] | None = None, gain: float | None = None) -> list[Margins]:
    """Margins of the loop of a design ('fb', 'ffb') for each plant (default: the eight corners)."""
    g = controller_tf(design_gain(design) if gain is None else gain)
    out = []
    for p in plants or corners():
        loop = g * plant_tf(p)
        gm, pm, _, wc = control.margin(loop)
        poles = control.poles(control.feedback(loop, 1))
        out.append(Margins(p, float(gm), float(pm), float(wc), bool(np.all(np.real(poles) < 0))))
    return out
