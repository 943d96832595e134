"""The latency bench's figures (:mod:`benchmarks.latency`): the data the driver sends, the output the node
should give for it, and the replies matched to the sends and checked, as one :class:`LatencyResult`.

Matching replies to sends
-------------------------
The send time of every message is kept in an array indexed by its sequence number ``k``
(1, 2, ..., n). The sequence number travels with the message twice:

* in ``layout.data_offset``, which both nodes pass through unchanged (the echo node republishes
  the message itself, the shaper node copies the layout of its input to its output); this is
  the primary key, and it is immune to filtering and to lost messages;
* in the data, as the ramp ``x_j(k) = k (1 + j / 8)`` on joint ``j``. The node under test may
  filter the data (the shaper does, and the sequence number cannot simply be read back), so a
  reply is decoded by comparing its joint 0 with the node's *expected* output for the ramp,
  computed here with the same causal FIR (:class:`shaper_nodes.core.shaping.fir.StreamingShaper`,
  designed from the parameters given to the node; identity for the echo node and for shaper
  family ``none``). A causal FIR with non-negative taps and a positive first tap (every shaper
  family here) maps a ramp to a strictly increasing sequence, so the inverse is a
  nearest-neighbour look-up. This is the fallback when a reply carries no ``data_offset``; it is
  exact only while no message is lost on the way in (a lost input shifts the filter's history).

Before the ramp the driver sends zeros (``data_offset`` 0) until the first reply arrives (both
hops discovered) and for ``warmup`` s more, so the node's filter starts at rest at 0 exactly as
the local one does. Every joint of every reply is checked against the expected output
(``max_output_error``, relative; ``inexact`` counts replies off by more than 1e-9, which only
happens after a lost input): the comparison is only fair if the node did the work it should.
Shaper family ``none`` still runs the node's full path (validation, ``StreamingShaper`` with one
tap, message building).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from shaper_nodes.core.shaping import SparseFir, StreamingShaper

from .latency_targets import Target

__all__ = ["LatencyResult", "analyse", "expected_output", "ramp"]


@dataclass
class LatencyResult:
    """Figures of one latency measurement (times in microseconds, CPU in percent of one core)."""

    label: str
    joints: int
    target_rate_hz: float
    sent: int
    received: int
    lost: int
    duplicates: int
    undecoded: int
    seq_from_data: int
    inexact: int
    max_output_error: float
    send_rate_hz: float
    send_interval_p99_us: float
    p50_us: float
    p99_us: float
    max_us: float
    mean_us: float
    node_cpu_pct: float
    node_cpu_us_per_msg: float
    driver_cpu_pct: float
    other_cpu_pct: float
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """Plain dictionary (for JSON)."""
        return asdict(self)


def ramp(n: int, joints: int) -> np.ndarray:
    """The driver's data: row 0 is the rest value 0, row k the ramp ``k (1 + j / 8)``; shape (n + 1, joints)."""
    k = np.arange(n + 1, dtype=float)[:, None]
    return k * (1.0 + np.arange(joints) / 8.0)[None, :]


def expected_output(fir: SparseFir, data: np.ndarray) -> np.ndarray:
    """The node's output for ``data`` (rows = samples), started at rest at ``data[0]``."""
    return StreamingShaper(fir, data.shape[1]).process(data)


def analyse(target: Target, replies: list[tuple[int, int, object]], stamps: np.ndarray, expected: np.ndarray,
            rate: float, joints: int, *, node_cpu: float, driver_cpu: float, busy: float,
            wall: float, turns: Sequence[int] = ()) -> LatencyResult:
    """The figures of one target from its ``replies`` ((receive stamp ns, ``data_offset``, data) each) and the
    send ``stamps`` (ns, one per data row 1..n): each reply matched to its send and checked against
    ``expected`` (:func:`expected_output` of the ramp); ``node_cpu``, ``driver_cpu`` and ``busy`` (the
    machine's) are CPU seconds over the ``wall`` s of sending; ``turns`` are the stamp indices at which each
    turn after the first began (the pause between turns is not a send interval)."""
    n = stamps.size
    key = expected[:, 0]  # strictly increasing; index = sequence number (0 = rest)
    half_gap = 0.5 * float(np.min(np.diff(key)))
    latencies: list[float] = []
    seen = np.zeros(n + 1, dtype=bool)
    duplicates = undecoded = inexact = from_data = 0
    max_err = 0.0
    for t_recv, offset, values in replies:
        row = np.asarray(values, dtype=float)
        if row.size != joints:
            undecoded += 1
            continue
        if 1 <= offset <= n:
            k = int(offset)
        else:
            if abs(row[0] - key[0]) <= half_gap:
                continue  # a late reply to the warm-up's rest value
            k = int(np.clip(np.searchsorted(key, row[0]), 1, n))
            if k > 1 and abs(key[k - 1] - row[0]) < abs(key[k] - row[0]):
                k -= 1
            if abs(key[k] - row[0]) > half_gap:
                undecoded += 1
                continue
            from_data += 1
        err = float(np.max(np.abs(row - expected[k]) / np.maximum(1.0, np.abs(expected[k]))))
        max_err = max(max_err, err)
        inexact += err > 1e-9
        if seen[k]:
            duplicates += 1
            continue
        seen[k] = True
        latencies.append((t_recv - int(stamps[k - 1])) * 1e-3)
    lat = np.asarray(latencies)
    received = int(seen.sum())
    # send intervals within each turn (the pause from one turn to the next is not a send interval)
    keep = np.ones(max(n - 1, 0), dtype=bool)
    for b in turns:
        if 0 < b < n:
            keep[b - 1] = False
    intervals = np.diff(stamps)[keep] * 1e-3
    span = float(intervals.sum()) * 1e-6

    def pct(q: float) -> float:
        return float(np.percentile(lat, q)) if lat.size else float("nan")

    return LatencyResult(
        label=target.label, joints=joints, target_rate_hz=rate, sent=n, received=received, lost=n - received,
        duplicates=duplicates, undecoded=undecoded, seq_from_data=from_data, inexact=int(inexact),
        max_output_error=max_err,
        send_rate_hz=float(intervals.size / span) if span > 0 else float("nan"),
        send_interval_p99_us=float(np.percentile(intervals, 99)) if intervals.size else float("nan"),
        p50_us=pct(50), p99_us=pct(99), max_us=float(lat.max()) if lat.size else float("nan"),
        mean_us=float(lat.mean()) if lat.size else float("nan"),
        node_cpu_pct=100.0 * node_cpu / wall,
        node_cpu_us_per_msg=1e6 * node_cpu / received if received else float("nan"),
        driver_cpu_pct=100.0 * driver_cpu / wall,
        other_cpu_pct=100.0 * max(0.0, busy - node_cpu - driver_cpu) / wall,
    )
