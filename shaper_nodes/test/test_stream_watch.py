"""The shaper node's input bookkeeping (ros/stream_watch.py) without a node: arrivals through the rate
watch, unwatched arrivals, refusals and the summary's keys and texts."""

from __future__ import annotations

from shaper_nodes.core.checks import InputError
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN
from shaper_nodes.ros.stream_watch import STREAMS, StreamWatch


class FakeDiagnostics:
    def __init__(self) -> None:
        self.reports: list[tuple[str, int, str, dict[str, str]]] = []

    def report(self, kind, level, message, *, name=None, values=()):
        self.reports.append((kind, level, message, dict(values)))
        return True


def info(i: int) -> dict[str, int]:
    return {"source_timestamp": 10**7 * i, "received_timestamp": 10**7 * i, "publication_sequence_number": i}


def test_a_quiet_window_is_ok_with_every_key():
    w = StreamWatch(100.0, FakeDiagnostics(), lambda k: 1)
    for i in range(1, 11):
        w.arrived("array", info(i))
        w.count_forwarded("array")
    level, msg, values = w.summary("shaping with zv", [("revision", "1")], [("action.scheduler.shaped", "0")])
    keys = [k for k, _ in values]
    assert level == OK and msg == "shaping with zv"
    assert keys[:2] == ["revision", "forwarded.array"]
    assert dict(values)["input.array.messages"] == "10" and dict(values)["input.array.drops"] == "0"
    assert dict(values)["input.array.rate_hz"] == "100.0"
    assert "input.stream.messages" not in keys and dict(values)["input.stream.total_drops"] == "0"
    assert keys[-1] == "action.scheduler.shaped"


def test_drops_gaps_and_refusals_warn():
    d = FakeDiagnostics()
    w = StreamWatch(100.0, d, lambda k: 1)
    for i in (1, 2, 5):
        w.arrived("stream", info(i))
    w.refused("/shaper/commands", InputError("non_finite", "data has non-finite values"))
    assert d.reports[0][:3] == ("non_finite", ERROR, "refused non_finite on /shaper/commands: data has non-finite"
                                                     " values (not forwarded)")
    assert d.reports[0][3] == {"topic": "/shaper/commands", "count": "1"}
    level, msg, values = w.summary("quiet")
    assert level == WARN
    assert msg == "1 messages refused in the last period; stream input: 1 gaps (largest 30.0 ms), 2 dropped"
    assert dict(values)["refused.non_finite"] == "1" and dict(values)["input.stream.total_drops"] == "2"
    assert w.watched("stream").total_drops == 2
    level, msg, _ = w.summary("quiet")  # a new window
    assert (level, msg) == (OK, "quiet")


def test_arrivals_pushed_out_before_they_were_watched_are_reported():
    w = StreamWatch(100.0, FakeDiagnostics(), lambda k: 1)
    assert w.arrivals_max == 4096 and set(w.rate_watch) == set(STREAMS)
    for i in range(1, w.arrivals_max + 101):
        w.arrived("array", info(i))
    level, msg, values = w.summary("quiet")
    assert level == WARN and "array input: 100 arrivals not watched" in msg
    assert dict(values)["input.array.unwatched"] == "100"
    assert dict(values)["input.array.messages"] == str(w.arrivals_max)


def test_drops_are_not_counted_while_several_publishers_are_seen():
    w = StreamWatch(100.0, FakeDiagnostics(), lambda k: 2)
    w.summary("quiet")  # the publisher counts are asked at each summary
    for i in (1, 5):
        w.arrived("array", info(i))
    _, _, values = w.summary("quiet")
    assert dict(values)["input.array.drops"] == "n/a (several publishers)"


def test_work_timing_is_off_unless_its_variable_names_a_file(monkeypatch, tmp_path):
    """WorkTiming (the benchmarks' timers in the node): None without SHAPER_WORK_TIMING; with it, a timed callable
    keeps the callable's signature (rclpy tells a (message, info) callback by it), its answer and its exception,
    and the summary written at the end counts every call."""
    import inspect
    import json

    import pytest
    from rclpy.subscription import Subscription

    from shaper_nodes.ros.stream_watch import WORK_TIMING_ENV, WorkTiming

    monkeypatch.delenv(WORK_TIMING_ENV, raising=False)
    assert WorkTiming.from_env() is None
    monkeypatch.setenv(WORK_TIMING_ENV, str(tmp_path / "work.json"))
    timing = WorkTiming.from_env()
    assert timing is not None

    class Node:
        def on_array(self, data, info):
            if data == b"bad":
                raise ValueError("refused")
            return data + b"!"

        def publish(self, msg):
            return len(msg)

    node = Node()
    callback = timing.timed("callback", node.on_array)
    timing.patch(node, "publish", "publish")
    assert inspect.signature(callback) == inspect.signature(node.on_array)
    sub = Subscription.__new__(Subscription)
    sub.callback = callback  # rclpy's own check of the callback's arguments
    assert sub._callback_type is Subscription.CallbackType.WithMessageInfo
    assert callback(b"ok", {}) == b"ok!" and node.publish(b"abc") == 3
    with pytest.raises(ValueError, match="refused"):
        callback(b"bad", None)
    timing.write()
    got = json.loads((tmp_path / "work.json").read_text())
    assert got["callback"]["n"] == 2 and got["publish"]["n"] == 1
    assert 0 <= got["callback"]["p10_us"] <= got["callback"]["p50_us"] <= got["callback"]["p90_us"]
