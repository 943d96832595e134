"""One FIR stage of the streaming shapers (core/shaping/fir.py): its input history as a ring or a linear buffer,
and its three paths: one sample on numpy, one sample of a few channels on Python floats, a block on numpy.

Split out of fir.py (session 13); :class:`_Stage` is the streaming shapers' own. The one-sample step on Python floats
is written out per number of taps and channels (:func:`_tap_step`), equal bit for bit to the loop over the taps.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from operator import sub
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .sparse_fir import SparseFir


#: rows a stage's linear buffer has room for after the history, at least (the block path moves the history to
#: the front when they are used up: a stream of one-row blocks moves it once every this many rows)
LINEAR_ROWS = 1024

#: the most taps :func:`_tap_step` writes a comprehension for (more: a loop over the taps)
UNROLLED_TAPS = 32
#: the most products (taps x channels) :func:`_tap_step` writes out one by one, with no comprehension
UNROLLED_TERMS = 256


def _tap_sum_loop(gains: list[float], rows: list[list[float]], offset: list[float]) -> list[float]:
    """:func:`_tap_step`'s sum as a loop over the taps (any number of them), in the same order: per column j,
    ``(gains[0] rows[0][j] + ... + gains[k-1] rows[k-1][j]) + offset[j]``."""
    g = gains[0]
    out = [g * v for v in rows[0]]
    for g, row in zip(gains[1:], rows[1:], strict=True):
        out = [a + g * b for a, b in zip(out, row, strict=True)]
    return [a + o for a, o in zip(out, offset, strict=True)]


def _tap_step_loop(values: Sequence[float], origin: list[float], rows: list[list[float]], taps: list[int], p: int,
                   gains: list[float], offset: list[float]) -> list[float]:
    """:func:`_tap_step` for any number of taps: the deviation into ``rows[p]``, then :func:`_tap_sum_loop` of
    the tapped rows."""
    rows[p] = [v - o for v, o in zip(values, origin, strict=True)]
    return _tap_sum_loop(gains, [rows[t] for t in taps], offset)


@functools.cache
def _tap_step(k: int, channels: int = 0) -> Callable[..., list[float]]:
    """``f(values, origin, rows, taps, p, gains, offset)``: one sample of :meth:`_Stage.step_values` in one call,
    for ``k`` taps: the deviation ``values - origin`` written to ``rows[p]``, then per column j
    ``(gains[0] rows[taps[0]][j] + ... + gains[k-1] rows[taps[k-1]][j]) + offset[j]`` summed left to right.
    Written out (as the standard library's ``namedtuple`` and ``dataclasses`` write their methods): for
    ``channels`` given and ``k * channels`` up to :data:`UNROLLED_TERMS`, every product one by one (no
    comprehension: on Python 3.11 each is a function call of its own, which a sample pays cold at 1 kHz), else for
    ``k`` up to :data:`UNROLLED_TAPS` one comprehension over the columns; with no loop over the taps and no list
    of the tapped rows, it is what makes one sample of a few channels cheaper on Python floats than numpy's
    calls. The same sums in the same order whichever form: equal bit for bit."""
    if k < 1:
        raise ValueError("a FIR has at least one tap")
    gs, xs, ts = ([f"{c}{i}" for i in range(k)] for c in "gxt")
    head = (f"def tap_step(values, origin, rows, taps, p, gains, offset):\n"
            f"    rows[p] = list(map(sub, values, origin))\n"
            f"    {', '.join(gs)}, = gains\n"
            f"    {', '.join(ts)}, = taps\n")
    if channels > 0 and k * channels <= UNROLLED_TERMS:
        os_ = [f"o{j}" for j in range(channels)]
        sums = ", ".join("(" + " + ".join(f"{g} * {x}[{j}]" for g, x in zip(gs, xs, strict=True)) + f") + {o}"
                         for j, o in enumerate(os_))
        source = (head + f"    {', '.join(xs)}, = {', '.join(f'rows[{t}]' for t in ts)},\n"
                  f"    {', '.join(os_)}, = offset\n"
                  f"    return [{sums}]\n")
        name = f"<fir tap step, {k} taps x {channels} channels>"
    elif k <= UNROLLED_TAPS:
        terms = " + ".join(f"{g} * {x}" for g, x in zip(gs, xs, strict=True))
        source = head + (f"    return [({terms}) + o for o, {', '.join(xs)} in zip(offset, "
                         f"{', '.join(f'rows[{t}]' for t in ts)})]\n")
        name = f"<fir tap step, {k} taps>"
    else:
        return _tap_step_loop
    namespace: dict[str, Any] = {"sub": sub}
    exec(compile(source, name, "exec"), namespace)  # our own source text
    fn = namespace["tap_step"]
    return fn  # type: ignore[no-any-return]


class _Stage:
    """One FIR running on its own input stream (deviation from ``origin``).

    The last ``fir.length`` inputs are kept in one of three forms, whichever path wrote last (the
    others are rebuilt from it when a path that reads them runs):

    - a numpy ring (``_buf``, the next input at row ``_pos``): the single-sample numpy path writes one
      row and gathers the few rows the taps need (one ``take`` with precomputed indices);
    - the same ring as Python lists (``_rows``): one sample of a few channels on Python floats;
    - a linear buffer (``_ext``): the block path writes a block's deviations right after the
      ``length - 1`` inputs before it, and each tap is then one strided pass over that buffer
      (``out += g x[k - d]`` as two numpy passes on the flat rows: every output's arithmetic the same wherever
      the block boundaries fall, so any partition into blocks gives the same output bit for bit). The buffer is
      kept from block to block (grown only for a larger block), so a block allocates nothing but its output; the next
      block goes after it while there is room (:data:`LINEAR_ROWS`), else the history (``length - 1``
      rows) is moved to the front first.
    """

    __slots__ = ("_buf", "_buf_ok", "_delays", "_ext", "_ext_end", "_gain_list", "_gains", "_idx", "_origin_flat",
                 "_origin_list", "_pos", "_rows", "_rows_ok", "_scratch", "_size", "_step", "_taps", "fir", "held",
                 "held_samples", "origin")

    def __init__(self, fir: SparseFir, origin: np.ndarray) -> None:
        self.fir = fir
        self.origin = origin.copy()
        self.held: np.ndarray | None = None
        self.held_samples = 0
        self._size = size = fir.length
        self._buf = np.zeros((size, origin.size))  # ring: input k at row k mod size
        self._pos = 0  # the row the next input goes to
        self._delays = [int(d) for d in fir.delays]
        self._gains = np.asarray(fir.gains, dtype=float)
        # per ring position, the rows holding x(k - delays[i]) when x(k) is at that position
        self._idx = [(p - fir.delays) % size for p in range(size)]
        # the same ring as Python lists, for one sample of a few channels (step_values): numpy's calls cost
        # more than the arithmetic there
        self._rows: list[list[float]] = self._buf.tolist()
        self._rows_ok = self._buf_ok = True
        # the block path's linear buffer: the newest `size` inputs are its rows _ext_end - size .. _ext_end - 1
        # when _ext_end >= 0 (the form written last); -1: the ring is current
        self._ext = np.zeros((0, origin.size))
        self._ext_end = -1
        self._origin_flat = np.tile(-self.origin, 1)  # -origin repeated row after row (grown as blocks need)
        self._scratch = np.empty(0)  # g x of one tap, for the block path (grown as blocks need)
        self._taps = [ix.tolist() for ix in self._idx]
        self._gain_list: list[float] = self._gains.tolist()
        self._origin_list: list[float] = self.origin.tolist()
        self._step = _tap_step(len(self._taps[0]), origin.size)

    def _numpy_ring(self) -> None:
        """Make the numpy ring current (before a numpy path reads it); the list ring stays current."""
        if not self._buf_ok:
            end = self._ext_end
            if end >= 0:  # the block path wrote last: its newest `size` inputs, the oldest at row 0
                self._buf[:] = self._ext[end - self._size : end]
                self._pos = 0
                self._ext_end = -1
            else:
                self._buf[:] = self._rows
            self._buf_ok = True

    def step(self, x: np.ndarray) -> np.ndarray:
        """One input (deviation, shape (channels,)); returns the FIR output for it (a new array)."""
        self._numpy_ring()
        self._rows_ok = False
        p = self._pos
        self._buf[p] = x
        self._pos = p + 1 if p + 1 < self._size else 0
        y: np.ndarray = np.dot(self._gains, self._buf.take(self._idx[p], axis=0))
        return y

    def step_value(self, x: np.ndarray) -> np.ndarray:
        """:meth:`step` for an input value ``x`` (not a deviation): its deviation from :attr:`origin` is
        written straight into the ring (one numpy call instead of two). Returns a new array."""
        self._numpy_ring()
        self._rows_ok = False
        p = self._pos
        np.subtract(x, self.origin, out=self._buf[p])
        self._pos = p + 1 if p + 1 < self._size else 0
        y: np.ndarray = np.dot(self._gains, self._buf.take(self._idx[p], axis=0))
        return y

    def step_values(self, values: Sequence[float], offset: list[float]) -> list[float]:
        """:meth:`step_value` on Python floats (one sample of a few channels), plus ``offset``: the deviation
        goes into the list ring, and the output is the same sum of the tapped inputs times the gains, in the
        order of the delays, then plus the offset (equal to the numpy paths to rounding). Returns a new list."""
        if not self._rows_ok:
            self._numpy_ring()
            self._rows = self._buf.tolist()
            self._rows_ok = True
        self._buf_ok = False
        p = self._pos
        self._pos = p + 1 if p + 1 < self._size else 0
        return self._step(values, self._origin_list, self._rows, self._taps[p], p, self._gain_list, offset)

    def _history(self, n: int) -> tuple[np.ndarray, int]:
        """The flat linear buffer (``self._ext``) with room for ``n`` inputs from its row ``at`` on, the last
        ``size - 1`` inputs in the rows just before, oldest first; returns (flat, at). The history is moved to
        the front only when the room after it runs out (for blocks of a few rows, once every
        :data:`LINEAR_ROWS` rows or so)."""
        hist = self._size - 1
        ext, end = self._ext, self._ext_end
        if end >= 0:  # the block path wrote last: the history is the rows end - hist .. end - 1
            if end + n <= ext.shape[0]:
                return ext.reshape(-1), end
            if hist + n > ext.shape[0]:
                grown = np.empty((hist + max(n, LINEAR_ROWS), ext.shape[1]))
                grown[:hist] = ext[end - hist : end]
                self._ext = ext = grown
            elif end != hist:
                ext[:hist] = ext[end - hist : end]  # (numpy copies through a buffer when the two overlap)
        else:
            self._numpy_ring()
            if ext.shape[0] < hist + n:
                self._ext = ext = np.empty((hist + max(n, LINEAR_ROWS), self._buf.shape[1]))
            p, buf = self._pos, self._buf  # the ring's next row holds its oldest input, not in the history
            ext[: hist - p] = buf[p + 1 :]
            ext[hist - p : hist] = buf[:p]
        return ext.reshape(-1), hist

    def _tap_sum_block(self, flat: np.ndarray, at: int, n: int) -> np.ndarray:
        """The FIR output of the ``n`` inputs written from row ``at`` of the flat buffer ``flat``, after the
        history; the block path's state then lives in the linear buffer."""
        c = self._ext.shape[1]
        nc = n * c
        delays, gains = self._delays, self._gains
        out = np.empty((n, c))
        acc = out.reshape(-1)
        start = (at - delays[0]) * c
        np.multiply(gains[0], flat[start : start + nc], out=acc)
        # the other taps added in place: g x into a scratch row, then added (two numpy passes; BLAS daxpy fuses the
        # multiply and the add in its vector body and not in its tail on some CPUs, so an output's last bit would
        # depend on where the block boundaries fall)
        tmp = self._scratch
        if tmp.size < nc:
            tmp = self._scratch = np.empty(max(nc, LINEAR_ROWS * c))
        tmp = tmp[:nc]
        for d, g in zip(delays[1:], self._gain_list[1:], strict=True):
            start = (at - d) * c
            np.multiply(flat[start : start + nc], g, out=tmp)
            np.add(acc, tmp, out=acc)
        self._ext_end = at + n
        self._buf_ok = self._rows_ok = False
        return out

    def run(self, block: np.ndarray) -> np.ndarray:
        """A block of inputs (deviations, shape (N, channels)); returns the FIR output (a new array)."""
        n = block.shape[0]
        flat, at = self._history(n)
        self._ext[at : at + n] = block
        return self._tap_sum_block(flat, at, n)

    def run_values(self, block: np.ndarray) -> np.ndarray:
        """:meth:`run` for a block of input values (not deviations, C-contiguous, shape (N, channels)): their
        deviations from :attr:`origin` are written straight into the linear buffer, as one flat pass (equal
        to ``run(block - origin)``, bit for bit). Returns a new array."""
        n, c = block.shape
        nc = n * c
        flat, at = self._history(n)
        neg = self._origin_flat
        if neg.size < nc:
            neg = self._origin_flat = np.tile(-self.origin, n)
        start = at * c
        np.add(block.reshape(-1), neg[:nc], out=flat[start : start + nc])
        return self._tap_sum_block(flat, at, n)
