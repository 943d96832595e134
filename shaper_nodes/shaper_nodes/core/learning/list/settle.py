"""A move's move + settle time from its accelerometer, measured and predicted, for a move with no schedule.

With a schedule at a move's goal the shaped command's own settling stands for the flange's (the schedule
cancels the modes, so the command's tail sets the time): :func:`~.payback.time_cost` predicts a factor's cost
from the command alone. With no schedule (a move learned from its unshaped cycle, issue 31's "LIST per move with
no calibration") it does not: the unshaped command settles at its planned end while the flange rings for up to a
second after it, so the vibration, not the command, sets the move + settle time, and a factor that cancels a
ringing mode (tens of ms late) shortens it. Against the command every such factor "costs" its delay, and nearly
nothing is chosen (docs/results/arm_demo.md, "More than one factor per move").

This module measures the time on the accelerometer instead (:func:`imu_settle`: when the deviation from its
settled value enters a band for good: the flange's 0.05 mm converted at the move's lowest mode) and predicts a
factor's cost from the components identified in the move's reference cycle (:func:`unshaped_time_cost`: the
later of the command's settling and the components' envelope, with the factor and without). The learner keeps a
factor only when its measured time is no longer than its reference's (one 2 ms sample of tolerance).

The factor (:func:`lowest_paying`): a full zero-vibration pair on each ringing mode, lowest first, one per mode
(:func:`full_pair`: as the schedule shapes each mode with one design, and the reproduction's ``list`` case); when
every ringing mode has one, the pair with the least predicted residual on the lowest mode still ringing, a partial
pair allowed (what tunes a mode a full pair left ringing). With partial pairs from the start (session 10, H2) one
mode took two or three of a move's four factors and the others were never reached (docs/results/arm_demo.md).

ROS-free.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable, Sequence

import numpy as np

from shaper_nodes.core.shaping import Mode

from .params import ListError, ListParams
from .payback import A1_MAX, Component, PaybackChoice, lowest_first, paying_factor, predicted_residual

__all__ = ["COVERED", "DEFAULT_BAND", "DEFAULT_HZ", "HORIZON", "SETTLED", "SMOOTH", "covered", "envelope_settle",
           "full_pair", "imu_settle", "lowest_paying", "unshaped_time_cost"]

#: the frequency a move's settled band is converted at when no mode is identified in its first reference, Hz
DEFAULT_HZ = 10.0
#: the accelerometer's settled band at :data:`DEFAULT_HZ`, m/s^2: the flange's 0.05 mm (x = a / (2 pi f)^2, the
#: arm's lowest mode at home; :func:`~shaper_nodes.core.learning.speed.acceleration_tolerance`)
DEFAULT_BAND = 5e-5 * (2.0 * math.pi * DEFAULT_HZ) ** 2
#: the window of :func:`imu_settle`'s RMS envelope, s (a period of the arm's 10 Hz mode)
SMOOTH = 0.1
#: :func:`imu_settle`'s settled value is the accelerometer's mean over this last part of its span, s
SETTLED = 0.5
#: a kept factor is on a mode when its pair's frequency is within this of the mode's damped one (relative: the
#: factors' band, so a partial pair at the band's edge counts as on its mode)
COVERED = 0.1
#: longest settling an envelope is followed for, s after the commanded end
HORIZON = 10.0


def imu_settle(times: np.ndarray, accel: np.ndarray, after: float, end: float, band: float,
               smooth: float = SMOOTH) -> float:
    """When the accelerometer settles for good, s (same clock as ``times``; not before ``after``): the sample after
    the last one in [``after``, ``end``] whose envelope exceeds ``band`` (m/s^2); ``after`` if none does. The
    envelope: sqrt(2) times the RMS, over ``smooth`` s centred on the sample, of the deviation from the settled
    value (the axes' magnitude; the mean over the span's last :data:`SETTLED` s, not the whole span's, which a
    stacked command's decelerating tail, 0.2 s of it, would bias by more than the band): a sinusoid's amplitude,
    where the sample's own deviation would let the noise's peaks set the time (a mode decaying at 2/s, 10 Hz at
    damping 0.033, crosses the band 0.15 s later for a noise peak of 0.05 m/s^2; noise in quadrature under the RMS
    moves it by a few ms). A move that rings to ``end`` settles at ``end`` (at most).

    Parameters
    ----------
    times : (N,) array
        Sample times, s, increasing.
    accel : (N,) or (N, k) array
        The accelerometer, m/s^2.
    after, end : float
        The span: from the commanded motion's planned end to the cycle's end, s.
    band : float
        The settled band, m/s^2.
    """
    if not (math.isfinite(band) and band > 0):
        raise ListError(f"band must be a finite number > 0 m/s^2, got {band!r}")
    t = np.asarray(times, dtype=float)
    a = np.asarray(accel, dtype=float).reshape(t.size, -1)
    sel = (t >= after) & (t <= end)
    if not np.any(sel):
        raise ListError(f"no accelerometer sample from {after:.3f} s to {end:.3f} s")
    ts, As = t[sel], a[sel]
    rest = As[ts >= ts[-1] - SETTLED]
    sq = np.sum((As - rest.mean(axis=0)) ** 2, axis=1)
    csum = np.concatenate([[0.0], np.cumsum(sq)])
    lo = np.searchsorted(ts, ts - 0.5 * smooth, side="left")
    hi = np.searchsorted(ts, ts + 0.5 * smooth, side="right")
    env = np.sqrt(2.0 * (csum[hi] - csum[lo]) / (hi - lo))
    idx = np.flatnonzero(env > band)
    if idx.size == 0:
        return float(after)
    k = int(idx[-1])
    return float(ts[k + 1] if k + 1 < ts.size else ts[-1])


def envelope_settle(components: Sequence[Component], band: float, factor: ListParams | None = None) -> float:
    """When the components' envelope (each one's amplitude decaying as its pole, summed: an upper bound of the
    residual) falls within ``band`` (m/s^2) for good, s after the commanded end they were identified from; 0 if it
    starts within; :data:`HORIZON` at most (a component that does not decay).

    With a ``factor``: before its T2 the response is A1 times the components (the late impulse has not acted);
    from T2 on each component's amplitude is A1 exp(p t) + A2 exp(p (t - T2)) (its pole p), the envelope of which is
    |A1 + A2 exp(-p T2)| exp(-zeta omega t).
    """
    sig = np.array([c.zeta * c.omega for c in components])
    amp = np.array([c.amplitude for c in components])
    if amp.size == 0:
        return 0.0
    a1, t2 = (1.0, 0.0) if factor is None else (factor.a1, factor.t2)
    late = amp if factor is None else amp * np.array([abs(factor.a1 + factor.a2 * cmath.exp(-c.pole * factor.t2))
                                                      for c in components])

    def crossing(scale: np.ndarray, lo: float, hi: float) -> float | None:
        """The crossing of sum(scale exp(-sig t)) with the band in [lo, hi]; None if it is within at lo."""
        def env(t: float) -> float:
            return float(np.sum(scale * np.exp(-sig * t)))

        if env(lo) <= band:
            return None
        if env(hi) > band:
            return hi
        while hi - lo > 1e-5:  # a sum of decaying exponentials: one crossing
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if env(mid) > band else (lo, mid)
        return hi

    after = crossing(late, t2, HORIZON)
    if after is not None:
        return after
    before = crossing(a1 * amp, 0.0, t2) if t2 > 0 else None
    return 0.0 if before is None else before


def unshaped_time_cost(components: Sequence[Component], band: float, kept: Sequence[ListParams],
                       command_cost: Callable[[tuple[ListParams, ...]], float]) -> Callable[[ListParams], float]:
    """The predicted move + settle cost (s) of a factor ``p`` over the ``kept`` ones, for a move with no schedule.

    The move settles at the later of its command's settling and its vibration's: predicted with the factors as
    ``max(command_cost(kept + (p,)), D + envelope_settle(components, band, p))`` and without as
    ``max(command_cost(kept), D + envelope_settle(components, band))``, in s after the planned end; D is the kept
    factors' duration (the reference's commanded end, where the ``components`` were identified from, is D after
    the planned end). The cost is their difference: negative where the factor cancels what rings longest.

    Parameters
    ----------
    components : sequence of Component
        What rings in the reference cycle (with the kept factors in place), amplitudes at its commanded end.
    band : float
        The settled band, m/s^2 (:func:`imu_settle`'s).
    kept : sequence of ListParams
        The factors kept so far.
    command_cost : callable
        The command's settling with factors, s after the planned end (e.g. :func:`~.payback.time_cost` of the move's
        planned goal, unshaped base, the factors convolved); called with () for the command alone.
    """
    kept = tuple(kept)
    delay = float(sum(p.t2 for p in kept))
    without = max(command_cost(kept), delay + envelope_settle(components, band))

    def cost(p: ListParams) -> float:
        return max(command_cost((*kept, p)), delay + envelope_settle(components, band, p)) - without

    return cost


def covered(c: Component, kept: Sequence[ListParams]) -> bool:
    """Whether a kept factor is on the component: its pair's frequency (1 / (2 T2)) within :data:`COVERED` of the
    component's damped one."""
    hz = c.hz * math.sqrt(1.0 - c.zeta**2)
    return any(abs(1.0 / (2.0 * p.t2 * hz) - 1.0) <= COVERED for p in kept)


