"""The FIR block path's linear buffer (core/shaping/fir_stage.py, _Stage.run_values): how a stream is cut into blocks
changes nothing, across the buffer's wrap, and the other paths read the state it leaves.

Every output row of the block path is the same sum in the same order (first tap times its input, then each
other tap added, then the offset), whatever block it came in: so one filter fed the same samples in any
partition into blocks gives the same output bit for bit. The single-sample paths form the sum as a dot
product (rounding differs by a few ulp): held to the offline convolution to 1e-12.
"""

from __future__ import annotations

import numpy as np
import pytest

from shaper_nodes.core.shaping.families import design
from shaper_nodes.core.shaping.fir import StreamingShaper, discretize
from shaper_nodes.core.shaping.fir_stage import LINEAR_ROWS
from shaper_nodes.core.shaping.sparse_fir import SparseFir
from shaper_nodes.core.shaping.types import Mode

RATE = 1000.0
FIRS = {
    "zvd 8 Hz": discretize(design("zvd", [Mode.from_hz(8.0, 0.03)]), RATE),
    "ei 2 Hz (long)": discretize(design("ei", [Mode.from_hz(2.0, 0.05)]), RATE),
    "zv 200 Hz (short)": discretize(design("zv", [Mode.from_hz(200.0, 0.0)]), RATE),
    "one tap": SparseFir(np.array([0]), np.array([1.0])),
}


def _partition(rng: np.random.Generator, total: int) -> list[int]:
    """Block sizes summing to ``total``: mostly single rows, some empty, some large ones."""
    sizes = []
    while sum(sizes) < total:
        sizes.append(int(rng.choice([0, 1, 1, 1, 1, 2, 3, 17, 300, 1500])))
    sizes[-1] -= sum(sizes) - total
    return sizes


def _offline(fir: SparseFir, x: np.ndarray) -> np.ndarray:
    """The convolution with the taps, the filter at rest at the first sample before it."""
    taps = fir.dense()
    padded = np.vstack([np.repeat(x[:1], taps.size - 1, axis=0), x])
    return np.stack([np.convolve(padded[:, j], taps, mode="valid") for j in range(x.shape[1])], axis=1)


@pytest.mark.parametrize("name", list(FIRS))
@pytest.mark.parametrize("channels", [1, 3, 7])
def test_any_partition_into_blocks_gives_the_same_output_bit_for_bit(name: str, channels: int) -> None:
    fir = FIRS[name]
    rng = np.random.default_rng(channels)
    total = 3 * LINEAR_ROWS + 500  # past the buffer's room several times
    x = np.cumsum(rng.normal(0.0, 0.01, (total, channels)), axis=0) + rng.uniform(-1.0, 1.0, channels)
    whole = StreamingShaper(fir, channels).process(x)
    for _ in range(3):
        sh, out, at = StreamingShaper(fir, channels), [], 0
        for n in _partition(rng, total):
            block = x[at : at + n]
            out.append(sh.process(block if rng.random() < 0.8 else np.asfortranarray(block)))
            at += n
        got = np.concatenate(out)
        assert got.shape == x.shape
        assert np.array_equal(got, whole)
    np.testing.assert_allclose(whole, _offline(fir, x), rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("name", list(FIRS))
def test_blocks_and_single_samples_interleaved_are_the_offline_convolution(name: str) -> None:
    """Each path takes over the state the others left (the linear buffer, the numpy ring, the list ring)."""
    fir = FIRS[name]
    rng = np.random.default_rng(11)
    total = 2 * LINEAR_ROWS + 300
    x = np.cumsum(rng.normal(0.0, 0.01, (total, 7)), axis=0)
    sh, out, at = StreamingShaper(fir, 7), [], 0
    while at < total:
        kind = rng.integers(4)
        if kind == 0:
            n = min(int(rng.choice([1, 2, 40, 700])), total - at)
            out.append(sh.process(x[at : at + n]))
            at += n
        elif kind == 1:
            out.append(sh.process(x[at])[None, :])
            at += 1
        else:
            out.append(np.array(sh.process_values(x[at].tolist()))[None, :])
            at += 1
    np.testing.assert_allclose(np.concatenate(out), _offline(fir, x), rtol=0.0, atol=1e-12)


def test_blocks_through_a_switch_are_bumpless_and_settle() -> None:
    """Two filters alive (one retiring) on the block path, cut into blocks as a lockstep exchange does."""
    a, b = FIRS["zvd 8 Hz"], FIRS["ei 2 Hz (long)"]
    x = np.concatenate([np.linspace(0.0, 1.0, 400), np.ones(2500)])[:, None] * np.array([1.0, -0.5, 0.25])
    ref = StreamingShaper(a, 3)
    ref_out = [ref.process(x[:200])]
    ref.switch(b)
    ref_out.append(ref.process(x[200:]))
    sh = StreamingShaper(a, 3)
    out = [sh.process(x[k : k + 10]) for k in range(0, 200, 10)]
    sh.switch(b)
    out += [sh.process(x[k : k + 1]) for k in range(200, x.shape[0])]
    np.testing.assert_allclose(np.concatenate(out), np.concatenate(ref_out), rtol=0.0, atol=1e-12)
    assert sh.stages == 1  # the retired filter's tail has passed and been folded in
    np.testing.assert_allclose(np.concatenate(out)[-1], x[-1], rtol=0.0, atol=1e-12)
