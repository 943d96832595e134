"""Causal FIR filters from impulse sequences, and the streaming multi-joint shaper.

Discretisation
--------------
At command period ``Ts`` an impulse at ``t = (k + f) Ts`` (integer k, 0 <= f < 1) is either
rounded to the nearest sample (``"round"``) or split linearly between samples k and k + 1 with
weights ``1 - f`` and ``f`` (``"split"``, the default). Splitting keeps the centroid of each
impulse exactly where it belongs, so the residual vibration it leaves is second order in
``omega Ts`` instead of first order (see ``docs/design/shaping.md`` for V before and after).

``"exact"`` starts from the split and corrects its taps (least change, in the 2-norm) so that the
FIR, read as impulses at the sample instants, meets the continuous shaper's own conditions at
every design mode exactly: its transform S(s) = sum_k b_k exp(-s k Ts) equals the continuous
shaper's sum_i A_i exp(-s t_i), with the first d derivatives in s, at each mode's pole
s = -zeta omega + j omega sqrt(1 - zeta^2) (d: the family's derivative order, ZV 0, ZVD 1,
ZV-D^n n, MZV and SI 0, the EI family 1), and the taps sum to 1. A plant driven through a
zero-order hold at Ts by the shaped command keeps a residual proportional to |S(s)| at its pole,
so on the design modes the FIR leaves exactly what the continuous shaper leaves (zero for the
ZV family: no discretisation floor). The correction is refused (``ValueError``) when the command
period leaves no solution on the samples next to the impulses (for a positive shaper, none with
taps >= 0: then the least change is found with the taps bounded below by zero), and, before any
arithmetic, for a design mode far above the command rate, one that decays by more than
:data:`~.fir_exact.MAX_EXACT_DECAY` (zeta omega Ts) over one command period or turns through more than
:data:`~.fir_exact.MAX_EXACT_PHASE` over the shaper.

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

Re-timing (time-varying shaping)
--------------------------------
:class:`RetimingShaper` writes the output the same way but keeps, per pending increment, the
fraction already emitted, e_j(k). A bumpless :meth:`~RetimingShaper.switch` gives new
increments the new filter (the behaviour above); :meth:`~RetimingShaper.retime` gives the new
filter to the pending increments as well, from their age on, never taking back what was
already emitted:

    e_j(k) = max(e_j at the retime, s_new(k - j)).

So when the mode changes while a move's impulses are still pending (seed 004: the pose, and
with it the mode, changes with the first impulse of a step), the rest of the move comes out at
the new mode's impulse times, as the time-varying shaper of a configuration-dependent system
does, and the output never steps back. Every increment still ends fully emitted, so the output
settles at the input.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .fir_exact import _exact_taps
from .fir_stage import _Stage
from .sparse_fir import SparseFir
from .types import Shaper

#: most filters alive at once (the active one plus those whose tails are still running)
MAX_STAGES = 16


def discretize(shaper: Shaper, rate: float, method: str = "split") -> SparseFir:
    """Discretise an impulse sequence to a causal FIR at ``rate`` (Hz).

    Parameters
    ----------
    shaper : Shaper
        The impulse sequence (times in s).
    rate : float
        Command rate, Hz.
    method : {"split", "round", "exact"}
        Linear split between the two neighbouring samples, rounding to the nearest, or the split
        corrected to meet the shaper's conditions at its design modes exactly (module docstring).
    """
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"command rate must be finite and > 0 Hz, got {rate!r}")
    pos = np.asarray(shaper.times) * rate
    amps = np.asarray(shaper.amplitudes)
    if method == "round":
        delays = np.rint(pos).astype(int)
        gains = amps.copy()
    elif method in ("split", "exact"):
        base = np.floor(pos + 1e-9).astype(int)
        frac = np.clip(pos - base, 0.0, 1.0)
        frac[frac < 1e-9] = 0.0
        delays = np.concatenate([base, base + 1])
        gains = np.concatenate([amps * (1.0 - frac), amps * frac])
    else:
        raise ValueError(f"unknown discretisation method {method!r}; use 'split', 'round' or 'exact'")
    acc = np.zeros(int(delays.max()) + 1)
    np.add.at(acc, delays, gains)
    if method == "exact":
        acc = _exact_taps(shaper, rate, acc, base)
        gain = float(np.sum(np.abs(acc)))
        if gain > shaper.gain * (1.0 + 1e-6) + 1e-12:  # the correction must not amplify beyond the shaper
            raise ValueError(f"exact discretisation of the {shaper.family} shaper at {rate:g} Hz would amplify: gain"
                             f" sum |b| = {gain:.6g} beyond the shaper's {shaper.gain:.6g}; use 'split'")
    total = float(acc.sum())
    if total != 0.0 and abs(total - 1.0) < 1e-6:  # taps summing to 1 to rounding: a held input comes out unchanged
        acc = acc / total
    nz = np.flatnonzero(acc != 0.0)
    return SparseFir(delays=nz, gains=acc[nz])


def fir_impulses(fir: SparseFir, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The FIR as an impulse sequence (amplitudes, times in s), e.g. to evaluate its V."""
    return fir.gains.copy(), fir.delays / float(rate)


