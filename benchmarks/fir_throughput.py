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
affects all of them alike). Each pass is timed in chunks (one block, or :data:`CHUNK_CALLS`
single-sample calls), and a method's figure is its **median chunk** over all passes, per call, as
joint-samples per second (samples x joints / s); ``vs lfilter`` is the ratio of those figures in
the same run. The median of chunks, not the best whole pass: on a loaded machine the process is
preempted for 4 to 35 ms every few ms, so a pass of 100 blocks of ``lfilter`` (25 to 50 ms) is
always cut several times while the shaper's pass (3 to 5 ms) is often not, and the best pass's
ratio swung with that (3.8x to 16x in runs of the same code); a preemption falls in a few chunks,
which the median leaves out. The best pass per call is kept as ``best_s`` (and its ratio as
``ratio_best_pass``), and the 10th and 90th percentiles of the chunks show each method's spread.
Outputs are compared with the reference over the same samples.
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
#: single-sample calls timed together as one chunk
CHUNK_CALLS = 100


@dataclass
class FirMethodResult:
    """One method's figures (times in s; the throughput and ratio from the median chunk)."""

    method: str
    samples: int
    calls: int
    joints: int
    best_s: float
    median_s: float
    call_p10_s: float
    call_p50_s: float
    call_p90_s: float
    joint_samples_per_s: float
    ratio_to_lfilter: float
    ratio_best_pass: float
    max_abs_diff: float
    agrees: bool


#: a method: marks the clock (``time.perf_counter``) into the list it is given at its start and after every
#: chunk, and returns its output
Method = Callable[[list[float]], np.ndarray]


def _shaper_samples(fir: SparseFir, x: np.ndarray, marks: list[float]) -> np.ndarray:
    sh = StreamingShaper(fir, x.shape[1])
    out = np.empty_like(x)
    process = sh.process
    clock = time.perf_counter
    marks.append(clock())
    for i in range(x.shape[0]):
        out[i] = process(x[i])
        if i % CHUNK_CALLS == CHUNK_CALLS - 1:
            marks.append(clock())
    return out


def _shaper_values(fir: SparseFir, rows: list[list[float]], marks: list[float]) -> np.ndarray:
    sh = StreamingShaper(fir, len(rows[0]))
    process = sh.process_values
    clock = time.perf_counter
    out = []
    marks.append(clock())
    for i in range(0, len(rows), CHUNK_CALLS):
        out += [process(r) for r in rows[i : i + CHUNK_CALLS]]
        marks.append(clock())
    return np.array(out)


def _shaper_blocks(fir: SparseFir, x: np.ndarray, block: int, marks: list[float]) -> np.ndarray:
    sh = StreamingShaper(fir, x.shape[1])
    clock = time.perf_counter
    outs = []
    marks.append(clock())
    for i in range(0, x.shape[0], block):
        outs.append(sh.process(x[i : i + block]))
        marks.append(clock())
    return np.concatenate(outs)


def _lfilter_blocks(taps: np.ndarray, x: np.ndarray, block: int, marks: list[float]) -> np.ndarray:
    a = np.array([1.0])
    zi = lfilter_zi(taps, a)[:, None] * x[0][None, :]
    clock = time.perf_counter
    outs = []
    every = CHUNK_CALLS if block == 1 else 1
    marks.append(clock())
    for k, i in enumerate(range(0, x.shape[0], block)):
        y, zi = lfilter(taps, a, x[i : i + block], axis=0, zi=zi)
        outs.append(y)
        if k % every == every - 1:
            marks.append(clock())
    return np.concatenate(outs)


