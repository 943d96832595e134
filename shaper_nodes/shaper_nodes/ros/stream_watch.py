"""The shaper node's bookkeeping of its inputs: arrivals through the rate watch, forwarded and refused counts.

The streaming path only appends each message's info (the middleware's stamps and sequence number) and
when it was taken (:meth:`StreamWatch.arrived`: a deque's append, atomic); the node's main thread
passes them through one :class:`~shaper_nodes.core.rate.RateWatch` per stream at each summary, and every
:data:`WATCH_PERIOD` s where the summaries are rarer (:meth:`StreamWatch.watch`), off the streaming path, as
one batch of arrays (:func:`arrival_arrays`). The kept arrivals are
bounded (10 s at the command rate, at least 4096): reaching the bound means a stalled main thread,
and the arrivals pushed out unseen are reported. :meth:`StreamWatch.summary` builds the periodic
``/diagnostics`` summary: the input windows (rate, gaps, bursts, drops, lag), what was forwarded and
what refused.

:class:`WorkTiming` times a node's own calls (the shaper's array callback, its work and its publish) on the
streaming path as the node runs them, when :data:`WORK_TIMING_ENV` names a file (the benchmarks set it; unset,
nothing is wrapped and nothing is paid).
"""

from __future__ import annotations

import functools
import json
import os
import pathlib
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import numpy.typing as npt

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.rate import RateWatch

from .diagnostics import ERROR, OK, WARN, Diagnostics

#: the streamed inputs (array_in, stream_in)
STREAMS = ("array", "stream")
#: the environment variable naming the file a node writes its :class:`WorkTiming` to when it stops (unset: off)
WORK_TIMING_ENV = "SHAPER_WORK_TIMING"
#: how often the streams' kept arrivals go through the rate watch (s, steady clock, main thread) where the
#: summaries (every ``diagnostics_period``, 1 s by default; each watches too) are rarer than this: a quarter of the
#: kept arrivals' bound (10 s), so they are watched in time however rare the summaries. Each wake-up of the main
#: thread costs its executor about 0.45 ms of CPU, and a batch's numpy calls a fixed cost: at 0.25 s (before
#: session 15) the main thread spent about 3-4 us per message at 1 kHz, at 2.5 s about 2 us (docs/results/
#: benchmarks.md, issue 34, session 15, H1 watch); with the default 1 s summaries, no timer of its own (session 17)
WATCH_PERIOD = 2.5


_NO_INFO: dict[str, Any] = {}
_Ints = npt.NDArray[np.int64]


def arrival_arrays(kept: list[tuple[dict[str, Any] | None, int]]) -> tuple[_Ints, _Ints, _Ints, _Ints]:
    """The kept (info, taken) pairs as :meth:`~shaper_nodes.core.rate.RateWatch.arrivals`' arrays: source and
    received stamps, taken (ns), sequence numbers; 0 where the info (or the info itself) gives none."""
    infos = [info or _NO_INFO for info, _ in kept]
    return (np.array([i.get("source_timestamp") or 0 for i in infos], np.int64),
            np.array([i.get("received_timestamp") or 0 for i in infos], np.int64),
            np.array([taken for _, taken in kept], np.int64),
            np.array([i.get("publication_sequence_number") or 0 for i in infos], np.int64))


