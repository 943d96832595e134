"""LockstepReader's acknowledgements are Acks' to the bit: the samples it keeps without asking Acks change nothing.

LockstepReader.took keeps a sample that advances its stream short of the next acknowledgement itself (no
acknowledgement can come of it) and hands every other one to :class:`shaper_nodes.core.lockstep.Acks`. Fed the same
samples (four streams at the arm's rates, in order, with repeated and late stamps and runs where one stream lags)
and the same wall-clock flushes, it sends what Acks alone returns, in order, and keeps the same latest stamps.
"""

from __future__ import annotations

import random

import pytest
import rclpy
from rclpy.context import Context

from shaper_nodes.core.lockstep import ACK_PERIOD, Acks
from shaper_nodes.ros.lockstep_reader import LockstepReader

STREAMS = {"/tip_imu": 0.001, "/joint_states": 0.002, "/sim_plant/tip_state": 0.002, "/sim_plant/reference": 0.002}


@pytest.fixture
def node():
    ctx = Context()
    rclpy.init(context=ctx)
    n = rclpy.create_node("lockstep_reader_acks", context=ctx)
    yield n
    n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def samples(seed: int, count: int) -> list[tuple[str, float] | None]:
    """(stream, stamp) in each stream's order, streams interleaved as a drained reader takes them (a batch of one,
    then of another), now and then a repeated or older stamp, and None where a flush comes."""
    rng = random.Random(seed)
    k = dict.fromkeys(STREAMS, 0)
    out: list[tuple[str, float] | None] = []
    while len(out) < count:
        stream = rng.choice(list(STREAMS))
        for _ in range(rng.choice((1, 1, 3, 10, 40))):
            k[stream] += 1
            t = round(k[stream] * STREAMS[stream], 9)
            out.append((stream, t))
            if rng.random() < 0.02:
                out.append((stream, t if rng.random() < 0.5 else round(t - STREAMS[stream], 9)))
        if rng.random() < 0.05:
            out.append(None)
    return out


@pytest.mark.parametrize("period", [ACK_PERIOD, 0.0, 0.005, 0.1])
@pytest.mark.parametrize("seed", range(4))
def test_the_reader_sends_what_acks_alone_return(node, period, seed):
    reader = LockstepReader(node, {}, period=period)
    sent: list[float] = []
    reader._send = sent.append  # type: ignore[method-assign]  # (what it would publish, in order)
    alone = Acks(period)
    want: list[float] = []
    for item in samples(seed, 6000):
        if item is None:
            reader._flush()
            ack = alone.flush()
        else:
            reader.took(*item)
            ack = alone.took(*item)
        if ack is not None:
            want.append(ack)
    assert len(want) > 20
    assert [a.hex() for a in sent] == [a.hex() for a in want]
    assert reader._acks.latest == alone.latest and reader.processed == alone.processed
