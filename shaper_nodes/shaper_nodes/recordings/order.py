"""The causal order of messages logged at the same time: a shaper made at a cycle's END goes after it.

A lockstep recording's clock stands still while a learner answers a cycle's END, so the active
shaper its update made is logged at the END's time, and a recorder taking several topics may have
written it first (an END repaired by DDS after a lost packet arrives later). :func:`shaper_after_end`
puts such a shaper back after the END, for the players and replays that go by recording order.

Nothing here imports rclpy or message types.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")
#: messages logged at one time held to be put in causal order, at most (a larger group goes as recorded)
MAX_TIE_GROUP = 10_000


def shaper_after_end(items: Iterable[T], time_of: Callable[[T], object], is_shaper: Callable[[T], bool],
                     is_end: Callable[[T], bool], max_group: int = MAX_TIE_GROUP) -> Iterator[T]:
    """``items`` in recording order, but in each run of items with the same ``time_of`` (log time), the active
    shapers recorded before the run's last END moved to just after it; everything else keeps its order. A change
    at an END's instant shaped none of that cycle's samples in either order; played or replayed before the END, a
    learner would take it as a change during the cycle. Runs longer than ``max_group`` go as recorded (memory
    stays bounded)."""
    group: list[T] = []
    for item in items:
        if group and (time_of(item) != time_of(group[0]) or len(group) >= max_group):
            yield from _reorder_ties(group, is_shaper, is_end)
            group = []
        group.append(item)
    yield from _reorder_ties(group, is_shaper, is_end)


def _reorder_ties(group: list[T], is_shaper: Callable[[T], bool], is_end: Callable[[T], bool]) -> list[T]:
    shapers = [is_shaper(m) for m in group]
    if len(group) < 2 or not any(shapers):
        return group
    last = max((i for i, m in enumerate(group) if not shapers[i] and is_end(m)), default=-1)
    moved = [m for i, m in enumerate(group[:last]) if shapers[i]] if last > 0 else []
    if not moved:
        return group
    return [m for i, m in enumerate(group[:last + 1]) if not shapers[i]] + moved + group[last + 1:]
