"""The payload MRILC per move builds its operators for (``mode: mrilc_moves``): told, or worked out from the drift.

**Told.** ``mrilc_moves.payload_mass`` (> 0, kg) is passed to the operator's provider as ``payload=`` when a move's
operator is next built (:meth:`PayloadGlue.provider`); 0: the provider's own.

**From the drift** (``mrilc_moves.payload_from_drift``, default on, with ``mrilc_moves.modes`` naming the model's
modes, ``"module:function"`` called as ``f(pose, payload)`` -> Hz; the simulated arm's:
``sim_plant_node.arm.lifted:arm_modes``). At the drift warning's relearn (:meth:`PayloadGlue.from_drift`) the
warning's KeyValues give the mode the identifier measured (``mode_hz``, the one it rated; ``modes_hz``, every sharp
mode of the cycle) and the cycle it was measured in (``cycle``: the move whose START the learner saw with that
index, its goal the pose); :func:`~shaper_nodes.core.learning.mrilc.payload.payload_from_modes` finds the payload
in ``mrilc_moves.payload_range`` kg whose model mode at that pose matches it. Found, it becomes
``mrilc_moves.payload_mass`` (set on the node: ``ros2 param get`` shows it), so every move's operator is rebuilt
for it at the relearn, and the state file keeps it (``payload``: the mass, ``"source": "drift"``, the mode and the
move) so that a restarted learner builds for it again. Refused (no mode in the warning, a cycle the learner did not
see, no mass in the range, an ambiguous mode, no ``mrilc_moves.modes``), the relearn goes on with
``payload_mass`` as it was (today's behaviour). A payload told since the last relearn (``payload_mass`` set from
outside, e.g. ``ros2 param set``) is the owner's word: kept, nothing worked out. Either way one line on the log and
the status ``learner: payload`` on /diagnostics (OK with ``mass_kg``, ``mode_hz``, ``move``; WARN with the reason).

Why on by default: on the operator of the old payload the relearn does not converge after a 2 -> 4.5 kg change
(docs/results/arm_mrilc_payload.md), and an owner does not always tell the robot its payload; the drift watch has
measured the new mode. It changes nothing without ``mrilc_moves.modes``.
"""

from __future__ import annotations

import collections
import functools
import importlib
import inspect
import math
from collections.abc import Callable
from typing import Any

from rclpy.parameter import Parameter

from shaper_nodes.core.learning.mrilc.model import MrilcError
from shaper_nodes.core.learning.mrilc.payload import PayloadEstimate, PayloadRefused, payload_from_modes
from shaper_nodes.ros.diagnostics import OK, WARN

#: cycles remembered (cycle index -> move key) to find the pose of a warning's cycle
REMEMBERED = 64
#: the state file's key of the payload worked out from the drift
KEY = "payload"
_ENTRY = {"mass", "source", "mode_hz", "move"}


def load_provider(name: str, what: str = "mrilc_moves.operator") -> Callable[..., Any]:
    """The provider ``module:function`` names. Raises ValueError naming the problem."""
    module, _, func = name.partition(":")
    if not module or not func:
        raise ValueError(f"{what} must be 'module:function', got {name!r}")
    try:
        out = getattr(importlib.import_module(module), func)
    except (ImportError, AttributeError) as err:
        raise ValueError(f"{what} {name!r} cannot be loaded: {err}") from None
    if not callable(out):
        raise ValueError(f"{what} {name!r} is not callable")
    return out


def saved_payload(doc: dict[str, Any]) -> dict[str, Any] | None:
    """The state document's payload from the drift (None without one). Raises MrilcError naming a bad entry."""
    entry = doc.get(KEY)
    if entry is None:
        return None
    if not isinstance(entry, dict) or set(entry) != _ENTRY or entry["source"] != "drift":
        raise MrilcError(f"{KEY} must have the entries {sorted(_ENTRY)} with source 'drift', got {entry!r}")
    mass = entry["mass"]
    if not (isinstance(mass, (int, float)) and math.isfinite(mass) and 0.0 <= mass <= 1000.0):
        raise MrilcError(f"{KEY}.mass must be a finite mass in [0, 1000] kg, got {mass!r}")
    return dict(entry)


