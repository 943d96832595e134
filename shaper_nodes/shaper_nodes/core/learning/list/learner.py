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
"""

from __future__ import annotations

import math
from typing import Any

from shaper_nodes.core.shaping import MAX_DURATION

from .measure import Measurement, Reference, direction_sign, make_reference, measure, reference_m, residual_window
from .params import ListConfig, ListError, ListParams, finite_value, int_at_least, paper_step, secant_step
from .trials import (
    ListUpdate,
    Step,
    Trial,
    fmt_params,
    m_search,
    make_trial,
    optional_trial_dict,
    other_param,
    params_from_dict,
    same_params,
    two_numbers,
)

#: version of the dictionaries of :meth:`ListLearner.to_dict`
STATE_VERSION = 1
#: components rule: a secant slope outside [1/SLOPE_BAND, SLOPE_BAND] times the LTI sensitivity
#: (noise between close trials) is replaced by the sensitivity step
SLOPE_BAND = 4.0
#: smallest step scale after rollbacks
MIN_STEP_SCALE = 1.0 / 1024.0

_PARAMS = ("t2", "a1")
_STATE_KEYS = {"format", "version", "config", "params", "t2_bounds", "reference", "iteration", "phase", "trials",
               "best", "last", "step_scale", "step_limited", "searching", "stale", "parked", "history"}

#: what the learner decides after a cycle: (next parameters, parameter varied, action, reason)
_Decision = tuple[ListParams, str, str, str]



class ListLearner:
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

    def __init__(self, config: ListConfig | None = None, params: ListParams | None = None,
                 reference: Reference | None = None) -> None:
        config = ListConfig() if config is None else config
        if not isinstance(config, ListConfig):
            raise ListError(f"config must be a ListConfig, got {type(config).__name__}")
        if reference is not None and not isinstance(reference, Reference):
            raise ListError(f"reference must be a Reference, got {type(reference).__name__}")
        self._config = config
        self._t2_bounds: tuple[float, float] | None = config.t2_bounds
        self._params: ListParams | None = None
        self._reference = reference
        self._iteration = 0
        self._phase = "t2"
        self._trials: list[Trial] = []
        self._best: Trial | None = None
        self._last: Trial | None = None
        self._scale = {"t2": 1.0, "a1": 1.0}  # per parameter, multiplies its maximum step
        self._limited = False  # the step to the last proposal was cut by the maximum step
        self._searching = False  # this phase minimises M alone (phi's model failed)
        self._stale = 0  # trials in a row without a new best M
        self._parked = False  # holding at the best point after `patience` such trials
        self._history: list[dict[str, Any]] = []
        if params is None and reference is not None:
            params, _ = self._clip(ListParams.from_mode(reference.mode), bounds_from=True)
        if params is not None:
            self._set_initial(params)

    # ------------------------------------------------------------------ state
    @property
    def config(self) -> ListConfig:
        return self._config

    @property
    def _score_name(self) -> str:
        return "M_c" if self._config.rule == "components" else "M"

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

    def _set_initial(self, params: ListParams) -> None:
        if not isinstance(params, ListParams):
            raise ListError(f"params must be ListParams, got {type(params).__name__}")
        params.check()
        if self._t2_bounds is None:
            self._t2_bounds = (0.5 * params.t2, min(2.0 * params.t2, MAX_DURATION / 2.0))
        lo, hi = self._config.a1_bounds
        tlo, thi = self._t2_bounds
        if not (lo <= params.a1 <= hi and tlo <= params.t2 <= thi):
            raise ListError(f"initial parameters {fmt_params(params)} outside the bounds A1 {lo:g}-{hi:g},"
                            f" T2 {tlo:.6g}-{thi:.6g} s")
        self._params = params

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

    # ------------------------------------------------------------------ trials and steps
    def _trial(self, used: ListParams, meas: Measurement) -> Trial:
        assert self._reference is not None
        return make_trial(used, meas, self._reference, self._last, self._config)

    def _slope(self, name: str, params: ListParams) -> float:
        """LTI sensitivity of the error to the parameter, near T2 = pi / omega_d:
        d Im R / d T2 = (1 - A1) e^{sigma T2} omega_d, d Re R / d A1 = 1 + e^{sigma T2}."""
        ref = self._reference
        assert ref is not None
        g = math.exp(ref.sigma * params.t2)
        return params.a2 * g * ref.omega_d if name == "t2" else 1.0 + g

    def _first_step(self, name: str, trial: Trial) -> float:
        """The LTI-sensitivity (Newton) step from one trial: p - e / slope (none at the noise floor)."""
        if trial.floor:
            return trial.p(name)
        return trial.p(name) - trial.e(name) / self._slope(name, trial.params)

    def _clip(self, params: ListParams, bounds_from: bool = False) -> tuple[ListParams, str]:
        """Parameters clipped into the bounds, and a note naming each clip."""
        lo, hi = self._config.a1_bounds
        tb = self._t2_bounds if not (bounds_from and self._config.t2_bounds is None) else None
        a1, t2, notes = params.a1, params.t2, []
        if not lo <= a1 <= hi:
            notes.append(f"A1 {a1:.6g} clipped to its bound {min(max(a1, lo), hi):g}")
            a1 = min(max(a1, lo), hi)
        if tb is not None and not tb[0] <= t2 <= tb[1]:
            notes.append(f"T2 {t2:.6g} s clipped to its bound {min(max(t2, tb[0]), tb[1]):.6g} s")
            t2 = min(max(t2, tb[0]), tb[1])
        return ListParams(a1, t2), ("; " + "; ".join(notes)) if notes else ""

    def _limit(self, name: str, base: ListParams, target: float) -> Step:
        """Step ``name`` from ``base`` towards ``target`` within the bounds and the maximum step
        (times the step scale)."""
        cur = base.t2 if name == "t2" else base.a1
        scale = self._scale[name]
        cap = scale * self._max_step(name, base)
        note = ""
        if not math.isfinite(target):
            target, note = cur, "; non-finite step ignored"
        wanted_params, clip_note = self._clip(ListParams(base.a1, target) if name == "t2"
                                              else ListParams(target, base.t2))
        wanted = (wanted_params.t2 if name == "t2" else wanted_params.a1) - cur
        step, limited = wanted, abs(wanted) > cap
        if limited:
            step = math.copysign(cap, wanted)
            note += f"; step limited to {cap:.6g}{' s' if name == 't2' else ''}" + (
                f" (maximum x {scale:.3g} after failed steps)" if scale < 1.0 else "")
        new = ListParams(base.a1, cur + step) if name == "t2" else ListParams(cur + step, base.t2)
        return Step(name, new, abs(step) / abs(cur), abs(wanted) / abs(cur), limited, note + clip_note)

    def _moves(self, step: Step) -> bool:
        """Whether a step is worth a cycle: it moves, the parameter is not converged (the step
        wanted is at least switch_tol), and after failed steps the allowed step is not below it."""
        tol = self._config.switch_tol
        return step.rel > 0.0 and step.wanted >= tol and not (self._scale[step.name] < 1.0 and step.rel < tol)

    def _max_step(self, name: str, base: ListParams) -> float:
        return self._config.max_step_t2 * base.t2 if name == "t2" else self._config.max_step_a1

    def _shrink(self, name: str, base: ListParams | None = None, tried: tuple[ListParams, ...] = ()) -> str:
        """Halve the maximum step of ``name`` after a failed step (a rollback); after a phase that
        found nothing better (``tried`` from ``base``), at most half its largest step, so that the
        same first step is not tried again. Returns a note."""
        ratio = 1.0
        if base is not None and tried:
            biggest = max(abs((q.t2 - base.t2) if name == "t2" else (q.a1 - base.a1)) for q in tried)
            ratio = biggest / self._max_step(name, base) or 1.0
        self._scale[name] = max(MIN_STEP_SCALE, 0.5 * min(self._scale[name], ratio))
        return f"; {name.upper()} steps now at most {self._scale[name]:.3g} x the maximum"

    def _from_base(self, base: Trial, prefer: str, why: str) -> _Decision:
        """Start a phase from ``base``: the preferred parameter's first step if it is worth a cycle
        (:meth:`_moves`), else the other's, else hold at the best point."""
        previous = self._phase
        small = []
        for name in (prefer, other_param(prefer)):
            step = self._limit(name, base.params, self._first_step(name, base))
            if self._moves(step):
                self._phase, self._trials, self._limited, self._searching = name, [base], step.limited, False
                action = "switch" if previous in _PARAMS and name != previous else "first_step"
                return step.params, name, action, (
                    f"{why}; {name.upper()} phase from {fmt_params(base.params)} (M {base.m:.4g}):"
                    f" first step {100 * step.rel:.3g} %{step.note}")
            small.append(f"{name.upper()} step {100 * step.rel:.2g} % (wanted {100 * step.wanted:.2g} %){step.note}"
                         + (" (at the noise floor)" if base.floor else ""))
        assert self._best is not None
        self._phase, self._trials, self._searching = "hold", [], False
        return self._best.params, "none", "hold", (
            f"{why}; holding at the best {fmt_params(self._best.params)} (M {self._best.m:.4g}): "
            + ", ".join(small) + f"; switch_tol {self._config.switch_tol:g}")

    def _learn(self, trial: Trial) -> _Decision:
        """What to do after a measured trial: hold while parked (:meth:`_stay_parked`), rank the
        trial against the best (:meth:`_rank`: a new best, patience, the best point re-measured,
        rollback), restart a phase from it when the cycle did not run the proposed point or a
        phase starts (:meth:`_restart`), else the phase's next step (:meth:`_phase_step`)."""
        held = self._stay_parked(trial)
        if held is not None:
            return held
        self._last = trial
        ranked, notes = self._rank(trial)
        if ranked is not None:
            return ranked
        restarted = self._restart(trial, notes)
        if restarted is not None:
            return restarted
        return self._phase_step(trial, notes)

    def _stay_parked(self, trial: Trial) -> _Decision | None:
        """While parked: hold if the cycle re-measured the best point and M there did not rise
        above ``rollback_factor`` times the best; otherwise stop holding (None)."""
        if not self._parked:
            return None
        cfg, best = self._config, self._best
        assert best is not None
        if same_params(trial.params, best.params) and trial.m <= cfg.rollback_factor * best.m:
            self._last = trial
            return best.params, "none", "hold", (
                f"holding at the best {fmt_params(best.params)} (best M {best.m:.4g}, now {trial.m:.4g}):"
                f" {cfg.patience} trials in a row found nothing better")
        self._parked, self._stale = False, 0  # M rose at the best point, or another shaper ran
        return None

    def _rank(self, trial: Trial) -> tuple[_Decision | None, str]:
        """Rank the trial against the best so far: a new best; the best point re-measured (its
        latest M counts; the steps are reset if M there rose by ``rollback_factor``); a hold
        after ``patience`` trials without a better M; a rollback when M grew by more than
        ``rollback_factor``. Returns the decision if the ranking made one, and notes."""
        cfg, best = self._config, self._best
        if best is None or trial.score < best.score:
            self._best, self._stale = trial, 0
            return None, ""
        if same_params(trial.params, best.params):
            notes = ""
            if trial.m > cfg.rollback_factor * best.m and min(self._scale.values()) < 1.0:
                self._scale = {"t2": 1.0, "a1": 1.0}
                notes = f"; M at the best point rose from {best.m:.4g} to {trial.m:.4g} (plant changed?): steps reset"
            self._best = trial  # the latest measurement of a point is the one that counts
            return None, notes
        if cfg.patience and self._stale + 1 >= cfg.patience:
            return self._give_up(best), ""
        if trial.m > cfg.rollback_factor * best.m:
            return self._rollback(trial, best), ""
        return None, ""

    def _give_up(self, best: Trial) -> _Decision:
        """Hold at the best point after ``patience`` trials in a row without a better M."""
        cfg = self._config
        self._stale += 1
        self._parked, self._phase, self._trials, self._searching = True, "hold", [], False
        self._last = best
        return best.params, "none", "hold", (
            f"{self._stale} trials in a row without a better M than {best.m:.4g}: holding at the best"
            f" {fmt_params(best.params)} until M there rises above {cfg.rollback_factor:g} x")

    def _rollback(self, trial: Trial, best: Trial) -> _Decision:
        """Back to the best point after M grew: the phase goes on from there on M alone if the
        trial was its proposed step; otherwise the phase ends. The failed steps shrink."""
        cfg, proposed = self._config, self._params
        self._stale += 1
        phase, kept = self._phase, ""
        other = other_param(phase)
        in_phase = (phase in _PARAMS and bool(self._trials) and proposed is not None
                    and same_params(trial.params, proposed)
                    and best.p(other) == self._trials[0].p(other) == trial.p(other))
        if in_phase:
            # the phase goes on from the best point, minimising M alone, its bad trial kept as a bound
            kept = self._shrink(phase)
            self._trials, self._searching = [*self._trials, trial], True
            kept += f"; the {phase.upper()} phase continues from there on M alone"
        else:
            for name in _PARAMS:
                if trial.p(name) != best.p(name):
                    kept += self._shrink(name)
            self._trials, self._searching = [], False
        self._last = best
        return best.params, phase if phase in _PARAMS else "none", "rollback", (
            f"M {trial.m:.4g} > {cfg.rollback_factor:g} x best M {best.m:.4g}: back to {fmt_params(best.params)}{kept}")

    def _restart(self, trial: Trial, notes: str) -> _Decision | None:
        """A phase from the trial when the cycle did not run the proposed parameters, when
        holding, or at a phase's start; None to go on with the phase."""
        proposed = self._params
        prefer = self._phase if self._phase in _PARAMS else "t2"
        if proposed is None or not same_params(trial.params, proposed):
            return self._from_base(trial, prefer, f"the cycle ran with {fmt_params(trial.params)}, not the proposed"
                                                  f" {fmt_params(proposed)}: phase restarted from it" + notes)
        if self._phase == "hold" or not self._trials:
            why = "holding: re-measured" if self._phase == "hold" else "phase start"
            return self._from_base(trial, prefer, why + notes)
        return None

    def _phase_step(self, trial: Trial, notes: str) -> _Decision:
        """The phase's next step after ``trial``: its end (:meth:`_phase_over`), or the step
        phi's model gives (:meth:`_model_target`), or, where that model failed, the search of
        the minimum of M alone; within the bounds and the maximum step."""
        cfg, name = self._config, self._phase
        trials = [*self._trials, trial]
        self._trials = trials
        prev = trials[-2]
        ended = self._phase_over(name, trials)
        if ended:
            return self._end_phase(name, trials, ended + notes)
        target: float | None = None
        action = "search"
        if not self._searching:
            target, action, notes = self._model_target(name, prev, trial, notes)
        start = trial
        if self._searching:
            action = "search"
            found = m_search(name, trials, cfg.switch_tol)
            if found is None:
                return self._end_phase(name, trials, f"{name.upper()} minimum of M bracketed within switch_tol" + notes)
            target, start, how = found
            notes = f" ({how}){notes}"
        assert target is not None
        step = self._limit(name, start.params, target)
        if step.rel == 0.0 or (self._scale[name] < 1.0 and step.rel < cfg.switch_tol):
            return self._end_phase(name, trials, f"{name.upper()} cannot move by switch_tol{step.note}" + notes)
        self._limited = step.limited
        p0, p1, e0, e1 = prev.p(name), trial.p(name), prev.e(name), trial.e(name)
        return step.params, name, action, (f"{name.upper()} {action} from trials {p0:.6g}, {p1:.6g}"
                                           f" (errors {e0:.4g}, {e1:.4g}, M {prev.m:.4g}, {trial.m:.4g}):"
                                           f" step {100 * step.rel:.3g} %{step.note}{notes}")

    def _phase_over(self, name: str, trials: list[Trial]) -> str:
        """Why the phase of ``name`` ends with its last trial, or "" if it goes on: the residual
        at the noise floor, converged, ``phase_trials`` done, or M rose past the minimum."""
        cfg = self._config
        trial, prev = trials[-1], trials[-2]
        improved = min(tr.score for tr in trials) < (1.0 - cfg.switch_tol) * trials[0].score
        rel_last = abs(trial.p(name) - prev.p(name)) / abs(trial.p(name))
        if trial.floor:
            return "residual at the noise floor (|rho| below 3 standard errors)"
        if rel_last < cfg.switch_tol and not self._limited and not self._searching:
            return f"{name.upper()} converged (last step {100 * rel_last:.2g} % < switch_tol)"
        if len({tr.p(name) for tr in trials}) - 1 >= cfg.phase_trials:
            return f"{cfg.phase_trials} trials of {name.upper()} done"
        if not self._searching and improved and trial.score > prev.score:
            return f"M rose ({self._score_name} {prev.score:.4g} -> {trial.score:.4g}): minimum passed"
        return ""

    def _model_target(self, name: str, prev: Trial, trial: Trial, notes: str) -> tuple[float | None, str, str]:
        """The next value of ``name`` from the last two trials by phi's model (the rule's secant
        or weighted step; the sensitivity step where the secant slope is off the LTI one), the
        action and the notes; no value, and the phase turned to searching M alone, where the
        model failed (M rose against its prediction, or the error fell as the parameter rose)."""
        cfg = self._config
        p0, p1, e0, e1 = prev.p(name), trial.p(name), prev.e(name), trial.e(name)
        target: float | None = None
        same_side = (e0 >= 0.0) == (e1 >= 0.0)
        action = "secant" if same_side else "weighted"
        if trial.score > prev.score:  # phi's step made M worse and nothing better was found
            notes += f"; M rose ({self._score_name} {prev.score:.4g} -> {trial.score:.4g}) against phi's prediction"
        elif (secant := secant_step(p0, p1, e0, e1)) is None:
            notes += f"; the error fell as {name.upper()} rose (errors {e0:.4g}, {e1:.4g}), against the LTI model"
        elif cfg.rule == "paper":
            target = paper_step(p0, p1, abs(e0), abs(e1), same_side)
        else:
            target, model = secant, self._slope(name, trial.params)
            if not 1.0 / SLOPE_BAND <= (e1 - e0) / (p1 - p0) / model <= SLOPE_BAND:
                target, action = self._first_step(name, trial), "first_step"
                notes += (f"; secant slope {(e1 - e0) / (p1 - p0):.4g} more than {SLOPE_BAND:g} times off the"
                          f" LTI sensitivity {model:.4g}: sensitivity step instead")
        if target is None:
            self._searching = True
            notes += ": searching the minimum of M alone"
        return target, action, notes

    def _end_phase(self, name: str, trials: list[Trial], why: str) -> _Decision:
        """End the phase of ``name``: continue from its best trial with the other parameter."""
        base = min(trials, key=lambda tr: tr.score)
        if len(trials) > 1 and not base.score < (1.0 - self._config.switch_tol) * trials[0].score:
            # the phase found nothing (more than switch_tol) better: smaller steps
            why += "; no improvement in the phase" + self._shrink(name, trials[0].params,
                                                                  tuple(tr.params for tr in trials))
        return self._from_base(base, other_param(name), why)


    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """The full state as a JSON-serialisable dictionary (floats round-trip exactly)."""
        return {
            "format": "list_learner", "version": STATE_VERSION,
            "config": self._config.as_dict(),
            "params": None if self._params is None else self._params.as_dict(),
            "t2_bounds": None if self._t2_bounds is None else list(self._t2_bounds),
            "reference": None if self._reference is None else self._reference.as_dict(),
            "iteration": self._iteration, "phase": self._phase,
            "trials": [tr.as_dict() for tr in self._trials],
            "best": optional_trial_dict(self._best), "last": optional_trial_dict(self._last),
            "step_scale": dict(self._scale),
            "step_limited": self._limited, "searching": self._searching,
            "stale": self._stale, "parked": self._parked,
            "history": [dict(h) for h in self._history],
        }

    @classmethod
    def from_dict(cls, d: Any) -> ListLearner:
        """Restore :meth:`to_dict`'s state; :class:`ListError` names what is corrupt or inconsistent."""
        try:
            return cls._from_dict(d)
        except ListError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ListError(f"corrupt learner state: {type(err).__name__}: {err}") from None

    @classmethod
    def _from_dict(cls, d: Any) -> ListLearner:
        """The restore, checked part by part in the order of the state's fields."""
        _check_state_keys(d)
        config = ListConfig.from_dict(d["config"])
        ref = None if d["reference"] is None else Reference.from_dict(d["reference"])
        self = cls(config, None, None)
        self._reference = ref
        self._restore_params(d)
        self._restore_trials(d)
        self._restore_steps(d)
        if not isinstance(d["history"], list) or not all(isinstance(h, dict) for h in d["history"]):
            raise ListError("history must be a list of dictionaries")
        self._history = [dict(h) for h in d["history"]][-config.history:] if config.history else []
        return self

    def _restore_params(self, d: dict[str, Any]) -> None:
        """The T2 bounds in force (the configured ones if configured) and the parameters."""
        config = self._config
        if d["t2_bounds"] is not None:
            self._t2_bounds = ListConfig._bounds("t2_bounds", two_numbers("t2_bounds", d["t2_bounds"]), 0.0,
                                                 MAX_DURATION / 2.0)
        elif config.t2_bounds is not None:
            raise ListError("t2_bounds missing although configured")
        if config.t2_bounds is not None and self._t2_bounds != config.t2_bounds:
            raise ListError("t2_bounds differ from the configured ones")
        if d["params"] is not None:
            if self._t2_bounds is None:
                raise ListError("parameters without T2 bounds")
            self._set_initial(params_from_dict(d["params"]))
        elif self._reference is not None:
            raise ListError("a reference but no parameters")

    def _restore_trials(self, d: dict[str, Any]) -> None:
        """The iteration, the phase, its trials, and the best and last trials."""
        self._iteration = int_at_least("iteration", d["iteration"], 0)
        if d["phase"] not in ("t2", "a1", "hold"):
            raise ListError(f"unknown phase {d['phase']!r}")
        self._phase = d["phase"]
        if not isinstance(d["trials"], list):
            raise ListError("trials must be a list")
        self._trials = [Trial.from_dict(x) for x in d["trials"]]
        self._best = None if d["best"] is None else Trial.from_dict(d["best"])
        self._last = None if d["last"] is None else Trial.from_dict(d["last"])
        if (self._trials or self._best or self._last) and (
                self._reference is None or self._best is None or self._last is None):
            raise ListError("trials without a reference, a best or a last trial")
        if self._phase == "hold" and self._trials:
            raise ListError("trials recorded while holding")

    def _restore_steps(self, d: dict[str, Any]) -> None:
        """The step scales and the flags of the step, the search, patience and holding."""
        scale = d["step_scale"]
        if not isinstance(scale, dict) or set(scale) != set(_PARAMS):
            raise ListError("step_scale must be a dictionary with keys t2, a1")
        for name in _PARAMS:
            x = finite_value("step_scale", scale[name])
            if not MIN_STEP_SCALE <= x <= 1.0:
                raise ListError(f"step_scale must be in [{MIN_STEP_SCALE:g}, 1], got {x!r}")
            self._scale[name] = x
        if not (isinstance(d["step_limited"], bool) and isinstance(d["searching"], bool)):
            raise ListError("step_limited and searching must be true or false")
        self._limited, self._searching = d["step_limited"], d["searching"]
        self._stale = int_at_least("stale", d["stale"], 0)
        if not isinstance(d["parked"], bool) or (d["parked"] and (self._phase != "hold" or self._best is None)):
            raise ListError("parked must be true or false, and true only while holding at a best point")
        self._parked = d["parked"]
        if self._searching and len(self._trials) < 2:
            raise ListError("searching with fewer than two trials")


def _check_state_keys(d: Any) -> None:
    """A dictionary of the list_learner format of :data:`STATE_VERSION` with exactly its keys."""
    if not isinstance(d, dict):
        raise ListError(f"learner state must be a dictionary, got {type(d).__name__}")
    if d.get("format") != "list_learner" or d.get("version") != STATE_VERSION:
        raise ListError(f"not a list_learner state of version {STATE_VERSION}:"
                        f" format {d.get('format')!r}, version {d.get('version')!r}")
    if set(d) != _STATE_KEYS:
        raise ListError(f"learner state keys differ: missing {sorted(_STATE_KEYS - set(d))},"
                        f" unknown {sorted(set(d) - _STATE_KEYS)}")
