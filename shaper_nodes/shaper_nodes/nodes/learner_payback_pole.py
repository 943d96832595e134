"""The pooled-pole rule in the learner node's payback mode (``payback.pool_cycles`` > 0; :mod:`.learner_payback`).

The rule is :mod:`shaper_nodes.core.learning.list.pole_rule`'s (the ROS-free reproduction's ``scheduled_list_factor``
runs the same code); this module holds each move's :class:`~shaper_nodes.core.learning.list.pole_rule.PoleState`
between cycles and in the state file, and says what was decided:

- a move over a schedule with no factor kept whose reference cycle finds no factor predicted to pay
  (:func:`.learner_payback.choose`) runs its reference again: :meth:`PooledPole.reference` adds the cycle's window
  (:data:`~shaper_nodes.core.learning.list.loop_pole.Pool`, from the shaped command's end, 1 s) to the move's pool
  and searches the loop's pole in the mean; a factor on it chosen by the one-sample time rule is the move's trial;
  none after ``payback.pool_cycles`` windows: the move is held at the schedule alone;
- the trial of a factor chosen so is judged at the pole (:meth:`PooledPole.trial`): its windows pooled, kept when
  its response there is lower than the reference's by 2 standard errors of the change
  (:func:`~shaper_nodes.core.learning.list.loop_pole.change_at_pole`), run again when lower but not by that much
  (up to ``payback.pool_cycles`` windows), withdrawn otherwise. The node measures no flange position over
  a schedule, so the time is the one predicted before the trial (within one 2 ms sample), as for the one-window
  rule;
- a factor from one window whose trial did not pay: the move's references are pooled from then on (its pool starts
  afresh), as in the reproduction.

State: per move the pool's running sum (:meth:`~shaper_nodes.core.learning.list.loop_pole.Pool.to_dict`: the
first window's times and the sum per axis over 1 s of accelerometer, about 4 numbers per sample: 4000 at 1 kHz),
the poles and the reference's amplitude while a trial is judged; the document's ``poles``. Only one pool per move
at a time (the references' while they are pooled, the trial's while it is judged), emptied once decided, so the
state file holds at most one second of accelerometer per move.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

from shaper_nodes.core.learning.list import ListError, ListParams
from shaper_nodes.core.learning.list.pole_rule import PolePick, PoleState, judge_pole, pole_pick
from shaper_nodes.core.learning.moves import TIME_TOLERANCE_S

__all__ = ["PooledPole"]


class PooledPole:
    """Each move's pooled-pole state and the rule's steps (module docstring); ``cycles`` 0: off."""

    def __init__(self, cycles: int, servo_zeta: float, band: float, saved: Any, keys: Iterable[str],
                 error: Callable[[str], None]) -> None:
        self.cycles, self.servo_zeta, self.band = int(cycles), float(servo_zeta), float(band)
        self.states: dict[str, PoleState] = {}
        #: per move, its last cycle's windows pooled and amplitude at the loop's pole with its standard error (m/s^2;
        #: NaN if none), for the cycle's report (taken by the node)
        self.measured: dict[str, tuple[int, float, float]] = {}
        saved = saved if isinstance(saved, dict) else {}
        for key in keys:
            if key in saved:
                try:
                    self.states[key] = PoleState.from_dict(saved[key])
                except ListError as err:  # the move keeps its other state; its pooled windows start afresh
                    error(f"move {key}: saved pooled windows left out ({err})")

    def doc(self) -> dict[str, Any]:
        """The document's ``poles``: each move's state that holds something."""
        return {k: s.to_dict() for k, s in self.states.items()
                if s.pool.count or s.judging or s.pooled_only}

    def clear(self, key: str | None = None) -> None:
        """The move (all moves: None) learns again: nothing pooled or judged."""
        if key is None:
            self.states.clear()
        else:
            self.states.pop(key, None)

    def pooled_only(self, key: str) -> bool:
        """Whether the move's references go straight to the pool (its factor from one window did not pay)."""
        return self.cycles > 0 and key in self.states and self.states[key].pooled_only

    def judging(self, key: str) -> bool:
        """Whether the move's trial is judged at the loop's pole."""
        return key in self.states and self.states[key].judging

    def reference(self, key: str, cap: Any, command_end: float,
                  cost: Callable[[ListParams], float]) -> tuple[PolePick | None, bool, str]:
        """The move's reference window (``cap``: :class:`.learner_payback.Captured`, the shaped command's end at
        ``command_end`` s) pooled and the loop's pole searched; returns the pick (None: none), whether the move runs
        its reference again (no pick, fewer than ``payback.pool_cycles`` windows) and what was decided (for the
        log)."""
        st = self.states.setdefault(key, PoleState())
        st.pool.add(cap.times, cap.accel, command_end)
        count = st.pool.count
        t, y = st.pool.mean()
        try:
            pick = pole_pick(t, y, cost, TIME_TOLERANCE_S, self.servo_zeta, self.band)
        except ListError as err:
            pick, why = None, f" ({err})"
        else:
            why = ""
        self.measured[key] = (count, *(pick.reference if pick is not None else (math.nan, math.nan)))
        if pick is not None:
            st.chosen(pick)
            c, p = pick.loop, pick.choice.params
            return pick, False, (f"; the loop's pole in {count} reference window(s) pooled: {c.hz:.1f} Hz, zeta"
                                 f" {c.zeta:.3f}, amplitude {pick.reference[0]:.4g} +- {pick.reference[1]:.4g} m/s^2"
                                 f" (beside {pick.ringing} mode(s) that ring); next: factor A1 {p.a1:.4f}, T2"
                                 f" {p.t2 * 1e3:.2f} ms, time cost {pick.choice.cost_s * 1e3:+.1f} ms, judged at"
                                 " the pole")
        again = count < self.cycles
        if not again:
            st.reset()
        return None, again, (f"; no loop's pole paying in {count} reference window(s) pooled{why}: "
                             + ("the reference runs again" if again else "the schedule alone, held"))

    def trial(self, key: str, cap: Any, command_end: float) -> tuple[str, tuple[float, float], int, str]:
        """The move's trial judged at the loop's pole (:func:`~shaper_nodes.core.learning.list.pole_rule.judge_pole`
        on its windows pooled): ``"learn"`` (kept), ``"again"`` (run again) or ``"base"`` (withdrawn), the trial's
        (amplitude, error) at the pole (m/s^2), the windows pooled and what was decided (for the log)."""
        st = self.states[key]
        assert st.poles is not None and st.reference is not None
        st.pool.add(cap.times, cap.accel, command_end)
        count = st.pool.count
        t, y = st.pool.mean()
        ref = st.reference
        decision, trial, change = judge_pole(t, y, st.poles, ref, count, True, self.cycles, st.response)
        self.measured[key] = (count, *trial)
        if decision != "again":  # decided: the move has its factor, or is held (nothing pooled any more)
            del self.states[key]
        return decision, trial, count, (
            f"; amplitude at the loop's pole {trial[0]:.4g} +- {trial[1]:.4g} m/s^2 ({count} trial window(s) pooled)"
            f" against the pooled reference's {ref[0]:.4g} +- {ref[1]:.4g}"
            + ("" if math.isnan(change) else f", its response lower by {change:.2f} standard errors of the change")
            + ": "
            + {"learn": "lower, the factor is kept", "again": "lower, not resolved: the trial runs again",
               "base": ("lower, not resolved in the windows allowed" if trial[0] < ref[0] else "not lower")
               + ": withdrawn, the schedule alone, held"}[decision])

    def single_failed(self, key: str) -> bool:
        """A factor from one window did not pay and the move has none kept: True if its references are pooled from
        now on (the rule on), False if it is held."""
        if self.cycles <= 0 or self.pooled_only(key):
            return False
        self.states[key] = PoleState(pooled_only=True)
        return True
