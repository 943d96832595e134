"""A lockstep plant's per-step writes kept and written together (node/sensors.WriteBatch): the same writes, each to
its writer, in the order they were made; none kept past ``periods`` periods or a flush."""

from __future__ import annotations

import pytest

from sim_plant_node.node.sensors import BATCH_PERIODS, WriteBatch


def test_the_writes_go_out_in_order_once_the_periods_are_in():
    batch = WriteBatch(3)
    wrote: list[tuple[str, object]] = []
    a, b = (batch.deferred(lambda data, k=k: wrote.append((k, data))) for k in "ab")
    for period in range(7):
        a(b"%d" % period)
        b(period)
        a(b"clock %d" % period)
        batch.period()
        assert len(wrote) == 9 * ((period + 1) // 3)  # (three writes a period: written at the third, the sixth)
        assert len(batch) == 3 * ((period + 1) % 3)
    batch.flush()
    assert len(batch) == 0
    assert wrote == [w for p in range(7) for w in (("a", b"%d" % p), ("b", p), ("a", b"clock %d" % p))]


def test_a_flush_writes_what_is_kept_and_starts_the_periods_again():
    batch = WriteBatch(2)
    wrote: list[int] = []
    w = batch.deferred(wrote.append)
    w(1)
    batch.period()
    w(2)
    batch.flush()  # (a cycle event, a feedback message, the end of a callback)
    assert wrote == [1, 2]
    w(3)
    batch.period()
    assert wrote == [1, 2]  # one period since the flush
    w(4)
    batch.period()
    assert wrote == [1, 2, 3, 4]
    batch.flush()
    assert wrote == [1, 2, 3, 4]


def test_a_failed_write_leaves_nothing_kept():
    batch = WriteBatch(5)

    def fails(data: int) -> None:
        raise RuntimeError("publisher destroyed")

    wrote: list[int] = []
    bad, good = batch.deferred(fails), batch.deferred(wrote.append)
    good(1)
    bad(2)
    good(3)
    with pytest.raises(RuntimeError):
        batch.flush()
    assert wrote == [1] and len(batch) == 0
    good(4)
    batch.flush()
    assert wrote == [1, 4]


def test_periods_are_checked():
    assert WriteBatch().periods == BATCH_PERIODS >= 1
    with pytest.raises(ValueError):
        WriteBatch(0)
