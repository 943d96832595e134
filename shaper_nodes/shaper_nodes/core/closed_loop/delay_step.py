"""The exact step response of the time-delay feedback loop of seed 001 (method of steps), free of ROS: overshoot,
peak and settling time (:func:`exact_step_response`), a horizon long enough to judge them
(:func:`step_response_with_horizon`), the performance beside both stability checks (:func:`step_performance`)
and the real frequencies whose overshoot meets a limit (:func:`overshoot_interval`). The equations:
:mod:`.time_delay`, which hands these names on."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .delay_stability import (
    StableInterval,
    TimeDelayError,
    _check,
    growth_rate,
    ppusmd_gains,
    stable_interval,
)

__all__ = ["DEFAULT_BAND", "MAX_ROUNDING_ERROR", "OvershootInterval", "OvershootSegment", "StepPerformance",
           "StepResponse", "exact_step_response", "overshoot_interval", "step_performance",
           "step_response_with_horizon"]


# ------------------------------------------------------------------------------------------------
# exact step response of the continuous loop (method of steps)


DEFAULT_BAND = 0.02
"""Default settling band: |y - 1| <= 2 % of the unit step."""


@dataclass(frozen=True)
class StepResponse:
    """Exact unit-step response of the continuous delay loop (see :func:`exact_step_response`).

    Attributes
    ----------
    t, y : np.ndarray
        Time (s) and output y on the grid (``points_per_delay`` per T, both ends of every interval).
    peak_time, peak : float
        Time (s) and value of the largest output over the horizon, located to machine precision as
        a zero of y'.
    band : float
        Settling band, a fraction of the unit step.
    settling_time : float or None
        First time (s) after which |y - 1| <= ``band`` up to the end of the horizon (the last exit
        from the band, located by Brent's method within its grid cell); None if |y - 1| > band at the
        end of the horizon (not settled within it).
    tail_deviation, earlier_deviation : float
        Largest |y - 1| over the last window of the horizon, and over the window before it; a window is
        the last quarter of the horizon but at least one period 2 pi / min(w_A, w_R). NaN for
        ``earlier_deviation`` if the horizon is shorter than two windows.
    rounding_error : float
        Largest difference of y between the history re-solved on an interval and the same history
        solved on the interval before (the method of steps re-solves the whole past on every interval):
        an estimate of the accumulated rounding error, which grows geometrically with the number of
        intervals (fastest for small w_A T, where the gains are large).
    accuracy_limited : bool
        True if the horizon was cut short because the next interval's rounding error would have passed
        ``max_rounding_error``.
    """

    t: np.ndarray
    y: np.ndarray
    peak_time: float
    peak: float
    band: float = DEFAULT_BAND
    settling_time: float | None = None
    tail_deviation: float = math.nan
    earlier_deviation: float = math.nan
    rounding_error: float = 0.0
    accuracy_limited: bool = False

    @property
    def overshoot(self) -> float:
        """Overshoot of the unit step over the horizon, as a fraction (peak - 1)."""
        return self.peak - 1.0

    @property
    def horizon(self) -> float:
        """End of the computed response, s."""
        return float(self.t[-1])

    @property
    def settled(self) -> bool:
        """Whether |y - 1| is inside the band from some time on up to the end of the horizon."""
        return self.settling_time is not None

    @property
    def decaying(self) -> bool:
        """Whether the deviation over the last window of the horizon is no larger than over the window
        before (or at rounding level): the horizon reaches the loop's decay. False if the horizon is
        shorter than two windows (two periods of the slower of w_A, w_R)."""
        return self.tail_deviation <= self.earlier_deviation or self.tail_deviation <= 1e-9

    @property
    def overshoot_bound(self) -> float:
        """Upper bound of the overshoot over all t >= 0, as a fraction: max(overshoot, tail deviation) if
        the response is :attr:`decaying` (later excursions are then no larger than the tail's), else
        inf. The true overshoot lies in [overshoot, overshoot_bound]."""
        return max(self.overshoot, self.tail_deviation) if self.decaying else math.inf

    @property
    def peak_captured(self) -> bool:
        """Whether the peak over the horizon is the peak for all t >= 0 (the response is decaying and
        its tail stays below the peak), i.e. :attr:`overshoot` is the loop's overshoot."""
        return self.decaying and self.tail_deviation <= max(self.overshoot, 0.0) + 1e-12


def _method_of_steps(omega_a: float, delay: float, omega_r: float, intervals: int, points_per_delay: int,
                     coef: tuple[float, float, float]) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """Yield, for each interval n = 0 .. intervals - 1 of length T, (n, m, taus, xs): the stacked-state
    matrix m of that interval (blocks z_0 .. z_n of [y, y', yhat, yhat'] and the constant reference as
    the last state), the grid taus in [0, T] and the states xs on it (one row per tau). The output y of
    the interval is ``xs[:, 4 n]`` and y' is ``xs[:, 4 n + 1]``."""
    prev_end = np.zeros(0)  # z_0 .. z_{n-1} at tau = T of the previous interval
    taus = np.linspace(0.0, delay, int(points_per_delay) + 1)
    for n in range(int(intervals)):
        dim = 4 * (n + 1) + 1  # blocks z_0 .. z_n and the constant reference 1
        m = np.zeros((dim, dim))
        one = dim - 1
        for j in range(n + 1):
            b = 4 * j
            m[b, b + 1] = 1.0
            m[b + 1, b] = -omega_r**2
            m[b + 2, b + 3] = 1.0
            m[b + 3, b + 2] = -omega_a**2
            # u on block j: sum_i A_i v(jT + tau - iT), v = 1 - y + yhat on blocks j - i >= 0, 0 before the step
            for i, a in enumerate(coef):
                src = j - i
                if src < 0:
                    continue
                for row, w2 in ((b + 1, omega_r**2), (b + 3, omega_a**2)):
                    m[row, one] += w2 * a
                    m[row, 4 * src] -= w2 * a
                    m[row, 4 * src + 2] += w2 * a
        x0 = np.zeros(dim)
        x0[4:4 * (n + 1)] = prev_end
        x0[one] = 1.0
        from scipy.linalg import expm  # on first use

        step = expm(m * (taus[1] - taus[0]))
        xs = np.empty((taus.size, dim))
        xs[0] = x0
        for i in range(1, taus.size):
            xs[i] = step @ xs[i - 1]
        yield n, m, taus, xs
        prev_end = xs[-1, :4 * (n + 1)]


def _advance(m: np.ndarray, x: np.ndarray, dtau: float) -> np.ndarray:
    """The state ``dtau`` later of x' = m x from ``x`` (matrix exponential)."""
    from scipy.linalg import expm  # on first use

    out: np.ndarray = expm(m * dtau) @ x
    return out


def _cell_maximum(m: np.ndarray, x: np.ndarray, t0: float, t1: float, index: int) -> tuple[float, float]:
    """(tau, y) of the local maximum of state ``index`` (y) inside the grid cell [t0, t1] whose state
    at t0 is ``x``: where its derivative (state ``index + 1``) passes zero, found by Brent."""
    from scipy.optimize import brentq

    def slope(tau: float) -> float:
        return float(_advance(m, x, tau - t0)[index + 1])

    tau = brentq(slope, t0, t1, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return tau, float(_advance(m, x, tau - t0)[index])


def _check_band(band: float) -> None:
    if not (isinstance(band, (int, float)) and math.isfinite(band) and 0.0 < band < 1.0):
        raise TimeDelayError(f"settling band must be a fraction in (0, 1), got {band!r}")


def exact_step_response(omega_a: float, delay: float, omega_r: float, intervals: int = 30,
                        points_per_delay: int = 400, gains: tuple[float, float, float] | None = None,
                        band: float = DEFAULT_BAND, max_rounding_error: float | None = None) -> StepResponse:
    """Unit-step response of the continuous loop of seed 001 (real plant w_R^2 / (s^2 + w_R^2), IMC
    controller with the internal model w_A^2 / (s^2 + w_A^2), exact delays T and 2T), computed by the
    method of steps: on the n-th interval [nT, (n+1)T] the delayed signals are the solution on the
    earlier intervals, so the stacked states z(jT + tau), j = 0..n, of x = [y, y', yhat, yhat'] obey
    one linear ODE in tau in [0, T] (zero history before the step, continuity z_j(0) = z_{j-1}(T)),
    solved by the matrix exponential. No discretisation: the only errors are rounding.

    The horizon is ``intervals`` T. ``gains`` defaults to the PPUSMD gains for (w_A, T). Independent of
    the sampled loop and of the sim plant. The peak is the largest of the grid values and of the local
    maxima (zeros of y', Brent) of the grid cells whose bound y_i + h y'_i could exceed it; the settling
    time is the last exit from ``band`` (a fraction of the step), Brent within its grid cell (grid of T /
    ``points_per_delay`` = h; an excursion that leaves and re-enters the band between two grid points is
    not seen: at its extremum y' = 0, so it passes the band by less than max|y''| h^2 / 8, about 2e-6 at
    the default grid for the paper's frequencies).

    With ``max_rounding_error``, the computation stops before the first interval whose estimated
    rounding error (:attr:`StepResponse.rounding_error`) passes it: the horizon is then shorter than
    ``intervals`` T (at least one interval is always kept).
    """
    from scipy.optimize import brentq

    _check(omega_a, delay)
    if not (math.isfinite(omega_r) and omega_r > 0):
        raise TimeDelayError(f"real frequency w_R must be finite and > 0 rad/s, got {omega_r!r}")
    if int(intervals) < 1 or int(points_per_delay) < 2:
        raise TimeDelayError("intervals must be >= 1 and points_per_delay >= 2")
    _check_band(band)
    coef = gains if gains is not None else ppusmd_gains(omega_a, delay)
    h = delay / int(points_per_delay)
    ts, ys = [], []
    best = (0.0, 0.0)
    exit_cell = None  # (n, m, tau_i, tau_i+1, x_i) of the last grid cell leaving the band
    rounding, limited = 0.0, False
    prev_y_ends = np.zeros(0)

    for n, m, taus, xs in _method_of_steps(omega_a, delay, omega_r, intervals, points_per_delay, coef):
        last = 4 * n
        y, dy = xs[:, last], xs[:, last + 1]
        if n:  # blocks 0 .. n-1 end where they ended on the previous interval, up to rounding
            err = float(np.abs(xs[-1, 0:last:4] - prev_y_ends).max())
            if max_rounding_error is not None and err > max_rounding_error:
                limited = True
                break
            rounding = max(rounding, err)
        prev_y_ends = xs[-1, 0:last + 1:4].copy()
        ts.append(n * delay + taus)
        ys.append(y)
        k = int(np.argmax(y))
        if y[k] > best[1]:
            best = (float(n * delay + taus[k]), float(y[k]))
        # local maxima inside a cell: y' from > 0 to <= 0; with y' decreasing over the (short) cell,
        # y <= y_i + h y'_i there, so only cells whose bound passes the best value need refining
        for i in np.nonzero((dy[:-1] > 0) & (dy[1:] <= 0) & (y[:-1] + h * dy[:-1] > best[1] + 1e-14))[0]:
            tau, val = _cell_maximum(m, xs[i], taus[i], taus[i + 1], last)
            if val > best[1]:
                best = (n * delay + tau, val)
        out = np.nonzero(np.abs(y - 1.0) > band)[0]
        if out.size and out[-1] < y.size - 1:
            j = int(out[-1])
            exit_cell = (n, m, taus[j], taus[j + 1], xs[j].copy())
    t, yy = np.concatenate(ts), np.concatenate(ys)
    settling: float | None = None
    if abs(yy[-1] - 1.0) <= band and exit_cell is not None:
        n, m, t0, t1, x0 = exit_cell

        def excess(tau: float) -> float:
            return abs(float(_advance(m, x0, tau - t0)[4 * n]) - 1.0) - band

        settling = n * delay + brentq(excess, t0, t1, xtol=1e-13)
    # tail windows: the last quarter of the horizon, but at least one period of the slower of w_A, w_R
    horizon = t[-1]
    win = max(0.25 * horizon, 2.0 * math.pi / min(omega_a, omega_r))
    q4 = np.abs(yy[t >= horizon - win] - 1.0)
    q3 = np.abs(yy[(t >= horizon - 2.0 * win) & (t < horizon - win)] - 1.0)
    earlier = float(q3.max()) if horizon >= 2.0 * win else math.nan  # too short to compare: not decaying
    return StepResponse(t, yy, best[0], best[1], float(band), settling,
                        float(q4.max()), earlier, rounding, limited)


# ------------------------------------------------------------------------------------------------
# performance: overshoot and settling time, with a horizon long enough to trust them

MAX_ROUNDING_ERROR = 1e-8
"""Largest accepted :attr:`StepResponse.rounding_error`: a longer horizon is not used beyond it."""


def _captured_and_settled(r: StepResponse) -> bool:
    return r.peak_captured and r.settled


def step_response_with_horizon(omega_a: float, delay: float, omega_r: float, band: float = DEFAULT_BAND,
                               min_periods: float = 6.0, max_intervals: int = 120, points_per_delay: int = 400,
                               enough: Callable[[StepResponse], bool] | None = None) -> StepResponse:
    """:func:`exact_step_response` over a horizon chosen so that its overshoot and settling time can be
    trusted.

    The horizon starts at max(30 T, ``min_periods`` periods 2 pi / min(w_A, w_R)) and is doubled (up to
    ``max_intervals`` T) until ``enough(response)`` holds (default: :attr:`StepResponse.peak_captured`
    and :attr:`StepResponse.settled`). The method of steps loses accuracy geometrically with the number
    of intervals (:attr:`StepResponse.rounding_error`), so a horizon whose estimated rounding error
    passes :data:`MAX_ROUNDING_ERROR` is cut where it does (``max_rounding_error`` of
    :func:`exact_step_response`); the response returned may then not satisfy ``enough`` (the caller
    reads ``peak_captured`` and ``settled``)."""
    _check(omega_a, delay)
    if not (math.isfinite(omega_r) and omega_r > 0):
        raise TimeDelayError(f"real frequency w_R must be finite and > 0 rad/s, got {omega_r!r}")
    _check_band(band)
    if int(max_intervals) < 1:
        raise TimeDelayError(f"max_intervals must be >= 1, got {max_intervals!r}")
    decided = _captured_and_settled if enough is None else enough
    period = 2.0 * math.pi / min(omega_a, omega_r)
    n = min(int(max_intervals), max(30, math.ceil(min_periods * period / delay)))
    while True:
        r = exact_step_response(omega_a, delay, omega_r, n, points_per_delay, band=band,
                                max_rounding_error=MAX_ROUNDING_ERROR)
        if decided(r) or n >= int(max_intervals) or r.accuracy_limited:
            return r  # decided, or as long as allowed, or as long as accurate
        n = min(2 * n, int(max_intervals))


@dataclass(frozen=True)
class StepPerformance:
    """Stability and step performance of the loop for one real plant w_R (rad/s).

    ``in_stable_interval``: w_A <= w_R <= upper bound of eq. (27); ``growth_rate`` (1/s): the sampled-data
    check (< 0: decays); ``response``: the exact step response over a horizon chosen by
    :func:`step_response_with_horizon`."""

    omega_a: float
    delay: float
    omega_r: float
    interval: StableInterval
    growth_rate: float
    response: StepResponse

    @property
    def in_stable_interval(self) -> bool:
        return self.interval.lower <= self.omega_r <= self.interval.upper


def step_performance(omega_a: float, delay: float, omega_r: float, band: float = DEFAULT_BAND,
                     max_intervals: int = 120, samples_per_delay: int = 100) -> StepPerformance:
    """Stable or not (eq. 27 and the sampled-data check) and the exact step response's overshoot, peak
    time and settling time into ``band`` (fraction) for w_A, T, w_R. For an unstable loop the response
    is only computed over the starting horizon (it grows; the numbers are over that horizon)."""
    si = stable_interval(omega_a, delay)
    g = growth_rate(omega_a, delay, omega_r, samples_per_delay)
    inside = si.lower <= omega_r <= si.upper
    resp = step_response_with_horizon(omega_a, delay, omega_r, band, max_intervals=max_intervals,
                                      enough=None if inside else (lambda r: True))
    return StepPerformance(omega_a, delay, omega_r, si, g, resp)


@dataclass(frozen=True)
class OvershootSegment:
    """A sub-interval [low, high] of real plant frequencies w_R (rad/s) where the loop is stable (eq. 27)
    and the exact overshoot is <= the limit. ``low_edge``, ``high_edge`` say what ends it: "stability"
    (the edge of eq. 27), "overshoot" (overshoot = limit there, Brent on the exact overshoot) or
    "horizon" (beyond it the overshoot could not be bounded over an accurate horizon; bisected)."""

    low: float
    high: float
    low_edge: str
    high_edge: str


@dataclass(frozen=True)
class OvershootInterval:
    """Result of :func:`overshoot_interval`: the stable interval, the limit (fraction), the segments
    and the scan (w_R, overshoot lower bound, overshoot upper bound, class) behind them."""

    omega_a: float
    delay: float
    max_overshoot: float
    interval: StableInterval
    segments: list[OvershootSegment]
    scan: list[tuple[float, float, float, str]]


def _classify(r: StepResponse, limit: float) -> str:
    if r.overshoot > limit:
        return "violates"
    if r.overshoot_bound <= limit:
        return "meets"
    return "unknown"


def overshoot_interval(omega_a: float, delay: float, max_overshoot: float, grid: int = 41, xtol: float = 1e-9,
                       max_intervals: int = 120, points_per_delay: int = 200) -> OvershootInterval:
    """The real plant frequencies w_R (rad/s) inside the stable interval of eq. (27) for which the exact
    step overshoot (:func:`exact_step_response`) is <= ``max_overshoot`` (a fraction: 0.2 for 20 %).

    The overshoot is not assumed monotonic in w_R. The stable interval is scanned on ``grid`` evenly
    spaced points (the last one 1e-4 of the interval inside the upper edge, where the loop is only
    marginally stable and its step response does not decay); each point is classified from an exact
    response over a horizon long enough to decide (:func:`step_response_with_horizon`): "meets" if the
    overshoot bound over all t (:attr:`StepResponse.overshoot_bound`) is within the limit, "violates" if
    the overshoot over the horizon already exceeds it, else "unknown" (treated as not meeting). Every
    change of class between neighbours is refined: meets/violates by Brent's method on overshoot(w_R) -
    limit, to ``xtol`` rad/s; changes involving "unknown" by bisection on the class, to the larger of
    ``xtol`` and 1e-6 of the stable interval's width. A dip of the
    overshoot below the limit that begins and ends between two grid points is not found: use a finer
    ``grid`` if the scan suggests one."""
    from scipy.optimize import brentq

    if not (isinstance(max_overshoot, (int, float)) and math.isfinite(max_overshoot) and max_overshoot > 0):
        raise TimeDelayError(f"overshoot limit must be a finite fraction > 0 (0.2 for 20 %), got {max_overshoot!r}")
    if int(grid) < 3:
        raise TimeDelayError(f"grid must have at least 3 points, got {grid!r}")
    if not (math.isfinite(xtol) and xtol > 0):
        raise TimeDelayError(f"xtol must be finite and > 0 rad/s, got {xtol!r}")
    si = stable_interval(omega_a, delay)
    limit = float(max_overshoot)
    cache: dict[float, StepResponse] = {}

    def resp(w: float) -> StepResponse:
        if w not in cache:
            cache[w] = step_response_with_horizon(
                omega_a, delay, w, max_intervals=max_intervals, points_per_delay=points_per_delay,
                enough=lambda r: _classify(r, limit) != "unknown")
        return cache[w]

    width = si.upper - si.lower
    ws = si.lower + width * np.linspace(0.0, 1.0, int(grid))
    ws[-1] = si.upper - 1e-4 * width
    classes = [_classify(resp(float(w)), limit) for w in ws]

    def edge(a: float, b: float, ca: str, cb: str) -> tuple[float, str]:
        """The w_R between grid points a < b where the class changes from ca to cb."""
        if {ca, cb} == {"meets", "violates"}:
            return brentq(lambda w: resp(w).overshoot - limit, a, b, xtol=xtol), "overshoot"
        while b - a > max(xtol, 1e-6 * width):
            mid = 0.5 * (a + b)
            if _classify(resp(mid), limit) == ca:
                a = mid
            else:
                b = mid
        return (a if ca == "meets" else b), "horizon"

    segments: list[OvershootSegment] = []
    low: tuple[float, str] | None = (si.lower, "stability") if classes[0] == "meets" else None
    for i in range(1, len(ws)):
        a, b, ca, cb = float(ws[i - 1]), float(ws[i]), classes[i - 1], classes[i]
        if ca == cb or "meets" not in (ca, cb):
            continue
        w, kind = edge(a, b, ca, cb)
        if cb == "meets":
            low = (w, kind)
        elif low is not None:
            segments.append(OvershootSegment(low[0], w, low[1], kind))
            low = None
    if low is not None:  # meets up to the last point, just inside the upper edge
        segments.append(OvershootSegment(low[0], si.upper, low[1], "stability"))
    scan = [(float(w), cache[float(w)].overshoot, cache[float(w)].overshoot_bound, c)
            for w, c in zip(ws, classes, strict=True)]
    return OvershootInterval(omega_a, delay, limit, si, segments, scan)
