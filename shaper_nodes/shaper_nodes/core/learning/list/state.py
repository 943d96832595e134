"""The LIST learner's state: its fields, the bounds that hold its parameters, and its dictionary form.

:class:`LearnerState` is the base of :class:`~.learner.ListLearner`: the fields the learner's rules
(:class:`~.phases.PhaseRules`) and its update (:meth:`~.learner.ListLearner.update`) read and change, the
initial parameters checked against the bounds (:meth:`LearnerState._set_initial`), parameters clipped into
them (:meth:`LearnerState._clip`), and :meth:`LearnerState.to_dict` / :meth:`LearnerState.from_dict`, which
carry the full state exactly and name what is corrupt or inconsistent in a saved one.
"""

from __future__ import annotations

from typing import Any, Self

from shaper_nodes.core.shaping import MAX_DURATION

from .measure import Reference
from .params import ListConfig, ListError, ListParams, finite_value, int_at_least
from .trials import Trial, fmt_params, optional_trial_dict, params_from_dict, two_numbers

#: version of the dictionaries of :meth:`LearnerState.to_dict`
STATE_VERSION = 1
#: smallest step scale after rollbacks
MIN_STEP_SCALE = 1.0 / 1024.0
#: the learner's two parameters, in the order its phases prefer them
PARAMS = ("t2", "a1")

_STATE_KEYS = {"format", "version", "config", "params", "t2_bounds", "reference", "iteration", "phase", "trials",
               "best", "last", "step_scale", "step_limited", "searching", "stale", "parked", "history"}


class LearnerState:
    """The learner's state (the parameters as :class:`~.learner.ListLearner`'s, which it is the base of).

    Raises
    ------
    ListError
        Invalid arguments, or initial parameters outside the bounds.
    """

    # ------------------------------------------------------------------ fields and bounds
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

    @property
    def config(self) -> ListConfig:
        return self._config

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
    def from_dict(cls, d: Any) -> Self:
        """Restore :meth:`to_dict`'s state; :class:`ListError` names what is corrupt or inconsistent."""
        try:
            return cls._from_dict(d)
        except ListError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ListError(f"corrupt learner state: {type(err).__name__}: {err}") from None

    @classmethod
    def _from_dict(cls, d: Any) -> Self:
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
        if not isinstance(scale, dict) or set(scale) != set(PARAMS):
            raise ListError("step_scale must be a dictionary with keys t2, a1")
        for name in PARAMS:
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
