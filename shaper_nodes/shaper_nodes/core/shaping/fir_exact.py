"""The ``exact`` discretisation's correction of the split taps (core/shaping/fir.py, "Discretisation"): the least
change that meets the shaper's conditions at its design modes exactly, and its refusals.

Split out of fir.py (session 13) with no change of behaviour.
"""

from __future__ import annotations

import numpy as np

from .types import Shaper

#: derivative order of the conditions each family meets at its design modes (``exact``)
_EXACT_ORDER = {"zv": 0, "zvd": 1, "zvdd": 2, "mzv": 0, "si": 0, "custom": 0,
                "ei": 1, "2hump_ei": 1, "3hump_ei": 1}


def _exact_order(shaper: Shaper) -> int:
    if shaper.family == "zvdn":
        return int(shaper.params.get("derivative_order", 0))
    return _EXACT_ORDER.get(shaper.family, 0)


#: the most a design mode may decay over one command period, zeta omega Ts, for ``exact``: the conditions'
#: rows hold exp(zeta omega (t - t_last)) for taps up to one period after the last impulse, and
#: exp(700) ~ 1e304 leaves them finite (exp overflows beyond ~709.8)
MAX_EXACT_DECAY = 700.0
#: the largest phase omega_d (t_n + Ts) (rad) a design mode may turn through over the shaper for ``exact``:
#: beyond 2**53 a float phase has no fraction left, its cos and sin mean nothing (and near 1.8e308 it overflows)
MAX_EXACT_PHASE = 2.0**53


def _exact_taps(shaper: Shaper, rate: float, split: np.ndarray, base: np.ndarray) -> np.ndarray:
    """The split taps ``split`` corrected to meet the shaper's conditions at its modes (``exact``)."""
    if not shaper.modes or split.size == 1:
        return split
    for i, mode in enumerate(shaper.modes):  # before any exp() of it
        decay = mode.zeta * mode.omega / rate
        if not decay <= MAX_EXACT_DECAY:
            raise ValueError(
                f"exact discretisation of the {shaper.family} shaper at {rate:g} Hz cannot hold design mode {i}"
                f" ({mode.hz:.6g} Hz, damping ratio {mode.zeta:g}): it decays by zeta omega Ts = {decay:.3g} over"
                f" one command period, beyond the limit of {MAX_EXACT_DECAY:g}; use 'split'")
        phase = mode.damped_omega * (float(shaper.times[-1]) + 1.0 / rate)
        if not phase <= MAX_EXACT_PHASE:
            raise ValueError(
                f"exact discretisation of the {shaper.family} shaper at {rate:g} Hz cannot hold design mode {i}"
                f" ({mode.hz:.6g} Hz, damping ratio {mode.zeta:g}): it turns through omega_d (t_n + Ts) = {phase:.3g}"
                f" rad over the shaper, beyond the limit of {MAX_EXACT_PHASE:.4g} rad (2**53); use 'split'")
    order = _exact_order(shaper)
    amps, times = np.asarray(shaper.amplitudes), np.asarray(shaper.times)
    span = max(float(times[-1]), 1.0 / rate)

    def system(taps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = taps / rate
        rows, rhs = [np.ones(taps.size)], [1.0]
        for mode in shaper.modes:
            s = complex(-mode.zeta * mode.omega, mode.damped_omega)
            # scaled by exp(s t_n) and span^-n so every row is of order one
            fir_row = np.exp(-s * (t - times[-1]))
            cont = amps * np.exp(-s * (times - times[-1]))
            for n in range(order + 1):
                row = fir_row * (-t / span) ** n
                target = complex(np.sum(cont * (-times / span) ** n))
                rows += [row.real, row.imag]
                rhs += [target.real, target.imag]
        return np.array(rows), np.array(rhs)

    positive = bool(np.all(amps >= 0.0))

    def solve(taps: np.ndarray) -> np.ndarray | None:
        """Least change from the split on ``taps`` meeting the conditions (and >= 0 for a positive shaper)."""
        a, b = system(taps)
        g0 = split[taps]
        g: np.ndarray = g0 + np.linalg.lstsq(a, b - a @ g0, rcond=None)[0]
        if np.max(np.abs(a @ g - b)) > 1e-9:
            return None
        if not positive or np.min(g) >= -1e-12:
            return g
        # the same least change with the taps bounded below by 0 (a small convex QP), then polished on
        # its support so the conditions hold to rounding
        from scipy.optimize import minimize

        res = minimize(lambda x: float(np.sum((x - g0) ** 2)), np.clip(g, 0.0, None), jac=lambda x: 2.0 * (x - g0),
                       bounds=[(0.0, None)] * taps.size, method="SLSQP", options={"ftol": 1e-15, "maxiter": 500},
                       constraints=[{"type": "eq", "fun": lambda x: a @ x - b, "jac": lambda x: a}])
        keep = res.x > 1e-9
        if not res.success or not np.any(keep):
            return None
        sub = res.x[keep] + np.linalg.lstsq(a[:, keep], b - a[:, keep] @ res.x[keep], rcond=None)[0]
        if np.max(np.abs(a[:, keep] @ sub - b)) > 1e-9 or np.min(sub) < -1e-12:
            return None
        g = np.zeros(taps.size)
        g[keep] = sub
        return g

    occupied = np.flatnonzero(split)
    nearby = np.concatenate([base - 1, base, base + 1])
    wider = np.union1d(occupied, nearby[nearby >= 0])
    for taps in (occupied, wider):
        g = solve(taps)
        if g is not None:
            break
    else:
        worst = max(shaper.modes, key=lambda m: m.omega)
        raise ValueError(
            f"exact discretisation of the {shaper.family} shaper at {rate:g} Hz has no "
            f"{'non-negative ' if positive else ''}solution on the samples next to its impulses "
            f"(highest mode {worst.hz:.3g} Hz, omega Ts = {worst.omega / rate:.2f}); use 'split'")
    out = np.zeros(max(int(taps.max()) + 1, split.size))
    out[taps] = g
    out[np.abs(out) < 1e-15] = 0.0
    return out