class PayloadGlue:
    """The payload of the MRILC-per-move learner ``node`` (module docstring).

    Parameters
    ----------
    node : LearnerBase
        The learner node (its logger and diagnostics; ``payload_mass`` is set on it).
    params : Live
        The mode's parameters (``mrilc_moves.*``).
    operator : callable
        The operator's provider.
    saved : dict or None
        The state file's payload from the drift (:func:`saved_payload`): set again as ``payload_mass``.
    """

    def __init__(self, node: Any, params: Any, operator: Callable[..., Any], saved: dict[str, Any] | None) -> None:
        self.node, self.params = node, params
        self.operator = operator
        v = params.value.mrilc_moves
        self.enabled = bool(v.payload_from_drift)
        self.modes = load_provider(str(v.modes), "mrilc_moves.modes") if str(v.modes) else None
        rng = [float(x) for x in v.payload_range]
        if len(rng) != 2 or not all(math.isfinite(x) for x in rng) or not 0.0 <= rng[0] < rng[1] <= 1000.0:
            raise ValueError(f"mrilc_moves.payload_range must be [low, high] kg with 0 <= low < high <= 1000, got"
                             f" {rng}")
        self.range = (rng[0], rng[1])
        self._moves: collections.OrderedDict[int, str] = collections.OrderedDict()
        self._setting = False  # (the node setting payload_mass itself)
        #: payload_mass was set from outside (told) since the last relearn: the owner's word is kept
        self.told = False
        node.add_post_set_parameters_callback(self._on_set)
        #: the payload from the drift in force (the state file's entry), None: none
        self.estimate: dict[str, Any] | None = None
        if saved is not None:
            self._take(saved, f"payload {saved['mass']:.4g} kg from the drift's mode (the state file)")

    def mass(self) -> float:
        """The payload the operators are built for, kg (0: the provider's own)."""
        return float(self.params.value.mrilc_moves.payload_mass)

    def state(self) -> dict[str, Any]:
        """The state file's entry: the payload from the drift while it is the one in force."""
        est = self.estimate
        return {KEY: est} if est is not None and est["mass"] == self.mass() else {}

    def seen(self, cycle: int, key: str) -> None:
        """Cycle ``cycle`` ran move ``key`` (the pose of a warning's cycle)."""
        self._moves[cycle] = key
        self._moves.move_to_end(cycle)
        while len(self._moves) > REMEMBERED:
            self._moves.popitem(last=False)

    def provider(self) -> Callable[..., Any]:
        """The operator's provider, told the payload when it is set (> 0). Raises ValueError when it takes none."""
        mass = self.mass()
        if mass <= 0.0:
            return self.operator
        try:
            inspect.signature(self.operator).bind(*[None] * 6, payload=mass)
        except TypeError as err:
            raise ValueError(f"mrilc_moves.payload_mass is set ({mass:g} kg) but the operator's provider takes no"
                             f" payload= ({err})") from None
        return functools.partial(self.operator, payload=mass)

    def from_drift(self, values: dict[str, str], goals: dict[str, list[float]]) -> None:
        """At a drift warning's relearn: the payload from the warning's mode (``values``, its KeyValues) at the
        goal (``goals``: move key -> goal pose) of the move of its cycle; taken as ``payload_mass``, or refused
        (module docstring)."""
        told, self.told = self.told, False
        if not self.enabled:
            return
        if told:
            text = (f"payload told ({self.mass():g} kg, mrilc_moves.payload_mass) since the last relearn: kept, not"
                    " worked out from the drift's mode")
            self.node.get_logger().info(text)
            self.node.diagnostics.publish("payload", OK, text)
            return
        try:
            key, est = self._estimate(values, goals)
        except (PayloadRefused, ValueError) as err:
            text = (f"payload from the drift's mode refused: {err}; the moves relearn on the operator for "
                    + (f"{self.mass():g} kg (mrilc_moves.payload_mass)" if self.mass() > 0 else
                       "the provider's own payload"))
            self.node.get_logger().warning(text)
            self.node.diagnostics.publish("payload", WARN, text)
            return
        entry = {"mass": est.mass, "source": "drift", "mode_hz": est.mode_hz, "move": key}
        self._take(entry, f"payload from the drift's mode at move {key}: {est.describe()}; every move's operator"
                   " is rebuilt for it")

    def _estimate(self, values: dict[str, str], goals: dict[str, list[float]]) -> tuple[str, PayloadEstimate]:
        if self.modes is None:
            raise PayloadRefused("mrilc_moves.modes is not set (the model's modes are needed)")
        if "mode_hz" not in values or "cycle" not in values:
            raise PayloadRefused(f"the warning carries no mode_hz and cycle (it has {sorted(values) or 'none'})")
        try:
            cycle = int(values["cycle"])
        except ValueError:
            raise PayloadRefused(f"the warning's cycle {values['cycle']!r} is not an integer") from None
        key = self._moves.get(cycle)
        if key is None or key not in goals:
            raise PayloadRefused(f"the warning's cycle {cycle} is not a move this learner saw")
        measured: list[Any] = [values["mode_hz"]]
        measured += [x for x in values.get("modes_hz", "").split(",") if x.strip() and x != values["mode_hz"]]
        pose, modes = list(goals[key]), self.modes

        def modes_at(mass: float) -> list[float]:
            try:
                return [float(x) for x in modes(pose, mass)]
            except Exception as err:  # (the owner's provider: whatever it raises refuses the estimate, not the relearn)
                raise PayloadRefused(f"mrilc_moves.modes failed at {mass:.6g} kg: {err!r}") from None

        return key, payload_from_modes([_number(x) for x in measured], modes_at, self.range)

    def _on_set(self, params: list[Parameter]) -> None:
        if not self._setting and any(p.name == "mrilc_moves.payload_mass" for p in params):
            self.told = True

    def _take(self, entry: dict[str, Any], text: str) -> None:
        self.estimate = entry
        self._setting = True
        try:
            result = self.node.set_parameters([Parameter("mrilc_moves.payload_mass", value=float(entry["mass"]))])[0]
        finally:
            self._setting = False
        if not result.successful:  # (the range is 0-1000 kg, the search's within it)
            self.estimate = None
            text = f"{text}: refused by mrilc_moves.payload_mass ({result.reason})"
        self.node.get_logger().info(text)
        values = [("mass_kg", f"{entry['mass']:.6g}"), ("mode_hz", f"{entry['mode_hz']:.6g}"),
                  ("move", str(entry["move"]))]
        self.node.diagnostics.publish("payload", OK if self.estimate is not None else WARN, text, values)


def _number(text: Any) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan
