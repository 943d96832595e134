"""The LIST learner: A1 and T2 updated cycle by cycle from the measured residual vibration.

Updates (:class:`ListLearner`). Steps 1-4 of seed 003: vary T2 with A1 fixed until M is
minimal, then A1 with the best T2, and repeat. With two trials of a phase the next value is
the secant (eq. (5), both on one side) or the M-weighted average (eq. (6), on both sides),
:func:`~.params.paper_step`. The default rule ``components`` applies the secant
(:func:`~.params.secant_step`) to the signed components Im rho (for T2) and Re rho (for A1)
instead, each linear in its own parameter's mismatch and free of the noise in M. The first step
of a phase uses the LTI sensitivity of R. Where phi's relation fails (M rose against its
prediction, or the error fell as the parameter rose: strongly nonlinear or saturating plants),
the phase minimises M alone (:func:`~.trials.m_search`: bracketing and parabolic steps in M^2).
Safeguards: bounds, maximum step, rejection of incomplete, saturated or non-finite cycles
(:func:`~.measure.measure`), rollback to the best parameters when M grows, smaller steps after
failed ones, and holding at the best point once no step of at least ``switch_tol`` is wanted or
allowed, or after ``patience`` trials without a better M.

Everything is deterministic: the same inputs give the same updates bit for bit, and
:meth:`ListLearner.to_dict` / :meth:`ListLearner.from_dict` carry the full state exactly.

The class stands on two layers: its state, the bounds and the dictionary form
(:class:`~.state.LearnerState`), and the rules that decide after a trial (:class:`~.phases.PhaseRules`);
this module holds what a caller uses: the update, what to apply next, hold and resume.
"""

from __future__ import annotations

import math
from typing import Any

from .measure import Measurement, Reference, direction_sign, make_reference, measure, reference_m, residual_window
from .params import ListError, ListParams, finite_value
from .phases import PhaseRules
from .trials import ListUpdate, Trial, fmt_params, make_trial


class ListLearner(PhaseRules):
    """The LIST learner: one :meth:`update` per finished cycle; :attr:`params` to apply next.

    Parameters
    ----------
    config : ListConfig
        Settings.
    params : ListParams, optional
        Initial guess (e.g. from a mode estimate). Without it, the first unshaped cycle's
        identified mode gives it (ZV formulas).
    reference : Reference, optional
        A reference made earlier (:func:`make_reference`); otherwise the first cycle reported
        with ``used=None`` (unshaped) becomes it. Shaped cycles before a reference are rejected.

    Raises
    ------
    ListError
        Invalid arguments, or initial parameters outside the bounds.
    """

    # ------------------------------------------------------------------ what to apply next
    @property
    def params(self) -> ListParams | None:
        """The parameters to apply to the next cycle (None: run it unshaped for a reference)."""
        return self._params

    @property
    def best(self) -> tuple[ListParams, float] | None:
        """The best parameters measured so far and their M, or None."""
        return None if self._best is None else (self._best.params, self._best.m)

    @property
    def reference(self) -> Reference | None:
        return self._reference

    @property
    def needs_reference(self) -> bool:
        """True until a reference exists: run the next cycle unshaped and report ``used=None``."""
        return self._reference is None

    @property
    def phase(self) -> str:
        """``t2`` or ``a1`` (the parameter being varied) or ``hold``."""
        return self._phase

    @property
    def t2_bounds(self) -> tuple[float, float] | None:
        """The T2 bounds in force (resolved from the initial T2 when not configured), s."""
        return self._t2_bounds

    @property
    def history(self) -> list[dict[str, Any]]:
        """The last ``config.history`` updates, as :meth:`ListUpdate.as_dict`."""
        return [dict(h) for h in self._history]

    def hold(self) -> ListParams | None:
        """Stop exploring: hold at the best parameters so far (returned; the current ones if
        nothing was measured yet) until :meth:`resume`, or until M there rises above
        ``rollback_factor`` times the best (the plant changed)."""
        if self._best is None:
            return self._params
        self._parked, self._phase, self._trials, self._searching = True, "hold", [], False
        self._last = self._best
        self._params = self._best.params
        return self._params

    def resume(self) -> None:
        """Explore again after :meth:`hold` (or after holding for ``patience``)."""
        self._parked, self._stale = False, 0

    @property
    def holding(self) -> bool:
        """Whether the learner holds at its best parameters (:meth:`hold`, or ``patience``)."""
        return self._parked

    # ------------------------------------------------------------------ the update
    def update(self, times: Any, accel: Any, motion_end: float, end: float, used: ListParams | None,
               direction: float = 1.0) -> ListUpdate:
        """Learn from one finished cycle and return what to apply next.

        Parameters
        ----------
        times : (N,) array_like
            Sample times, s, relative to the cycle's START.
        accel : (N,) or (N, k) array_like
            Acceleration, m/s^2 (k axes: the reference's principal direction is used).
        motion_end, end : float
            The cycle's MOTION_END and END, s from its START.
        used : ListParams or None
            The parameters the cycle ran with; None: it ran unshaped, and becomes the reference.
        direction : float
            Sign of the move, +1 or -1: the residual is multiplied by it.

        Returns
        -------
        ListUpdate
            ``rejected`` cycles (incomplete, saturated, non-finite, no reference yet, or an
            unusable reference cycle) leave the parameters and the learning state unchanged.

        Raises
        ------
        ListError
            ``used`` or ``direction`` invalid (the caller's mistake, not the cycle's).
        """
        if used is not None:
            if not isinstance(used, ListParams):
                raise ListError(f"used must be ListParams or None, got {type(used).__name__}")
            used.check()
        sign = direction_sign(direction)
        self._iteration += 1
        if used is None:
            try:
                ref = make_reference(times, accel, motion_end, end, sign, self._config)
                if self._params is None:
                    guess, note = self._clip(ListParams.from_mode(ref.mode), bounds_from=True)
                else:
                    guess, note = self._params, ""
                m_ref = self._reference_m(ref, float(motion_end))
            except ListError as err:
                return self._record(math.nan, math.nan, None, self._params, "none", "rejected",
                                    f"unshaped cycle not usable as the reference: {err}")
            self._reference = ref
            if self._params is None:
                self._set_initial(guess)
            self._phase, self._trials, self._best, self._last = "t2", [], None, None
            self._scale = {"t2": 1.0, "a1": 1.0}
            self._limited = self._searching = self._parked = False
            self._stale = 0
            return self._record(m_ref, 0.0, None, self._params, "none", "reference",
                                f"reference: mode {ref.omega / (2 * math.pi):.4g} Hz, damping {ref.zeta:.4g}"
                                f" identified; next {fmt_params(self._params)}{note}", complex(1.0, 0.0))
        if self._reference is None:
            return self._record(math.nan, math.nan, used, self._params, "none", "rejected",
                                "no reference yet: run one cycle unshaped (used=None) first")
        if self._params is None:  # a reference given without parameters cannot happen; keep safe
            self._set_initial(used)
        try:
            window = self._window(self._reference, finite_value("motion_end", motion_end))
            meas = measure(times, accel, motion_end, end, self._reference, sign, self._config, window_start=window[0])
        except ListError as err:
            return self._record(math.nan, math.nan, used, self._params, "none", "rejected", f"cycle rejected: {err}")
        trial = self._trial(used, meas)
        nxt, parameter, action, reason = self._learn(trial)
        nxt, note = self._clip(nxt)  # only ever clips a foreign (out-of-bounds) point held or rolled back to
        self._params = nxt
        reason += note
        return self._record(meas.m, meas.phi, used, nxt, parameter, action, reason, meas.rho)

    def _window(self, ref: Reference, motion_end: float) -> tuple[float, float]:
        """The residual window with the T2 bounds in force (:func:`~.measure.residual_window`)."""
        return residual_window(motion_end, ref, self._config, self._t2_bounds)

    def _reference_m(self, ref: Reference, motion_end: float) -> float:
        """M of the reference over the learning window (what a shaped cycle's M compares with)."""
        return reference_m(ref, self._window(ref, motion_end), self._config)

    def _record(self, m: float, phi: float, used: ListParams | None, nxt: ListParams | None, parameter: str,
                action: str, reason: str, rho: complex = complex(math.nan, math.nan)) -> ListUpdate:
        best = self._best.m if self._best is not None else math.nan
        upd = ListUpdate(self._iteration, float(m), float(phi), used, nxt, parameter, action, reason, rho, best)
        if self._config.history:
            self._history.append(upd.as_dict())
            del self._history[: -self._config.history]
        return upd

    # ------------------------------------------------------------------ the trial
    def _trial(self, used: ListParams, meas: Measurement) -> Trial:
        assert self._reference is not None
        return make_trial(used, meas, self._reference, self._last, self._config)

