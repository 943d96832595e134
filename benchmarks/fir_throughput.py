"""Throughput of the FIR core against ``scipy.signal.lfilter`` on the same dense taps and data.

Methods (each over the same data, each started at rest at the first sample):

``shaper, sample by sample``
    :meth:`shaper_nodes.core.shaping.fir.StreamingShaper.process` called with one ``(joints,)`` sample
    per call, as the shaper node does for every message.
``shaper, sample by sample (lists)``
    :meth:`~shaper_nodes.core.shaping.fir.StreamingShaper.process_values` with one sample as a list of
    floats per call, the shaper node's path for ``Float64MultiArray`` messages (Python floats
    throughout: numpy's calls cost more than the arithmetic on a few values).
``shaper, blocks``
    The same with ``(block, joints)`` blocks.
``lfilter, blocks`` (the reference)
    ``scipy.signal.lfilter(fir.dense(), [1.0], block, axis=0, zi=zi)`` carrying ``zi`` from
    block to block; the initial ``zi`` is ``lfilter_zi`` scaled by the first sample (at rest).
``lfilter, sample by sample``
    The same with one ``(1, joints)`` sample per call (the per-call overhead of scipy, for
    comparison with the node's path).

Timing: the methods are run round-robin ``repeats`` times (so slow drift of a noisy machine
affects all of them alike) and each one's best pass is reported, as joint-samples per second
(samples x joints / s). Outputs are compared with the reference over the same samples.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import lfilter, lfilter_zi

from shaper_nodes.core.shaping import Mode, SparseFir, StreamingShaper, design, discretize

#: outputs must agree with lfilter to this (absolute, data of order 1)
AGREEMENT_TOL = 1e-9


@dataclass
class FirMethodResult:
    """One method's figures."""

    method: str
    samples: int
    calls: int
    joints: int
    best_s: float
    median_s: float
    joint_samples_per_s: float
    ratio_to_lfilter: float
    max_abs_diff: float
    agrees: bool


def _shaper_samples(fir: SparseFir, x: np.ndarray) -> np.ndarray:
    sh = StreamingShaper(fir, x.shape[1])
    out = np.empty_like(x)
    process = sh.process
    for i in range(x.shape[0]):
        out[i] = process(x[i])
    return out


def _shaper_values(fir: SparseFir, rows: list[list[float]]) -> np.ndarray:
    sh = StreamingShaper(fir, len(rows[0]))
    process = sh.process_values
    return np.array([process(r) for r in rows])


def _shaper_blocks(fir: SparseFir, x: np.ndarray, block: int) -> np.ndarray:
    sh = StreamingShaper(fir, x.shape[1])
    return np.concatenate([sh.process(x[i : i + block]) for i in range(0, x.shape[0], block)])


def _lfilter_blocks(taps: np.ndarray, x: np.ndarray, block: int) -> np.ndarray:
    a = np.array([1.0])
    zi = lfilter_zi(taps, a)[:, None] * x[0][None, :]
    outs = []
    for i in range(0, x.shape[0], block):
        y, zi = lfilter(taps, a, x[i : i + block], axis=0, zi=zi)
        outs.append(y)
    return np.concatenate(outs)


def _lfilter_samples(taps: np.ndarray, x: np.ndarray) -> np.ndarray:
    return _lfilter_blocks(taps, x, 1)


