"""The lockstep wait for readers and the loss detection (shaper_nodes.core.lockstep), without rclpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shaper_nodes.core.lockstep import ANNOUNCE, Acks, Gaps, ReaderGate

DT = 0.002


def test_acks_send_the_oldest_stream_once_it_advanced_a_period():
    acks = Acks(period=0.02)
    assert acks.took("imu", 0.001) == 0.001  # the first is sent at once
    assert acks.took("js", 0.002) is None  # oldest still 0.001: nothing new to say
    assert acks.processed == 0.001
    for k in range(1, 30):
        acks.took("imu", 0.001 * k)
    assert acks.processed == 0.002  # the joint states hold it back
    sent = [acks.took("js", DT * k) for k in range(2, 16)]
    assert [s for s in sent if s is not None] == [pytest.approx(0.022)]
    assert acks.sent == pytest.approx(0.022)


def test_acks_flush_says_the_last_samples_the_period_held_back_once():
    acks = Acks(period=0.02)
    assert acks.flush() is None  # nothing taken
    assert acks.took("imu", 0.001) == 0.001
    assert acks.flush() is None  # nothing beyond what was sent
    for k in range(2, 10):  # the run's last samples: less than a period beyond the last acknowledgement
        assert acks.took("imu", 0.001 * k) is None
    assert acks.flush() == pytest.approx(0.009)  # the end of the run, said
    assert acks.flush() is None  # once
    assert acks.took("imu", 0.010) is None and acks.took("imu", 0.030) == pytest.approx(0.030)  # the period goes on


def test_acks_refuse_a_bad_period():
    with pytest.raises(ValueError, match="period"):
        Acks(period=math.nan)


def test_gate_holds_the_plant_a_lead_beyond_the_slowest_reader():
    gate = ReaderGate(["/a", "/b"], lead=0.1, timeout=5.0)
    assert gate.may_step(10.0, 0.0) == (True, "")  # nobody heard from yet: not started, nothing to wait for
    gate.ack("/a", 1.0, sim_time=1.0)
    gate.ack("/b", ANNOUNCE, sim_time=1.05)  # started, nothing taken: holds the plant where it is
    assert gate.acked == {"/a": 1.0, "/b": 1.05}
    assert gate.may_step(1.1, 0.0) == (True, "")
    assert gate.may_step(1.1 + DT, 0.0) == (False, "")
    assert gate.holding(1.1 + DT) == ["/a"]
    gate.ack("/a", 1.2, sim_time=1.1)
    assert gate.may_step(1.1 + DT, 0.1) == (True, "")  # /b now allows up to 1.15
    assert gate.may_step(1.15 + DT, 0.2) == (False, "")
    gate.ack("/c", 9.0, sim_time=1.1)  # not declared: ignored
    assert "/c" not in gate.acked
    assert gate.ack("/a", 1.0, sim_time=1.1) == "" and gate.acked["/a"] == 1.2  # never goes back


def test_gate_drops_a_silent_reader_after_the_timeout_with_one_line_and_takes_it_back():
    gate = ReaderGate(["/slow"], lead=0.1, timeout=5.0)
    gate.ack("/slow", 1.0, sim_time=1.0)
    assert gate.may_step(1.2, 100.0) == (False, "")
    assert gate.may_step(1.2, 104.9) == (False, "")
    ok, line = gate.may_step(1.2, 105.0)
    assert ok and "/slow" in line and "reader_timeout" in line and "\n" not in line
    assert gate.may_step(5.0, 106.0) == (True, "")  # dropped: no longer waited for
    back = gate.ack("/slow", 1.3, sim_time=5.0)
    assert "/slow" in back and "back" in back
    assert gate.may_step(5.0, 107.0) == (False, "")  # waited for again


def test_gate_drops_a_reader_that_went_away():
    gate = ReaderGate(["/gone"], lead=0.1, timeout=60.0)
    assert gate.leave("/gone") == ""  # never counted
    gate.ack("/gone", 2.0, sim_time=2.0)
    line = gate.leave("/gone")
    assert "/gone" in line and "went away" in line
    assert gate.leave("/gone") == ""  # said once
    assert gate.may_step(9.0, 0.0) == (True, "")


def test_gate_counts_a_reader_back_from_out_of_the_graph_from_the_plants_time():
    """A reader paused past the DDS lease leaves the graph; the plant steps on, and what it sends meanwhile never
    reaches the reader (unmatched). Back, its last acknowledgement (kept by the topic) is behind the plant's time:
    held at it, the reader could never release the plant (no sample to take) until lockstep.reader_timeout (30 s
    on the sim arm, session 13). It is counted from the plant's time instead, with the line saying so."""
    gate = ReaderGate(["/paused"], lead=0.25, timeout=30.0)
    gate.ack("/paused", 19.5, sim_time=19.5)
    assert "went away" in gate.leave("/paused")
    assert gate.may_step(21.8, 0.0) == (True, "")  # stepped on without it
    back = gate.ack("/paused", 19.513, sim_time=21.85)
    assert "back" in back and "never reach it" in back and "21.850" in back and "\n" not in back
    assert gate.acked["/paused"] == 21.85
    assert gate.may_step(21.85 + 0.2, 100.0) == (True, "")  # not held by what it cannot take
    assert gate.may_step(21.85 + 0.3, 100.0) == (False, "")  # but waited for again, a lead beyond
    gate.ack("/paused", 22.0, sim_time=22.1)
    assert gate.acked["/paused"] == 22.0 and gate.may_step(22.2, 101.0) == (True, "")
    # dropped for its silence first, out of the graph after: also counted from the plant's time when back
    gate.may_step(23.0, 200.0)
    ok, line = gate.may_step(23.0, 230.0)
    assert ok and "reader_timeout" in line
    assert gate.leave("/paused") == ""  # said once
    assert "never reach it" in gate.ack("/paused", 22.0, sim_time=40.0) and gate.acked["/paused"] == 40.0
    # a slow reader dropped for its silence, still in the graph, has the steps queued: held at what it took
    gate.may_step(40.5, 300.0)
    gate.may_step(40.5, 330.0)
    back = gate.ack("/paused", 40.1, sim_time=45.0)
    assert "back" in back and "never" not in back and gate.acked["/paused"] == 40.1