class StreamWatch:
    """The rate, drop, forward and refusal bookkeeping of the shaper node (see the module docstring).

    Parameters
    ----------
    rate : float
        The command rate, Hz: the nominal rate of the streams.
    diagnostics : Diagnostics
        Where refusals are reported.
    publishers : callable
        The number of publishers on a stream's input (``publishers("array")``): sequence numbers are per
        publisher, so drops are counted while one publisher is seen. Asked at every summary.

    Attributes
    ----------
    rejections, forwarded : collections.Counter
        Refused inputs per kind, forwarded messages per path ('array', 'stream', 'trajectory', 'action').
    rate_watch : dict of str to RateWatch
        One per stream of :data:`STREAMS`.
    arrivals_max : int
        How many arrivals per stream are kept until the main thread watches them.
    lock : threading.Lock
        The counters and rate watches, shared by the node's threads.
    """

    def __init__(self, rate: float, diagnostics: Diagnostics, publishers: Callable[[str], int]) -> None:
        self.diagnostics = diagnostics
        self._publishers = publishers
        self.lock = threading.Lock()
        self.rejections: Counter[str] = Counter()
        self.forwarded: Counter[str] = Counter()
        self._window_rejections = 0
        self.rate_watch = {k: RateWatch(rate) for k in STREAMS}
        self._publisher_counts = dict.fromkeys(STREAMS, 1)
        # the streams' message infos wait here (a deque's append and popleft are atomic) and go through the
        # rate watch off the streaming path, on the main thread every WATCH_PERIOD s (watch); the bound is
        # 10 s of arrivals at the command rate: reaching it means a stalled main thread, and is reported
        self.arrivals_max = max(4096, int(10 * rate))
        self._arrivals: dict[str, deque[tuple[dict[str, Any] | None, int]]] = {
            k: deque(maxlen=self.arrivals_max) for k in STREAMS}
        self._arrivals_in = dict.fromkeys(STREAMS, 0)  # appended, by the one thread of each stream
        self._arrivals_seen = dict.fromkeys(STREAMS, 0)  # through the rate watch

    def arrived(self, stream: str, info: dict[str, Any] | None, taken_ns: int | None = None) -> None:
        """Keep a streamed message's info (the middleware's stamps) and when it was taken (``taken_ns``, wall
        clock ns; default now), for the rate watch; only an append on the streaming path."""
        self._arrivals[stream].append((info, time.time_ns() if taken_ns is None else taken_ns))
        self._arrivals_in[stream] += 1

    def passed(self, stream: str, info: dict[str, Any] | None, taken_ns: int) -> None:
        """:meth:`arrived` and :meth:`count_forwarded` of a streamed message passed on, in one call: the
        bookkeeping a stream's callback does after its publish (``taken_ns``: when it was taken, read before
        the work), off the hop's latency."""
        self._arrivals[stream].append((info, taken_ns))
        self._arrivals_in[stream] += 1
        self.forwarded[stream] += 1  # (one writer per path: see count_forwarded)

    def count_forwarded(self, path: str) -> None:
        """One message passed on by ``path``."""
        # no lock: each path's count has one writer (array and stream: the streaming thread; trajectory and
        # action: the side node's thread), and a dict item's update is atomic to the readers under the GIL
        self.forwarded[path] += 1

    def refused(self, topic: str, err: InputError) -> None:
        """Count a refused input of ``topic`` and report it (throttled per kind)."""
        with self.lock:
            self.rejections[err.kind] += 1
            self._window_rejections += 1
            count = self.rejections[err.kind]
            self.diagnostics.report(err.kind, ERROR, f"refused {err.kind} on {topic}: {err} (not forwarded)",
                                    name="input", values=[("topic", topic), ("count", str(count))])

    def watch(self) -> None:
        """Pass the kept arrivals through the rate watches (the main thread's timer)."""
        with self.lock:
            self._watch_arrivals()

    def _watch_arrivals(self) -> None:
        """:meth:`watch` with :attr:`lock` held: each stream's kept arrivals as one batch (:func:`arrival_arrays`)."""
        for k, queue in self._arrivals.items():
            # bounded: what is there now (the stream thread may go on appending)
            kept = [queue.popleft() for _ in range(len(queue))]
            if kept:
                self.rate_watch[k].arrivals(*arrival_arrays(kept), self._publisher_counts[k])
                self._arrivals_seen[k] += len(kept)

    def watched(self, stream: str) -> RateWatch:
        """The rate watch of ``stream`` ('array' or 'stream') with every arrival so far taken in."""
        with self.lock:
            self._watch_arrivals()
            return self.rate_watch[stream]

    def summary(self, quiet: str, head: Iterable[tuple[str, str]] = (),
                tail: Iterable[tuple[str, str]] = ()) -> tuple[int, str, list[tuple[str, str]]]:
        """The periodic summary's (level, message, values), and a new window: WARN when inputs were refused
        in the window, a stream saw gaps or drops, or arrivals went unwatched; the message says which, or is
        ``quiet`` when none. Values: ``head``, the forwarded counts, each stream's window, ``tail``, the
        refused counts."""
        with self.lock:
            refused, self._window_rejections = self._window_rejections, 0
            forwarded, rejections = dict(self.forwarded), dict(self.rejections)
            self._watch_arrivals()
            windows = {k: w.window() for k, w in self.rate_watch.items()}
            total_drops = {k: w.total_drops for k, w in self.rate_watch.items()}
            # arrivals pushed out of a full queue before the rate watch saw them (a stalled main thread)
            unwatched = {k: self._arrivals_in[k] - self._arrivals_seen[k] - len(self._arrivals[k]) for k in STREAMS}
        # sequence numbers are per publisher: drops are counted while one publisher is seen
        self._publisher_counts = {k: self._publishers(k) for k in STREAMS}
        troubled = [k for k, w in windows.items() if w.trouble]
        level = WARN if refused or troubled else OK
        parts = [f"{refused} messages refused in the last period"] if refused else []
        parts += [f"{k} input: {w.gaps} gaps (largest {1e3 * w.largest_gap_s:.1f} ms), {w.drops} dropped"
                  for k, w in windows.items() if w.trouble]
        parts += [f"{k} input: {n} arrivals not watched (the node's main thread fell behind)"
                  for k, n in unwatched.items() if n > 0]
        if any(n > 0 for n in unwatched.values()):
            level = WARN
        msg = "; ".join(parts) if parts else quiet
        values = list(head)
        values += [(f"forwarded.{k}", str(v)) for k, v in sorted(forwarded.items())]
        for k, w in windows.items():
            if w.messages:
                values += w.values(f"input.{k}")
            values.append((f"input.{k}.total_drops", str(total_drops[k])))
            if unwatched[k] > 0:
                values.append((f"input.{k}.unwatched", str(unwatched[k])))
        values += list(tail)
        values += [(f"refused.{k}", str(v)) for k, v in sorted(rejections.items())]
        return level, msg, values