def full_pair(components: Sequence[Component], cost: Callable[[ListParams], float], tolerance_s: float,
              servo_zeta: float, kept: Sequence[ListParams] = (), gain: float = 0.95) -> PaybackChoice | None:
    """The zero-vibration pair (A1 = 1 / (1 + K), K from the identified damping, T2 half the damped period) on the
    lowest mode that rings (damping below ``servo_zeta``) no ``kept`` factor is on (:func:`covered`), of those
    predicted to lower the residual (from the shaped command's end) below ``gain`` times its level and to cost at
    most ``tolerance_s``; None if none is. One full pair per ringing mode, as the schedule shapes each mode with
    one design (the reproduction's ``list`` case: a ZV pair on each ringing mode)."""
    without = predicted_residual(components, None)
    for c in lowest_first(components, servo_zeta):
        if c.zeta >= servo_zeta or covered(c, kept):
            continue
        zv = ListParams.from_mode(Mode(c.omega, c.zeta))
        p = ListParams(min(zv.a1, A1_MAX), zv.t2)
        pred = predicted_residual(components, p, shifted=True)
        if pred < gain * without:
            dt = cost(p)
            if dt <= tolerance_s:
                return PaybackChoice(p, c, pred, without, dt, p == zv)
    return None


def lowest_paying(components: Sequence[Component], cost: Callable[[ListParams], float], tolerance_s: float,
                  servo_zeta: float, band: float = 0.1,
                  kept: Sequence[ListParams] | None = None) -> PaybackChoice | None:
    """The factor for a move with no schedule: with ``kept`` given (the factors kept so far), first a full pair on
    the lowest ringing mode none of them is on (:func:`full_pair`); then (every ringing mode has one, or none is
    predicted to pay; ``kept`` None: at once) on the lowest mode still ringing that a factor predicted to pay is
    found for (:func:`~.payback.lowest_first`: the modes that ring lowest first, then the damped ones), the one
    with the least predicted residual among those predicted to cost at most ``tolerance_s``
    (:func:`~.payback.paying_factor` with that component as its target, the residual predicted from the shaped
    command's end, a partial pair allowed: what tunes the mode a full pair left ringing; ``cost`` e.g.
    :func:`unshaped_time_cost`); None if no component has one."""
    if kept is not None:
        pick = full_pair(components, cost, tolerance_s, servo_zeta, kept)
        if pick is not None:
            return pick
    for target in lowest_first(components, servo_zeta):
        pick = paying_factor(components, cost, tolerance_s, band=band, targets=[target], shifted=True)
        if pick is not None:
            return pick
    return None