@pytest.mark.parametrize("lead, timeout", [(0.0, 1.0), (math.inf, 1.0), (0.1, 0.0), (0.1, math.nan)])
def test_gate_refuses_bad_settings(lead, timeout):
    with pytest.raises(ValueError, match="lockstep"):
        ReaderGate(["/a"], lead, timeout)


def stamps(n: int, period: float, missing: set[int] = frozenset()) -> list[float]:
    return [k * period for k in range(1, n + 1) if k not in missing]


def test_gaps_count_the_missing_stamps_and_where_they_are():
    gaps = Gaps(DT)
    for t in stamps(100, DT, {10, 11, 12, 50}):
        gaps.add(t)
    assert gaps.samples == 96
    assert gaps.lost() == 4
    assert gaps.lost(0.0, 0.022) == 2  # stamps 0.020, 0.022 (of 0.020, 0.022, 0.024) within (0, 0.022]
    assert gaps.lost(0.022, 0.2) == 2
    assert gaps.lost(0.03, 0.09) == 0


def test_gaps_ignore_a_repeated_stamp_and_learn_the_period():
    gaps = Gaps()
    for t in [0.001, 0.002, 0.002, 0.002, 0.003, 0.006, 0.007]:
        gaps.add(t)
    assert gaps.period == pytest.approx(0.001)
    assert gaps.lost() == 2
    clean = Gaps(0.001)
    for t in [0.001, 0.002, 0.002, 0.003]:  # the joint states at rest: the last state again
        clean.add(t)
    assert clean.lost() == 0


def test_gaps_on_the_wall_clock_count_no_loss_and_a_simulated_grid_still_does():
    """A stream stamped on the wall clock (a real-time sim plant, a robot's driver) jitters: its smallest spacing
    measured here was 0.22 ms against a period of 2 ms (the joint states of the sim plant in real time at load 25).
    Learned as the period it made every ordinary spacing a run of lost samples (the identifier logged "lost 20878
    samples of /joint_states" in a cycle of 2.6 s). Off the grid, it counts none. A stream on a grid (simulated
    time, in ns) with 300 Hz's rounding still counts each missing stamp."""
    rng = np.random.default_rng(1)
    wall = 1.7e9 + np.cumsum(0.002 + rng.normal(0.0, 0.0004, 1300))
    gaps = Gaps()
    for t in wall:
        gaps.add(float(t))
    assert gaps.off_grid and gaps.lost() == 0 and gaps.holes  # the holes are kept; they are not losses
    ns = [round(k * 1e9 / 300) * 1e-9 for k in range(1, 400) if k not in {5, 6, 100, 101, 102}]
    grid = Gaps()
    for t in ns:
        grid.add(100.0 + t)
    assert not grid.off_grid and grid.period == pytest.approx(1 / 300, rel=1e-6)
    assert grid.lost() == 5
