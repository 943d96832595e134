"""Samples as the learners keep them: compact stamped buffers, and the sensor's range.

:class:`SampleBuffer` holds stamped samples of one width in growable numpy arrays: 8 (1 + k)
bytes a sample of k values, against about 300 for Python lists of small arrays, and it gives
the memory back when it shrinks, so that a cycle refused at its duration limit frees its samples
at once. :func:`out_of_range` finds the samples at or beyond a sensor's range (a saturated
accelerometer, an implausible joint state) and :class:`OutOfRange` says so in words. Both
learners (LIST and MRILC) and the identifier node use them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

#: default longest cycle of both learners, s: a longer one is refused, its samples dropped at the limit
MAX_CYCLE_DURATION = 600.0
#: default range of the accelerometer, m/s^2 (16 g): a sample at or beyond it is saturated
MAX_ABS_ACCEL = 160.0
#: smallest capacity of a buffer, samples
MIN_CAPACITY = 1024
#: a buffer whose capacity exceeds this many times what it holds (and MIN_CAPACITY) is reallocated
SHRINK_FACTOR = 4

FloatArray = npt.NDArray[np.float64]


class SampleBuffer:
    """Stamped samples of ``width`` values each, in order of arrival, in growable numpy arrays.

    Parameters
    ----------
    width : int, optional
        Values per sample; None: the first sample's (again after the buffer was emptied).

    Appending is amortised O(1) (the capacity doubles); :meth:`keep`, :meth:`keep_last` and
    :meth:`drop_first` reallocate to a smaller capacity when most of it would be unused, so the
    memory a long cycle took is released as soon as its samples are dropped.
    """

    def __init__(self, width: int | None = None) -> None:
        if width is not None and width < 1:
            raise ValueError(f"width must be >= 1, got {width}")
        self._fixed = width
        self.width = width
        self.n = 0
        self._t: FloatArray = np.empty(MIN_CAPACITY)
        self._v: FloatArray = np.empty((MIN_CAPACITY, width or 0))

    def __len__(self) -> int:
        return self.n

    @property
    def times(self) -> FloatArray:
        """The stamps, s (a view: copy it to keep it past the next change)."""
        return self._t[: self.n]

    @property
    def values(self) -> FloatArray:
        """The samples, (n, width) (a view)."""
        return self._v[: self.n]

    @property
    def capacity(self) -> int:
        return int(self._t.size)

    @property
    def nbytes(self) -> int:
        """Bytes the buffer's arrays take (its capacity, not only what it holds)."""
        return int(self._t.nbytes + self._v.nbytes)

    def _accepts(self, width: int) -> bool:
        if self.width is None or (self.n == 0 and self._fixed is None):
            if width != self.width:
                self.width = width
                self._v = np.empty((self.capacity, width))
            return True
        return width == self.width

    def _reserve(self, need: int) -> None:
        if need <= self.capacity:
            return
        cap = max(MIN_CAPACITY, self.capacity)
        while cap < need:
            cap *= 2
        self._realloc(cap)

    def _realloc(self, cap: int) -> None:
        t, v = np.empty(cap), np.empty((cap, self._v.shape[1]))
        t[: self.n], v[: self.n] = self._t[: self.n], self._v[: self.n]
        self._t, self._v = t, v

    def append(self, t: float, value: npt.ArrayLike) -> bool:
        """Add one sample; False (and nothing added) if its width is not the buffer's."""
        v = np.asarray(value, dtype=float).ravel()
        if v.size == 0 or not self._accepts(v.size):
            return False
        self._reserve(self.n + 1)
        self._t[self.n] = t
        self._v[self.n] = v
        self.n += 1
        return True

    def extend(self, times: npt.ArrayLike, values: npt.ArrayLike) -> bool:
        """Add samples in order: ``times`` (m,), ``values`` (m, width); False (nothing added) if
        their width is not the buffer's or the shapes do not agree."""
        t = np.asarray(times, dtype=float).ravel()
        v = np.asarray(values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if v.ndim != 2 or v.shape[0] != t.size or v.shape[1] == 0 or not self._accepts(v.shape[1]):
            return False
        self._reserve(self.n + t.size)
        self._t[self.n : self.n + t.size] = t
        self._v[self.n : self.n + t.size] = v
        self.n += t.size
        return True

    def insert(self, index: int, t: float, value: npt.ArrayLike) -> bool:
        """Insert one sample before ``index`` (O(n): for the rare sample out of order)."""
        v = np.asarray(value, dtype=float).ravel()
        if v.size == 0 or not self._accepts(v.size):
            return False
        self._reserve(self.n + 1)
        self._t[index + 1 : self.n + 1] = self._t[index : self.n].copy()
        self._v[index + 1 : self.n + 1] = self._v[index : self.n].copy()
        self._t[index], self._v[index] = t, v
        self.n += 1
        return True

    def replace(self, index: int, value: npt.ArrayLike) -> bool:
        """Replace the values of sample ``index`` (same stamp); False if the width differs."""
        v = np.asarray(value, dtype=float).ravel()
        if v.size != self.width:
            return False
        self._v[index] = v
        return True

    def _set(self, t: FloatArray, v: FloatArray) -> None:
        """Hold exactly ``t``, ``v`` (copied), in arrays no larger than they need to be."""
        n = t.size
        if self.capacity > SHRINK_FACTOR * max(n, MIN_CAPACITY):
            cap = max(MIN_CAPACITY, 2 * n)
            self._t, self._v = np.empty(cap), np.empty((cap, self._v.shape[1]))
        self._t[:n], self._v[:n] = t, v
        self.n = n

    def keep(self, mask: npt.NDArray[np.bool_]) -> None:
        """Keep the samples where ``mask`` (over the samples held) is true, in order."""
        self._set(self.times[mask], self.values[mask])

    def keep_last(self, count: int) -> None:
        """Keep the newest ``count`` samples (by arrival)."""
        self.drop_first(max(self.n - max(int(count), 0), 0))

    def drop_first(self, count: int) -> None:
        """Drop the oldest ``count`` samples (by arrival)."""
        count = min(max(int(count), 0), self.n)
        if count:
            self._set(self._t[count : self.n].copy(), self._v[count : self.n].copy())

    def clear(self) -> None:
        """Drop every sample and give the memory back."""
        self.n = 0
        if self.capacity > MIN_CAPACITY:
            self._t, self._v = np.empty(MIN_CAPACITY), np.empty((MIN_CAPACITY, self._v.shape[1]))
        if self._fixed is None:
            self.width = None


@dataclass(frozen=True)
class OutOfRange:
    """Samples at or beyond a sensor's range: how many, of how many, the peak and where."""

    count: int      # samples (rows) with at least one value at or beyond the limit
    total: int      # samples checked
    peak: float     # the largest magnitude among them
    first: int      # index of the first
    limit: float

    def describe(self, what: str, unit: str, parameter: str) -> str:
        """The refusal in words, e.g. ``3 of 6000 accelerometer samples at or beyond ...``."""
        return (f"{self.count} of {self.total} {what} samples at or beyond the sensor's range of {self.limit:g} {unit}"
                f" ({parameter}; peak {self.peak:.6g} {unit}, first at sample {self.first})")


def out_of_range(values: npt.ArrayLike, limit: float) -> OutOfRange | None:
    """The samples of ``values`` ((n,) or (n, k)) with a finite value of magnitude at or beyond
    ``limit``, or None if there are none. Non-finite values are left to the checks that refuse
    them as such."""
    a = np.asarray(values, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.size == 0 or not math.isfinite(limit):
        return None
    mag = np.abs(a)
    over = np.isfinite(mag) & (mag >= limit)
    rows = np.any(over, axis=1)
    if not rows.any():
        return None
    return OutOfRange(int(rows.sum()), int(a.shape[0]), float(mag[over].max()), int(np.flatnonzero(rows)[0]),
                      float(limit))


def sensor_fault(values: npt.ArrayLike, what: str = "accelerometer") -> str | None:
    """Why the samples of one cycle ((n,) or (n, k)) cannot come from a working sensor, or None.

    A cycle contains a motion, and a motion moves a working accelerometer's reading (its noise alone
    moves it by 1e-4 m/s^2 and more): a cycle whose every axis reads one value from its START to its
    END (exactly 0, or stuck at 3.0) is a dead or stuck sensor, never "a quiet residual". A cycle
    with no sample at all is a silent sensor; non-finite samples are a faulty one. (Saturation is
    :func:`out_of_range`.) The words name the fault; the callers report them as a sensor fault.
    """
    a = np.asarray(values, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.shape[0] == 0:
        return f"0 {what} samples in the cycle: the sensor is silent (disconnected, or its driver stopped)"
    bad = ~np.isfinite(a)
    if bad.any():
        rows = np.flatnonzero(bad.any(axis=1))
        return f"{rows.size} of {a.shape[0]} {what} samples are non-finite (first at sample {int(rows[0])})"
    if a.shape[0] >= 2 and np.all(np.ptp(a, axis=0) == 0.0):
        values_text = ", ".join(f"{v:g}" for v in a[0])
        return (f"every {what} axis read one value through the whole cycle ([{values_text}], {a.shape[0]} samples):"
                " a working sensor's reading moves with the motion and with its noise; the sensor is stuck or dead")
    return None