def _lfilter_samples(taps: np.ndarray, x: np.ndarray, marks: list[float]) -> np.ndarray:
    return _lfilter_blocks(taps, x, 1, marks)


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
    # name: (function, samples, calls, calls per chunk)
    methods: dict[str, tuple[Method, int, int, int]] = {
        "shaper, sample by sample": (lambda m: _shaper_samples(fir, xs, m), ns, ns, CHUNK_CALLS),
        "shaper, sample by sample (lists)": (lambda m: _shaper_values(fir, xs_lists, m), ns, ns, CHUNK_CALLS),
        f"shaper, blocks of {block} x {joints}": (lambda m: _shaper_blocks(fir, x, block, m), nb, -(-nb // block), 1),
        f"lfilter (zi), blocks of {block} x {joints}": (lambda m: _lfilter_blocks(taps, x, block, m), nb,
                                                         -(-nb // block), 1),
        "lfilter (zi), sample by sample": (lambda m: _lfilter_samples(taps, xs, m), ns, ns, CHUNK_CALLS),
    }
    reference = f"lfilter (zi), blocks of {block} x {joints}"
    times: dict[str, list[float]] = {m: [] for m in methods}
    chunks: dict[str, list[float]] = {m: [] for m in methods}  # per call, s
    outputs: dict[str, np.ndarray] = {}
    for m, (fn, _, _, _) in methods.items():  # warm-up pass, and the outputs to compare
        outputs[m] = fn([])
    for r in range(repeats):
        progress(f"FIR throughput: pass {r + 1}/{repeats}")
        for m, (fn, _, _, per) in methods.items():
            marks: list[float] = []
            fn(marks)
            times[m].append(marks[-1] - marks[0])
            chunks[m] += (np.diff(marks) / per).tolist()

    ref_out = outputs[reference]
    ref_samples, ref_calls = methods[reference][1], methods[reference][2]
    ref_rate = ref_samples * joints / (ref_calls * float(np.median(chunks[reference])))
    ref_best = ref_samples * joints / min(times[reference])
    results = []
    for m, (_, samples, calls, _) in methods.items():
        best = min(times[m])
        diff = float(np.max(np.abs(outputs[m] - ref_out[:samples])))
        p10, p50, p90 = (float(v) for v in np.percentile(chunks[m], [10, 50, 90]))
        throughput = samples * joints / (calls * p50)
        results.append(FirMethodResult(
            method=m, samples=samples, calls=calls, joints=joints, best_s=best, median_s=float(np.median(times[m])),
            call_p10_s=p10, call_p50_s=p50, call_p90_s=p90, joint_samples_per_s=throughput,
            ratio_to_lfilter=throughput / ref_rate, ratio_best_pass=samples * joints / best / ref_best,
            max_abs_diff=diff, agrees=diff <= AGREEMENT_TOL))
    return {
        "shaper": {"family": "zvd", "frequency_hz": hz, "damping_ratio": zeta, "rate_hz": rate,
                   "impulses": len(shaper), "dense_taps": int(taps.size), "nonzero_taps": int(fir.delays.size)},
        "joints": joints, "block": block, "blocks": blocks, "sample_calls": int(xs.shape[0]), "repeats": repeats,
        "chunk_calls": CHUNK_CALLS,
        "reference": reference, "tolerance": AGREEMENT_TOL,
        "all_agree": all(r.agrees for r in results),
        "methods": [asdict(r) for r in results],
    }


def print_table(fir: dict) -> None:
    """FIR throughput table."""
    s = fir["shaper"]
    print(f"FIR throughput: ZVD {s['frequency_hz']:g} Hz, damping {s['damping_ratio']:g}, at {s['rate_hz']:g} Hz"
          f" ({s['impulses']} impulses -> {s['dense_taps']} dense taps, {s['nonzero_taps']} non-zero),"
          f" {fir['joints']} joints, median chunk of {fir['repeats']} passes")
    head = (f"  {'method':<34}{'samples':>8}{'us/call p10':>12}{'p50':>9}{'p90':>9}{'joint-samples/s':>17}"
            f"{'vs lfilter':>11}{'best pass':>10}{'max |diff|':>11}  agree")
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in fir["methods"]:
        print(f"  {m['method']:<34}{m['samples']:>8}{m['call_p10_s'] * 1e6:>12.1f}{m['call_p50_s'] * 1e6:>9.1f}"
              f"{m['call_p90_s'] * 1e6:>9.1f}{m['joint_samples_per_s']:>17,.0f}{m['ratio_to_lfilter']:>11.3g}"
              f"{m['ratio_best_pass']:>10.3g}{m['max_abs_diff']:>11.1e}  {'yes' if m['agrees'] else 'NO'}")
    print(f"  reference: {fir['reference']}; outputs agree to {fir['tolerance']:g}:"
          f" {'yes' if fir['all_agree'] else 'NO'}; 'best pass': the ratio of the best whole passes (see the"
          " module docstring)")


def main(argv: list[str] | None = None) -> None:
    """``python -m benchmarks.fir_throughput``: this benchmark alone (``./run bench --skip-*`` runs it among the
    others)."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m benchmarks.fir_throughput", description=__doc__.split("\n")[0])
    p.add_argument("--joints", type=int, default=7, help="channels (default 7)")
    p.add_argument("--repeats", type=int, default=5, help="passes per method (default 5)")
    p.add_argument("--runs", type=int, default=1, help="whole runs one after the other (default 1)")
    args = p.parse_args(argv)
    if args.joints < 1 or args.repeats < 1 or args.runs < 1:
        p.error("--joints, --repeats and --runs must be >= 1")
    for _ in range(args.runs):
        print_table(run(joints=args.joints, repeats=args.repeats))


if __name__ == "__main__":
    main()
