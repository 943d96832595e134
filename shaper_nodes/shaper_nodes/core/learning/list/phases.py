"""The LIST learner's rules: what to try after a measured trial.

:class:`PhaseRules` is the middle of :class:`~.learner.ListLearner` (over :class:`~.state.LearnerState`):
:meth:`PhaseRules._learn` takes one trial and decides the next parameters, the parameter varied, the action and
why. Hold while parked, rank the trial against the best (a new best, patience, the best point re-measured,
rollback), restart a phase when the cycle did not run the proposed point or a phase starts, else the phase's next
step: the secant or weighted step of phi's model (the LTI-sensitivity step where the secant slope is off), or,
where that model failed, the search of the minimum of M alone; every step within the bounds and the maximum step,
smaller after failed ones.
"""

from __future__ import annotations

import math

from .params import ListParams, paper_step, secant_step
from .state import MIN_STEP_SCALE, PARAMS, LearnerState
from .trials import Step, Trial, fmt_params, m_search, other_param, same_params

#: components rule: a secant slope outside [1/SLOPE_BAND, SLOPE_BAND] times the LTI sensitivity
#: (noise between close trials) is replaced by the sensitivity step
SLOPE_BAND = 4.0

#: what the learner decides after a cycle: (next parameters, parameter varied, action, reason)
_Decision = tuple[ListParams, str, str, str]


class PhaseRules(LearnerState):
    """The learner's decisions after a trial, on the state of :class:`~.state.LearnerState`."""

    # ------------------------------------------------------------------ steps
    @property
    def _score_name(self) -> str:
        return "M_c" if self._config.rule == "components" else "M"

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

    # ------------------------------------------------------------------ decisions
    def _from_base(self, base: Trial, prefer: str, why: str) -> _Decision:
        """Start a phase from ``base``: the preferred parameter's first step if it is worth a cycle
        (:meth:`_moves`), else the other's, else hold at the best point."""
        previous = self._phase
        small = []
        for name in (prefer, other_param(prefer)):
            step = self._limit(name, base.params, self._first_step(name, base))
            if self._moves(step):
                self._phase, self._trials, self._limited, self._searching = name, [base], step.limited, False
                action = "switch" if previous in PARAMS and name != previous else "first_step"
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
        in_phase = (phase in PARAMS and bool(self._trials) and proposed is not None
                    and same_params(trial.params, proposed)
                    and best.p(other) == self._trials[0].p(other) == trial.p(other))
        if in_phase:
            # the phase goes on from the best point, minimising M alone, its bad trial kept as a bound
            kept = self._shrink(phase)
            self._trials, self._searching = [*self._trials, trial], True
            kept += f"; the {phase.upper()} phase continues from there on M alone"
        else:
            for name in PARAMS:
                if trial.p(name) != best.p(name):
                    kept += self._shrink(name)
            self._trials, self._searching = [], False
        self._last = best
        return best.params, phase if phase in PARAMS else "none", "rollback", (
            f"M {trial.m:.4g} > {cfg.rollback_factor:g} x best M {best.m:.4g}: back to {fmt_params(best.params)}{kept}")

    def _restart(self, trial: Trial, notes: str) -> _Decision | None:
        """A phase from the trial when the cycle did not run the proposed parameters, when
        holding, or at a phase's start; None to go on with the phase."""
        proposed = self._params
        prefer = self._phase if self._phase in PARAMS else "t2"
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
