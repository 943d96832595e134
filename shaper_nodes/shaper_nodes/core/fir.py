"""Causal FIR filters from impulse sequences, and the streaming multi-joint shaper.

Discretisation
--------------
At command period ``Ts`` an impulse at ``t = (k + f) Ts`` (integer k, 0 <= f < 1) is either
rounded to the nearest sample (``"round"``) or split linearly between samples k and k + 1 with
weights ``1 - f`` and ``f`` (``"split"``, the default). Splitting keeps the centroid of each
impulse exactly where it belongs, so the residual vibration it leaves is second order in
``omega Ts`` instead of first order (see ``docs/shaping.md`` for V before and after).

Bumpless switching
------------------
:class:`StreamingShaper` writes the shaped output as a sum over the increments of the input,
each shaped by the filter that was active when it arrived:

    y(k) = y0 + sum_j s_{f(j)}(k - j) (x(j) - x(j - 1)),

where ``s_f`` is the step response of filter ``f`` (0 before the first tap, 1 after the last).
With one filter this is exactly the convolution ``h * x``. When the filter changes, motion
already commanded finishes under the old filter while new motion is shaped by the new one, so
the output is continuous, every part of the motion stays vibration-free with respect to the
filter that shaped it, and the output settles to the same final value (every step response
ends at 1). A retired filter's contribution is constant once its taps have passed, and is
then folded into the offset.

Re-timing switch (time-varying shaping)
---------------------------------------
:meth:`StreamingShaper.retime` instead makes the new filter act on the recent input as well,

    y(k) = sum_i g_i(k) x(k - d_i(k)),

the filter of the present sample applied to the input history: the impulses of motion already
commanded but not yet emitted come out at the new filter's times and amplitudes. This is the
time-varying shaper of configuration-dependent systems (seed 004's shaper follows the fuzzy
interpolator's mode continuously): when a step's second impulse is still pending while the
pose, and so the mode, changes, it is re-timed to the new mode. The output is continuous when
the input was constant over both filters' lengths; otherwise it may jump by the difference of
the two filters' outputs on the recent input, which is what re-timing a pending impulse means.
It needs the input history, kept when the shaper is built with ``retain`` > 0 samples.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from .shapers import Shaper

#: most filters alive at once (the active one plus those whose tails are still running)
MAX_STAGES = 16


@dataclass(frozen=True)
class SparseFir:
    """A causal FIR with few non-zero taps: ``y(k) = sum_i gains[i] x(k - delays[i])``.

    ``delays`` are distinct, increasing integers (samples); ``gains`` dimensionless.
    """

    delays: np.ndarray
    gains: np.ndarray

    @property
    def length(self) -> int:
        """Number of dense taps (largest delay + 1)."""
        return int(self.delays[-1]) + 1

    def dense(self) -> np.ndarray:
        """The dense tap vector b_0 .. b_{length-1}."""
        taps = np.zeros(self.length)
        taps[self.delays] = self.gains
        return taps


def discretize(shaper: Shaper, rate: float, method: str = "split") -> SparseFir:
    """Discretise an impulse sequence to a causal FIR at ``rate`` (Hz).

    Parameters
    ----------
    shaper : Shaper
        The impulse sequence (times in s).
    rate : float
        Command rate, Hz.
    method : {"split", "round"}
        Linear split between the two neighbouring samples, or rounding to the nearest.
    """
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"command rate must be finite and > 0 Hz, got {rate!r}")
    pos = np.asarray(shaper.times) * rate
    amps = np.asarray(shaper.amplitudes)
    if method == "round":
        delays = np.rint(pos).astype(int)
        gains = amps.copy()
    elif method == "split":
        base = np.floor(pos + 1e-9).astype(int)
        frac = np.clip(pos - base, 0.0, 1.0)
        frac[frac < 1e-9] = 0.0
        delays = np.concatenate([base, base + 1])
        gains = np.concatenate([amps * (1.0 - frac), amps * frac])
    else:
        raise ValueError(f"unknown discretisation method {method!r}; use 'split' or 'round'")
    acc = np.zeros(int(delays.max()) + 1)
    np.add.at(acc, delays, gains)
    nz = np.flatnonzero(acc != 0.0)
    return SparseFir(delays=nz, gains=acc[nz])


def fir_impulses(fir: SparseFir, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The FIR as an impulse sequence (amplitudes, times in s), e.g. to evaluate its V."""
    return fir.gains.copy(), fir.delays / float(rate)


class _Stage:
    """One FIR running on its own input stream (deviation from ``origin``)."""

    __slots__ = ("fir", "origin", "history", "held", "held_samples")

    def __init__(self, fir: SparseFir, origin: np.ndarray) -> None:
        self.fir = fir
        self.origin = origin.copy()
        self.history = np.zeros((fir.length - 1, origin.size))
        self.held: np.ndarray | None = None
        self.held_samples = 0

    def run(self, block: np.ndarray) -> np.ndarray:
        n = block.shape[0]
        hist_len = self.history.shape[0]
        ext = np.concatenate([self.history, block]) if hist_len else block
        out = np.zeros_like(block)
        for d, g in zip(self.fir.delays, self.fir.gains):
            start = hist_len - int(d)
            out += g * ext[start : start + n]
        if hist_len:
            self.history = ext[-hist_len:].copy()
        return out