def run(*, hz: float = 8.0, zeta: float = 0.03, rate: float = 1000.0, joints: int = 7, block: int = 1000,
        blocks: int = 100, sample_calls: int = 10000, repeats: int = 5, seed: int = 0,
        progress: Callable[[str], None] = lambda s: None) -> dict:
    """Run the FIR throughput benchmark; returns the figures as a dictionary.

    Parameters
    ----------
    hz, zeta : float
        The ZVD shaper's mode (Hz, damping ratio).
    rate : float
        Sample rate, Hz.
    joints : int
        Channels.
    block, blocks : int
        Block mode: ``blocks`` blocks of ``block`` samples.
    sample_calls : int
        Sample mode: this many samples, one per call (the first ones of the block-mode data).
    repeats : int
        Passes per method; the best is reported.
    seed : int
        Seed of the random-walk test data.
    progress : callable
        Receives progress messages.
    """
    shaper = design("zvd", [Mode.from_hz(hz, zeta)])
    fir = discretize(shaper, rate)
    taps = fir.dense()
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(scale=0.01, size=(block * blocks, joints)), axis=0) + rng.uniform(-1, 1, joints)
    xs = x[: min(sample_calls, x.shape[0])]
    xs_lists = xs.tolist()

    ns, nb = xs.shape[0], x.shape[0]
    # name: (function, samples, calls)
    methods: dict[str, tuple[Callable[[], np.ndarray], int, int]] = {
        "shaper, sample by sample": (lambda: _shaper_samples(fir, xs), ns, ns),
        "shaper, sample by sample (lists)": (lambda: _shaper_values(fir, xs_lists), ns, ns),
        f"shaper, blocks of {block} x {joints}": (lambda: _shaper_blocks(fir, x, block), nb, -(-nb // block)),
        f"lfilter (zi), blocks of {block} x {joints}": (lambda: _lfilter_blocks(taps, x, block), nb, -(-nb // block)),
        "lfilter (zi), sample by sample": (lambda: _lfilter_samples(taps, xs), ns, ns),
    }
    reference = f"lfilter (zi), blocks of {block} x {joints}"
    times: dict[str, list[float]] = {m: [] for m in methods}
    outputs: dict[str, np.ndarray] = {}
    for m, (fn, _, _) in methods.items():  # warm-up pass, and the outputs to compare
        outputs[m] = fn()
    for r in range(repeats):
        progress(f"FIR throughput: pass {r + 1}/{repeats}")
        for m, (fn, _, _) in methods.items():
            t = time.perf_counter()
            fn()
            times[m].append(time.perf_counter() - t)

    ref_out = outputs[reference]
    ref_rate = x.shape[0] * joints / min(times[reference])
    results = []
    for m, (_, samples, calls) in methods.items():
        best = min(times[m])
        diff = float(np.max(np.abs(outputs[m] - ref_out[:samples])))
        throughput = samples * joints / best
        results.append(FirMethodResult(
            method=m, samples=samples, calls=calls, joints=joints, best_s=best, median_s=float(np.median(times[m])),
            joint_samples_per_s=throughput, ratio_to_lfilter=throughput / ref_rate, max_abs_diff=diff,
            agrees=diff <= AGREEMENT_TOL))
    return {
        "shaper": {"family": "zvd", "frequency_hz": hz, "damping_ratio": zeta, "rate_hz": rate,
                   "impulses": len(shaper), "dense_taps": int(taps.size), "nonzero_taps": int(fir.delays.size)},
        "joints": joints, "block": block, "blocks": blocks, "sample_calls": int(xs.shape[0]), "repeats": repeats,
        "reference": reference, "tolerance": AGREEMENT_TOL,
        "all_agree": all(r.agrees for r in results),
        "methods": [asdict(r) for r in results],
    }


def print_table(fir: dict) -> None:
    """FIR throughput table."""
    s = fir["shaper"]
    print(f"FIR throughput: ZVD {s['frequency_hz']:g} Hz, damping {s['damping_ratio']:g}, at {s['rate_hz']:g} Hz"
          f" ({s['impulses']} impulses -> {s['dense_taps']} dense taps, {s['nonzero_taps']} non-zero),"
          f" {fir['joints']} joints, best of {fir['repeats']}")
    head = (f"  {'method':<34}{'samples':>8}{'us/call':>9}{'joint-samples/s':>17}{'vs lfilter':>11}"
            f"{'max |diff|':>11}  agree")
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in fir["methods"]:
        print(f"  {m['method']:<34}{m['samples']:>8}{m['best_s'] / m['calls'] * 1e6:>9.1f}"
              f"{m['joint_samples_per_s']:>17,.0f}{m['ratio_to_lfilter']:>11.3g}"
              f"{m['max_abs_diff']:>11.1e}  {'yes' if m['agrees'] else 'NO'}")
    print(f"  reference: {fir['reference']}; outputs agree to {fir['tolerance']:g}:"
          f" {'yes' if fir['all_agree'] else 'NO'}")