class WorkTiming:
    """Wall-clock timers (``time.perf_counter_ns``) around a node's calls, kept per name for the whole run and
    written as JSON when the node stops (:meth:`write`): per name the number of calls and the median, p10, p90
    and mean, us. For the benchmarks (``benchmarks/work_timing.py``): the work a message costs as the node does
    it at 1 kHz, with the caches cold from the wait between messages, which a tight loop does not show. Each
    timer adds a call and two clock reads (a fraction of a microsecond) to what it times, and to the callback
    around it.

    Parameters
    ----------
    path : str or pathlib.Path
        Where :meth:`write` writes.
    """

    def __init__(self, path: str | pathlib.Path) -> None:
        self.path = pathlib.Path(path)
        #: per name, every call's wall time, ns
        self.times: dict[str, list[int]] = {}

    @classmethod
    def from_env(cls) -> WorkTiming | None:
        """A WorkTiming writing to the file :data:`WORK_TIMING_ENV` names, or None when it is unset or empty."""
        path = os.environ.get(WORK_TIMING_ENV, "")
        return cls(path) if path else None

    def timed(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        """``fn`` with its wall time kept under ``name`` (the same signature, for rclpy's callback check)."""
        append = self.times.setdefault(name, []).append
        clock = time.perf_counter_ns

        @functools.wraps(fn)
        def timed_call(*args: Any) -> Any:
            t = clock()
            try:
                return fn(*args)
            finally:
                append(clock() - t)

        return timed_call

    def timed_callback(self, fn: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
        """A subscription's (message, info) callback ``fn`` timed under "callback", and its wake-up under "wake":
        from the middleware's reception of the message (the info's ``received_timestamp``, system clock) to the
        callback's start (the take loop's wait, wake-up and take)."""
        times, wakes = self.times.setdefault("callback", []).append, self.times.setdefault("wake", []).append
        clock, now = time.perf_counter_ns, time.time_ns

        def callback(msg: Any, info: Any) -> Any:
            wakes(now() - info["received_timestamp"])
            t = clock()
            try:
                return fn(msg, info)
            finally:
                times(clock() - t)

        return callback

    def patch(self, owner: Any, method: str, name: str) -> None:
        """Time ``owner.method`` under ``name``: the bound method replaced on the instance by :meth:`timed`'s."""
        setattr(owner, method, self.timed(name, getattr(owner, method)))

    def summary(self) -> dict[str, dict[str, float]]:
        """Per name: ``n`` calls, and ``p50_us``, ``p10_us``, ``p90_us``, ``mean_us`` of their wall times."""
        out = {}
        for name, times in self.times.items():
            ts = sorted(times)
            if not ts:
                continue
            n = len(ts)
            out[name] = {"n": n, "p50_us": 1e-3 * ts[n // 2], "p10_us": 1e-3 * ts[n // 10],
                         "p90_us": 1e-3 * ts[min(n - 1, (9 * n) // 10)], "mean_us": 1e-3 * sum(ts) / n}
        return out

    def write(self) -> None:
        """Write :meth:`summary` as JSON to :attr:`path`."""
        self.path.write_text(json.dumps(self.summary()))