class StreamingShaper:
    """Causal multi-channel FIR on streamed samples, with bumpless filter changes.

    Parameters
    ----------
    fir : SparseFir
        The initial filter.
    channels : int
        Number of channels (joints).

    Notes
    -----
    The filter starts at rest at the first sample it sees (as if that value had been commanded
    forever), so starting the shaper never makes the output jump. :meth:`switch` takes effect
    before the next sample.
    """

    def __init__(self, fir: SparseFir, channels: int, retain: int = 0) -> None:
        if channels < 1:
            raise ValueError("channels must be >= 1")
        self.channels = int(channels)
        self._fir = fir
        self._stages: list[_Stage] = []
        self._offset = np.zeros(self.channels)
        self._last: np.ndarray | None = None
        self.retain = max(0, int(retain))  # input samples kept for retime()
        self._raw: deque[np.ndarray] = deque(maxlen=self.retain or 1)

    @property
    def fir(self) -> SparseFir:
        """The active filter."""
        return self._fir

    @property
    def started(self) -> bool:
        """Whether a sample has been seen since construction or :meth:`reset`."""
        return self._last is not None

    @property
    def stages(self) -> int:
        """Filters alive: the active one plus retired ones whose tails are still running."""
        return len(self._stages)

    def reset(self, value: np.ndarray | None = None) -> None:
        """Forget all history; with ``value``, rest there (output = value)."""
        self._stages.clear()
        self._last = None
        self._raw.clear()
        self._offset = np.zeros(self.channels)
        if value is not None:
            self._start(np.asarray(value, dtype=float).reshape(self.channels))

    def _start(self, x0: np.ndarray) -> None:
        self._offset = x0.copy()
        self._stages = [_Stage(self._fir, x0)]
        self._last = x0.copy()

    def switch(self, fir: SparseFir) -> None:
        """Make ``fir`` the active filter from the next sample on, bumplessly.

        Raises
        ------
        RuntimeError
            If :data:`MAX_STAGES` filters are already alive (changes faster than the filters'
            lengths); the active filter is then unchanged.
        """
        if self._last is None:
            self._fir = fir
            return
        if len(self._stages) >= MAX_STAGES:
            raise RuntimeError(
                f"{len(self._stages)} shaper changes still settling; wait {self._fir.length} samples"
            )
        active = self._stages[-1]
        active.held = self._last - active.origin
        active.held_samples = 0
        self._stages.append(_Stage(fir, self._last))
        self._fir = fir

    def retime(self, fir: SparseFir) -> None:
        """Make ``fir`` the active filter on the input history as well (see the module docstring).

        Raises
        ------
        RuntimeError
            If the shaper keeps too little history for ``fir`` (``retain`` < its length - 1);
            the active filter is then unchanged.
        """
        if self._last is None:
            self._fir = fir
            return
        need = fir.length - 1
        if need > self.retain:
            raise RuntimeError(f"re-timing needs {need} samples of input history, the shaper keeps {self.retain}")
        hist = list(self._raw)[-need:] if need else []
        first = self._raw[0] if self._raw else self._last  # before the first sample: at rest there
        if len(self._raw) < self.retain:
            hist = [first] * (need - len(hist)) + hist
        origin = self._last.copy()
        stage = _Stage(fir, origin)
        if need:
            stage.history = np.asarray(hist, dtype=float).reshape(need, self.channels) - origin
        self._stages = [stage]
        self._offset = origin
        self._fir = fir

    def process(self, block: np.ndarray) -> np.ndarray:
        """Shape a block of samples, shape (N, channels) or (channels,); returns the same shape."""
        x = np.asarray(block, dtype=float)
        single = x.ndim == 1
        x2 = x.reshape(-1, self.channels)
        n = x2.shape[0]
        if n == 0:
            return x2.copy()
        if self._last is None:
            self._start(x2[0])
        out = np.broadcast_to(self._offset, x2.shape).copy()
        keep: list[_Stage] = []
        for stage in self._stages:
            if stage.held is None:
                out += stage.run(x2 - stage.origin)
                keep.append(stage)
                continue
            out += stage.run(np.broadcast_to(stage.held, x2.shape))
            stage.held_samples += n
            if stage.held_samples >= stage.fir.length - 1:
                # tail has passed: from the next sample its output is exactly `held`
                self._offset = self._offset + stage.held
            else:
                keep.append(stage)
        self._stages = keep
        self._last = x2[-1].copy()
        if self.retain:
            self._raw.extend(x2[-self.retain:].copy())
        return out.reshape(x.shape) if single else out