class _ChannelShaper:
    """What the streaming shapers share: the number of channels, the active filter, and the
    last input sample (None until the first sample after construction or a reset)."""

    def __init__(self, fir: SparseFir, channels: int) -> None:
        if channels < 1:
            raise ValueError("channels must be >= 1")
        self.channels = int(channels)
        self._fir = fir
        self._last: np.ndarray | Sequence[float] | None = None

    @property
    def fir(self) -> SparseFir:
        """The active filter."""
        return self._fir

    @property
    def started(self) -> bool:
        """Whether a sample has been seen since construction or :meth:`reset`."""
        return self._last is not None

    def process(self, block: np.ndarray) -> np.ndarray:
        """Shape a block of samples, shape (N, channels) or (channels,); returns the same shape."""
        raise NotImplementedError

    def process_values(self, values: Sequence[float]) -> list[float]:
        """:meth:`process` for one sample given as a list or tuple of ``channels`` floats; returns a list."""
        if len(values) != self.channels:
            raise ValueError(f"expected {self.channels} values, got {len(values)}")
        out: list[float] = self.process(np.array(values, dtype=float)).tolist()
        return out


class StreamingShaper(_ChannelShaper):
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

    def __init__(self, fir: SparseFir, channels: int) -> None:
        super().__init__(fir, channels)
        self._stages: list[_Stage] = []
        self._offset = np.zeros(self.channels)
        self._offset_tiled: tuple[np.ndarray, np.ndarray] = (self._offset, self._offset)  # see _offset_row
        self._one = (self.channels,)  # the shape of one sample
        self._offset_list: tuple[np.ndarray, list[float]] = (self._offset, self._offset.tolist())

    @property
    def stages(self) -> int:
        """Filters alive: the active one plus retired ones whose tails are still running."""
        return len(self._stages)

    def reset(self, value: np.ndarray | None = None) -> None:
        """Forget all history; with ``value``, rest there (output = value)."""
        self._stages.clear()
        self._last = None
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
        last = np.array(self._last, dtype=float)  # (a tuple after process_values)
        active = self._stages[-1]
        active.held = last - active.origin
        active.held_samples = 0
        self._stages.append(_Stage(fir, last))
        self._last = last
        self._fir = fir

    def process(self, block: np.ndarray) -> np.ndarray:
        """Shape a block of samples, shape (N, channels) or (channels,); returns the same shape."""
        x = np.asarray(block, dtype=float)
        if x.shape == self._one:
            stages = self._stages
            if len(stages) == 1 and stages[0].held is None:  # the usual case, inlined: _sample as below
                y: np.ndarray = stages[0].step_value(x)
                y += self._offset
                self._last = x.copy()  # a copy: it is the last sample
                return y
            return self._sample(x.copy())  # a copy: it becomes the last sample
        single = x.ndim == 1
        x2 = x.reshape(-1, self.channels)
        n = x2.shape[0]
        if n == 0:
            return x2.copy()
        if self._last is None:
            self._start(x2[0])
        stages = self._stages
        x2 = np.ascontiguousarray(x2)
        if len(stages) == 1 and stages[0].held is None:  # the usual case: one filter, no change settling
            out = stages[0].run_values(x2)
            flat = out.reshape(-1)
            np.add(flat, self._offset_row(flat.size), out=flat)
            self._last = x2[-1].copy()
            return out.reshape(x.shape) if single else out
        out = np.broadcast_to(self._offset, x2.shape).copy()
        keep: list[_Stage] = []
        for stage in stages:
            if stage.held is None:
                out += stage.run_values(x2)
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
        return out.reshape(x.shape) if single else out

    def _offset_row(self, size: int) -> np.ndarray:
        """The offset repeated row after row, ``size`` values (flat); kept until the offset changes (its
        array is replaced, never changed in place) or a larger block comes."""
        offset, tiled = self._offset_tiled
        if offset is not self._offset or tiled.size < size:
            offset = self._offset
            tiled = np.tile(offset, max(size // offset.size, 1))
            self._offset_tiled = (offset, tiled)
        return tiled[:size]

    def process_values(self, values: Sequence[float]) -> list[float]:
        """:meth:`process` for one sample given as a list or tuple of ``channels`` floats; returns the shaped
        sample as a list. In the usual case (started, one filter, no change settling) it runs on Python floats
        (:meth:`_Stage.step_values`), cheaper than numpy's calls on a few values; equal to :meth:`process`
        to rounding (tests hold them to 1e-12)."""
        if len(values) != self.channels:
            raise ValueError(f"expected {self.channels} values, got {len(values)}")
        stages = self._stages
        if self._last is None or len(stages) != 1 or stages[0].held is not None:
            out: list[float] = self._sample(np.array(values, dtype=float)).tolist()
            return out
        offset, offset_list = self._offset_list
        if offset is not self._offset:  # (the offset array is replaced, never changed in place)
            offset, offset_list = self._offset_list = (self._offset, self._offset.tolist())
        y = stages[0].step_values(values, offset_list)
        self._last = tuple(values)  # a list copied (the caller's may change), a tuple kept as it is
        return y

    def _sample(self, x: np.ndarray) -> np.ndarray:
        """:meth:`process` for one sample ``x`` (shape (channels,), owned), without the block path's
        copies of the history: the same sums as the block path, formed as one dot product of the
        gains with the tapped inputs (so equal to it to rounding, a few ulp; tests hold them to 1e-12)."""
        if self._last is None:
            self._start(x)
        stages = self._stages
        if len(stages) == 1 and stages[0].held is None:  # the usual case: one filter, no change settling
            y: np.ndarray = stages[0].step_value(x)
            y += self._offset
            self._last = x
            return y
        out = self._offset.copy()
        keep: list[_Stage] = []
        for stage in stages:
            if stage.held is None:
                out += stage.step(x - stage.origin)
                keep.append(stage)
                continue
            out += stage.step(stage.held)
            stage.held_samples += 1
            if stage.held_samples >= stage.fir.length - 1:
                self._offset = self._offset + stage.held
            else:
                keep.append(stage)
        self._stages = keep
        self._last = x
        return out


class RetimingShaper(_ChannelShaper):
    """Causal multi-channel shaper whose filter can be re-timed for pending motion (see the
    module docstring), or switched bumplessly as :class:`StreamingShaper`.

    Parameters
    ----------
    fir : SparseFir
        The initial filter.
    channels : int
        Number of channels (joints).
    """

    def __init__(self, fir: SparseFir, channels: int) -> None:
        super().__init__(fir, channels)
        self._filters: list[np.ndarray] = []  # step responses s(0..length-1) of the filters in use
        self.reset()

    @property
    def stages(self) -> int:
        """Distinct filters still shaping pending increments, the active one included."""
        return len(set(self._fid.tolist()) | {self._active})

    def reset(self, value: np.ndarray | None = None) -> None:
        """Forget all history; with ``value``, rest there (output = value)."""
        self._last = None
        self._base = np.zeros(self.channels)
        self._filters = [np.cumsum(self._fir.dense())]
        self._active = 0
        self._inc = np.zeros((0, self.channels))   # pending increments
        self._age = np.zeros(0, dtype=int)          # samples since each arrived (0 at arrival)
        self._fid = np.zeros(0, dtype=int)          # index of the filter shaping each
        self._floor = np.zeros(0)                   # emitted fraction at the last retime
        self._emitted = np.zeros(0)
        if value is not None:
            self._last = np.asarray(value, dtype=float).reshape(self.channels).copy()
            self._base = self._last.copy()

    def _use(self, fir: SparseFir) -> None:
        self._fir = fir
        self._filters.append(np.cumsum(fir.dense()))
        self._active = len(self._filters) - 1
        self._prune()

    def _prune(self) -> None:
        """Forget the filters no pending increment uses (the active one stays)."""
        used = sorted(set(self._fid.tolist()) | {self._active})
        if len(used) != len(self._filters):
            remap = {old: new for new, old in enumerate(used)}
            self._filters = [self._filters[i] for i in used]
            self._fid = np.array([remap[i] for i in self._fid.tolist()], dtype=int)
            self._active = remap[self._active]

    def switch(self, fir: SparseFir) -> None:
        """Bumpless: ``fir`` shapes the increments from the next sample on."""
        self._use(fir)

    def retime(self, fir: SparseFir) -> None:
        """``fir`` shapes the pending increments too, from their present age, never un-emitting."""
        self._fir = fir
        self._filters = [np.cumsum(fir.dense())]  # no increment keeps another filter
        self._active = 0
        self._fid[:] = 0
        # never taking back what was emitted, but at most all of it: an overshooting filter (negative
        # taps) may have emitted more than the increment, and a floor above 1 would never settle
        self._floor = np.minimum(self._emitted, 1.0)

    def _sample(self, x: np.ndarray) -> np.ndarray:
        if self._last is None:
            self.reset(x)
        d = x - self._last
        self._last = x.copy()
        if np.any(d != 0.0):
            self._inc = np.vstack([self._inc, d])
            self._age = np.append(self._age, -1)
            self._fid = np.append(self._fid, self._active)
            self._floor = np.append(self._floor, -np.inf)
            self._emitted = np.append(self._emitted, 0.0)
        if self._age.size == 0:
            return self._base.copy()
        self._age += 1
        s = np.ones(self._age.size)
        done = np.zeros(self._age.size, dtype=bool)
        for f in np.unique(self._fid):
            step = self._filters[f]
            sel = self._fid == f
            age = self._age[sel]
            s[sel] = np.where(age < step.size, step[np.minimum(age, step.size - 1)], 1.0)
            done[sel] = age >= step.size
        self._emitted = np.maximum(self._floor, s)
        done &= self._emitted >= 1.0
        if np.any(done):  # fully emitted: folded into the base
            self._base = self._base + (self._emitted[done, None] * self._inc[done]).sum(axis=0)
            keep = ~done
            self._inc, self._age, self._fid = self._inc[keep], self._age[keep], self._fid[keep]
            self._floor, self._emitted = self._floor[keep], self._emitted[keep]
            self._prune()
        return self._base + self._emitted @ self._inc

    def process(self, block: np.ndarray) -> np.ndarray:
        """Shape a block of samples, shape (N, channels) or (channels,); returns the same shape."""
        x = np.asarray(block, dtype=float)
        single = x.ndim == 1
        x2 = x.reshape(-1, self.channels)
        out = np.array([self._sample(row) for row in x2]).reshape(x2.shape)
        return out.reshape(x.shape) if single else out
