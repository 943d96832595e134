"""The sparse FIR a shaper becomes at a sample rate (:class:`SparseFir`): its delays and gains. Split out of fir.py
(session 13) so that the streaming shapers' stage (fir_stage.py) and fir.py both take it from here."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
