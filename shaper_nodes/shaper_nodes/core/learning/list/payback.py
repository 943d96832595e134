"""A factor over a move's base shaper that pays: less residual, and no longer move + settle time.

A LIST factor convolved with a move's scheduled shaper adds its own delay to the schedule's. On the
arm the move + settle time (the flange within 0.05 mm) ends when the tail of the commanded approach
is within that band, so a factor costs about the time its late impulse keeps the command away from
the goal: a zero-vibration pair on a mode that rings (A2 near 0.5 at half its period) costs nearly
its T2 (0.03-0.05 s on the arm), a pair on the position loop's heavily damped transient (A2 under
0.1 at a few ms) costs nothing (docs/results/arm_learning.md).

That cost is predictable before any trial, from the command alone (:func:`time_cost`): the shaped
command's own settling (every joint within a band of its goal) moves as the flange's does. This
module chooses, from the components identified in a move's residual (:class:`Component`: the
modes that ring and the loop's damped poles), the two-impulse factor with the least predicted
residual among those whose predicted time cost is within a tolerance (:func:`paying_factor`); a
partial pair (A1 above the zero-vibration value) on a ringing mode is one of the candidates, so
where the full pair costs too much the factor takes what the time allows. The learner then tries
it and keeps it only when the measured cycle pays (:func:`shaper_nodes.core.learning.moves.pays`).

ROS-free: the reproduction (``reproductions.arm_learning``) and the learner node can call it.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from shaper_nodes.core.shaping import Mode, Shaper
from shaper_nodes.core.shaping.families import convolve

from .params import ListError, ListParams

__all__ = ["EXTRA_DAMPED", "SERVO_SKIP", "Component", "PaybackChoice", "component_energy", "components", "lowest_first",
           "paying_factor", "predicted_residual", "settle_crossing", "time_cost"]

#: A1 grid of the candidates, from the zero-vibration value up to this (A2 = 0.02: nearly no factor)
A1_MAX = 0.98
#: candidates per parameter: T2 over the band, A1 from the zero-vibration value to A1_MAX
GRID = 9
#: the modes that ring are identified from this long after the commanded end, s (the position loop's transient,
#: 50 Hz at damping 0.5-0.7 on the arm, has decayed by then); the loop's poles from the commanded end itself
SERVO_SKIP = 0.1
#: :func:`components`' ``extra_damped`` for a move over a schedule: fits from the commanded end with up to this many
#: more modes than the modes that ring fill (on the arm's pick->home three ring, and the loop's transient, 58 Hz at
#: damping 0.49, is found only in a fit of four; docs/results/arm_learning.md)
EXTRA_DAMPED = 2


@dataclass(frozen=True)
class Component:
    """A damped exponential identified in a residual: natural frequency omega (rad/s), damping ratio zeta,
    and its amplitude (m/s^2) at the start of the residual window (the commanded motion's end)."""

    omega: float
    zeta: float
    amplitude: float

    def __post_init__(self) -> None:
        for name in ("omega", "zeta", "amplitude"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ListError(f"component {name} must be a finite number, got {v!r}")
        if self.omega <= 0 or not 0 <= self.zeta < 1 or self.amplitude < 0:
            raise ListError(f"a component needs omega > 0 rad/s, 0 <= zeta < 1 and amplitude >= 0, got"
                            f" {self.omega!r}, {self.zeta!r}, {self.amplitude!r}")

    @property
    def pole(self) -> complex:
        """The pole -zeta omega + j omega sqrt(1 - zeta^2), 1/s."""
        return complex(-self.zeta * self.omega, self.omega * math.sqrt(1.0 - self.zeta**2))

    @property
    def hz(self) -> float:
        return self.omega / (2.0 * math.pi)


def components(times: np.ndarray, signal: np.ndarray, commanded_end: float, servo_zeta: float,
               max_modes: int = 3, min_hz: float = 2.0, extra_damped: int = 0) -> list[Component]:
    """The damped exponentials of a residual (the modes that ring and the loop's damped poles), amplitudes at
    ``commanded_end`` (m/s^2).

    The modes that ring (damping below ``servo_zeta``) are identified
    (:func:`~shaper_nodes.core.identification.identify`) from :data:`SERVO_SKIP` after the commanded end, their
    amplitudes carried back to it by their decay; the others of a fit from the commanded end itself (the loop's
    damped poles) are added where no component found is within 5 % of them. An empty list when nothing is found.

    With ``extra_damped`` > 0 the fit from the commanded end is also made with up to that many more modes than
    ``max_modes`` (each adding only the damped ones, damping >= ``servo_zeta``): where the modes that ring fill a
    fit of ``max_modes`` (on the arm's pick->home, three of them), the loop's transient, a few ms long, is found
    only beside them.

    Parameters
    ----------
    times : (N,) array
        Sample times, s.
    signal : (N,) or (N, k) array
        The accelerometer, m/s^2.
    commanded_end : float
        When the commanded motion ended, s (same clock as ``times``).
    servo_zeta : float
        Damping ratio from which an eigenvalue is the position loop's, not a mode's.
    """
    from shaper_nodes.core.identification import IdentificationError, identify

    t = np.asarray(times, dtype=float)
    y = np.asarray(signal, dtype=float)

    if not (isinstance(extra_damped, int) and 0 <= extra_damped <= 8 - max_modes):
        raise ListError(f"extra_damped must be an integer from 0 to {8 - max_modes} (8 modes at most in a fit),"
                        f" got {extra_damped!r}")

    def found(skip: float, n: int = max_modes) -> list:  # type: ignore[type-arg]
        sel = t > commanded_end + skip
        try:
            return [f for f in identify(t[sel], y[sel], max_modes=n) if f.hz > min_hz]
        except IdentificationError:
            return []

    out = [Component(f.omega, f.zeta, f.amplitude * math.exp(f.zeta * f.omega * SERVO_SKIP))
           for f in found(SERVO_SKIP) if f.zeta < servo_zeta]
    for k in range(extra_damped + 1):
        for f in found(0.0, max_modes + k):
            if (k == 0 or f.zeta >= servo_zeta) and all(abs(f.omega / c.omega - 1.0) > 0.05 for c in out):
                out.append(Component(f.omega, min(f.zeta, 0.95), f.amplitude))
    return out


def component_energy(c: Component, window: float = 1.0) -> float:
    """The component's mean square over a window of ``window`` s from its start, (m/s^2)^2
    (a decaying sinusoid's: amplitude^2 / 2 times the mean of exp(-2 sigma t))."""
    s = c.zeta * c.omega
    mean = 1.0 if s * window < 1e-12 else (1.0 - math.exp(-2.0 * s * window)) / (2.0 * s * window)
    return 0.5 * c.amplitude**2 * mean


def _factor_at(params: ListParams, pole: complex, shifted: bool = False) -> complex:
    """A component's amplitude ratio with the factor, at the same time after the move's start
    (:func:`~.params.lti_factor`: A1 + A2 exp(-p T2)). Not credited: that the residual window, which starts at the
    shaped command's end, starts T2 later with the factor (what a component decays meanwhile is no cancellation;
    a partial pair that moves the window would otherwise look as if it cancelled).

    With ``shifted`` the ratio at the shaped command's end instead, T2 later (A1 exp(p T2) + A2): what the window
    from there measures. On a heavily damped pole the unshifted ratio grows as exp(zeta omega T2) (the late
    impulse's transient carried back to before it starts: e^9.7 for a 50 ms pair on the loop's 50 Hz pole at
    damping 0.6); the shifted one stays below 1. Used with no schedule, where the time is weighed apart
    (:mod:`.settle`)."""
    if shifted:
        return params.a1 * cmath.exp(pole * params.t2) + params.a2
    return params.a1 + params.a2 * cmath.exp(-pole * params.t2)


def predicted_residual(components: Sequence[Component], params: ListParams | None, window: float = 1.0,
                       shifted: bool = False) -> float:
    """The residual RMS (m/s^2) the components predict with the factor ``params`` convolved in (None: without):
    each component's amplitude times the factor's residual ratio at its pole (:func:`_factor_at`, ``shifted``), the
    components' mean squares added (their cross terms left out)."""
    total = 0.0
    for c in components:
        ratio = 1.0 if params is None else abs(_factor_at(params, c.pole, shifted))
        total += component_energy(c, window) * ratio**2
    return math.sqrt(total)


def settle_crossing(times: np.ndarray, positions: np.ndarray, after: float, tolerance: float) -> float:
    """When every joint enters, for good, the band of ``tolerance`` about its last value, s (not before ``after``):
    :func:`~shaper_nodes.core.shaping.vibration.settle_time` between samples, the last crossing interpolated
    linearly (the sampled settling time is the next sample at or after it).

    Parameters
    ----------
    times : (N,) array
        Sample times, s, increasing.
    positions : (N, J) array
        Joint positions (rad).
    after : float
        Earliest time to return, s.
    tolerance : float
        The band, rad.
    """
    t = np.asarray(times, dtype=float)
    p = np.asarray(positions, dtype=float).reshape(t.size, -1)
    err = np.abs(p - p[-1])
    idx = np.flatnonzero(np.any(err > tolerance, axis=1))
    if idx.size == 0:
        return float(after)
    k = int(idx[-1])
    if k + 1 >= t.size:
        return float(max(t[-1], after))
    out = err[k] > tolerance
    drop = err[k, out] - err[k + 1, out]
    frac = np.where(drop > 0, (err[k, out] - tolerance) / np.where(drop > 0, drop, 1.0), 1.0)
    return float(max(t[k] + float(np.max(np.clip(frac, 0.0, 1.0))) * (t[k + 1] - t[k]), after))


def time_cost(times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None, base: Shaper | None,
              factor: ListParams | Shaper, rate: float, tolerance: float, interpolate: bool = False) -> float:
    """How much later (s) the shaped command settles with ``factor`` convolved into ``base`` than with ``base``
    alone: the first time after the planned end from which every joint stays within ``tolerance`` (rad) of its
    goal (:func:`~shaper_nodes.core.shaping.vibration.settle_time` on the command shaped at ``rate`` Hz).

    With ``interpolate`` the two settling times are taken between samples (:func:`settle_crossing`), so the cost
    is not rounded to the command's samples: a cost of at most one sample so predicted moves the flange's sampled
    settling by at most one sample, where a sampled cost of one sample may be up to two (measured on the arm:
    home->pick, a pair predicted at +2 ms on the samples measured +4 ms; docs/results/arm_learning.md).

    Parameters
    ----------
    times, positions, velocities
        The move's planned waypoints (s from its start; (N, J) rad; (N, J) rad/s or None).
    base : Shaper or None
        The move's base shaper (the schedule at its goal; None: unshaped).
    factor : ListParams or Shaper
        The two-impulse factor, or any impulse sequence (e.g. the factors kept so far and a new one, convolved).
    rate : float
        Command rate, Hz.
    tolerance : float
        The settling band in joint space, rad (the flange's band over the arm's reach).
    """
    from shaper_nodes.core.shaping.fir import discretize
    from shaper_nodes.core.shaping.trajectory import shape_trajectory
    from shaper_nodes.core.shaping.vibration import settle_time

    t = np.asarray(times, dtype=float)
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ListError(f"tolerance must be a finite number > 0 rad, got {tolerance!r}")
    end = float(t[-1])

    def settled(shaper: Shaper) -> float:
        out = shape_trajectory(t, positions, discretize(shaper, rate), rate, velocities)
        if interpolate:
            return settle_crossing(out.times, out.positions, end, tolerance)
        return settle_time(out.times, out.positions, end, tolerance)

    pair = factor.shaper() if isinstance(factor, ListParams) else factor
    if base is None:
        with_factor = pair
        alone = Shaper(np.array([1.0]), np.array([0.0]), "custom")
    else:
        a, tt = convolve((base.amplitudes, base.times), (pair.amplitudes, pair.times))
        with_factor, alone = Shaper(a, tt, "custom"), base
    return settled(with_factor) - settled(alone)


@dataclass(frozen=True)
class PaybackChoice:
    """The factor :func:`paying_factor` chose: its parameters, the component it was designed on, the predicted
    residual with and without it (m/s^2) and its predicted time cost (s); ``full`` whether it is the component's
    zero-vibration pair (False: a partial pair, what the time allows)."""

    params: ListParams
    component: Component
    predicted: float
    without: float
    cost_s: float
    full: bool


def paying_factor(components: Sequence[Component], cost: Callable[[ListParams], float], tolerance_s: float,
                  band: float = 0.1, a1_bounds: tuple[float, float] = (0.5, A1_MAX), window: float = 1.0,
                  gain: float = 0.95, targets: Sequence[Component] | None = None,
                  shifted: bool = False) -> PaybackChoice | None:
    """The two-impulse factor with the least predicted residual among those predicted to cost at most
    ``tolerance_s`` of move + settle time (module docstring); None if none is predicted to lower the residual
    below ``gain`` times its level without a factor.

    Candidates, per component: T2 that put the pair's frequency within +-``band`` of the component's damped one
    (its own included; so the factor stays on it, as :meth:`~.params.ListParams.t2_band`), A1 from its
    zero-vibration value (clipped to ``a1_bounds``) up to ``a1_bounds[1]`` (a partial pair: less amplitude late,
    less delay). Ranked by
    :func:`predicted_residual`; ``cost`` (e.g. :func:`time_cost` bound to the move) is called on them in that
    order until one is within ``tolerance_s``. With ``targets`` the candidates are designed on those components
    only (the predicted residual is still over all of them; :func:`lowest_first`); ``shifted``: the residual
    predicted from the shaped command's end (:func:`_factor_at`).
    """
    if not components:
        return None
    lo, hi = a1_bounds
    without = predicted_residual(components, None, window)
    ranked: list[tuple[float, ListParams, Component, bool]] = []
    for c in components if targets is None else targets:
        zv = ListParams.from_mode(Mode(c.omega, c.zeta))
        a1_start = min(max(zv.a1, lo), hi)
        for k, a1 in enumerate(np.linspace(a1_start, hi, GRID)):
            for t2 in zv.t2 / (1.0 + np.linspace(-band, band, GRID)):  # the frequency within the band, its own in it
                p = ListParams(float(a1), float(t2))
                ranked.append((predicted_residual(components, p, window, shifted), p, c, k == 0 and a1_start == zv.a1))
    ranked.sort(key=lambda x: x[0])
    for pred, p, c, full in ranked:
        if pred >= gain * without:
            return None
        dt = cost(p)
        if dt <= tolerance_s:
            return PaybackChoice(p, c, pred, without, dt, full)
    return None


def lowest_first(components: Sequence[Component], servo_zeta: float) -> list[Component]:
    """The components in the order a move with no schedule targets them (the reproduction's ``_ringing``): the modes
    that ring (damping below ``servo_zeta``), lowest first, then the damped ones (the loop's transient), lowest
    first."""
    ringing = sorted((c for c in components if c.zeta < servo_zeta), key=lambda c: c.omega)
    return ringing + sorted((c for c in components if c.zeta >= servo_zeta), key=lambda c: c.omega)
