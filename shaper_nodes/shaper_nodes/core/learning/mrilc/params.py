"""The learner node's MRILC parameters: names, defaults, ranges, meanings, and the model they build.

:data:`DEFAULTS`, :data:`RANGES` and :data:`DESCRIPTIONS` single-source the ``mrilc.*``,
``joint_names`` and ``topics.*`` parameters of the learner node; :func:`model_from_params`
builds the model (:class:`~.model.MrilcModel`) and the learner's settings
(:class:`MrilcSettings`) from them, so that the node and offline replays configure the
learner the same way. The ``sensor.*`` bounds are the session's
(:class:`~.session.MrilcSession`: samples at or beyond them are implausible).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from shaper_nodes.core.checks import in_range, integer

from . import model as M
from .model import MrilcError, MrilcModel

#: default bound of joint state and reference positions, rad or m (implausible at or beyond it)
MAX_ABS_POSITION = 100.0
#: default bound of measured efforts, N or N m (implausible at or beyond it)
MAX_ABS_EFFORT = 1e5

#: the learner node's MRILC parameters and their defaults (the node declares exactly these)
DEFAULTS: dict[str, object] = {
    "mrilc.rate": 200.0,
    "mrilc.controller.numerator": list(M.PAPER_CONTROLLER[0]),
    "mrilc.controller.denominator": list(M.PAPER_CONTROLLER[1]),
    "mrilc.nominal.omega": M.PAPER_NOMINAL[0],
    "mrilc.nominal.zeta": M.PAPER_NOMINAL[1],
    "mrilc.check.omegas": list(M.PAPER_OMEGAS),
    "mrilc.check.zetas": list(M.PAPER_ZETAS),
    "mrilc.check.min_frequency_hz": 0.1,
    "mrilc.law": "p",
    "mrilc.gamma": 10.0,
    "mrilc.lambda": 0.0,
    "mrilc.robust_gain": 0.7,
    "mrilc.q_cutoff_hz": 0.0,
    "mrilc.q_order": 2,
    "mrilc.injection": "effort",
    "mrilc.injection_target": "/sim_plant",
    "mrilc.shaper_family": "zvd",
    "mrilc.learn": True,
    "mrilc.patience": 3,
    "mrilc.noise_floor": 1e-9,
    "sensor.max_abs_position": MAX_ABS_POSITION,
    "sensor.max_abs_effort": MAX_ABS_EFFORT,
    "joint_names": [""],
    "topics.joint_states": "/joint_states",
    "topics.reference": "/sim_plant/reference",
    "topics.cycle_events": "/cycle_events",
}
#: numeric parameters: (low, high, integer); the node's descriptors use the same ranges
RANGES: dict[str, tuple[float, float, bool]] = {
    "mrilc.rate": (1.0, 100000.0, False),
    "mrilc.nominal.omega": (1e-3, 1e6, False),
    "mrilc.nominal.zeta": (0.0, 0.999, False),
    "mrilc.check.min_frequency_hz": (1e-4, 1e5, False),
    "mrilc.gamma": (0.0, 1e9, False),
    "mrilc.lambda": (0.0, 1e9, False),
    "mrilc.robust_gain": (0.0, 1.0, False),
    "mrilc.q_cutoff_hz": (0.0, 1e6, False),
    "mrilc.q_order": (1, 8, True),
    "mrilc.patience": (1, 1000, True),
    "mrilc.noise_floor": (0.0, 1e9, False),
    "sensor.max_abs_position": (1e-3, 1e9, False),
    "sensor.max_abs_effort": (1e-3, 1e12, False),
}


#: what each parameter means (the node's descriptors show it)
DESCRIPTIONS: dict[str, str] = {
    "mrilc.rate": "Sample rate of the loop and of the profile, Hz.",
    "mrilc.controller.numerator": "Feedback controller C(s) numerator, highest power first (default seed 000 eq. 13).",
    "mrilc.controller.denominator": "Feedback controller C(s) denominator.",
    "mrilc.nominal.omega": "Nominal plant natural frequency, rad/s.",
    "mrilc.nominal.zeta": "Nominal plant damping ratio.",
    "mrilc.check.omegas": "Plant set of the convergence check: natural frequencies, rad/s (every pair with"
                          " check.zetas).",
    "mrilc.check.zetas": "Plant set: damping ratios.",
    "mrilc.check.min_frequency_hz": "Lowest frequency of the check (and of the robust design), Hz: about"
                                    " 1 / (cycle duration).",
    "mrilc.law": "Learning law: 'p' (gamma z), 'pd' (gamma z + lambda (z - 1)), 'robust'.",
    "mrilc.gamma": "P/PD learning gain.",
    "mrilc.lambda": "PD derivative learning gain.",
    "mrilc.robust_gain": "Robust law: fraction of the minimax L applied.",
    "mrilc.q_cutoff_hz": "Q filter cut-off (zero-phase Butterworth), Hz (0 = Q = 1).",
    "mrilc.q_order": "Q filter order.",
    "mrilc.injection": "'effort' (added to the controller output) or 'command' (added to the setpoint after the"
                       " shaper).",
    "mrilc.injection_target": "Node offering ~/set_feedforward at the injection point.",
    "mrilc.shaper_family": "Shaper designed on the reference model's mode and sent to the shaper node ('' = leave"
                           " it).",
    "mrilc.learn": "Learn (true) or only measure and report with the profile held (false).",
    "mrilc.patience": "Divergence guard: iterations of growing RMS(e) before rollback.",
    "mrilc.noise_floor": "RMS(e) below which growth is not divergence (output units).",
    "sensor.max_abs_position": "Bound of the joint state and reference positions, rad or m: a cycle with a sample"
                               " at or beyond it is refused as implausible (the joints' range with a margin).",
    "sensor.max_abs_effort": "Bound of the measured efforts, N or N m: a cycle with a sample at or beyond it is"
                             " refused as implausible (the actuators' range with a margin).",
    "joint_names": "Joints learned, in profile order ([''] = those of the first START).",
    "topics.joint_states": "Topic name (joint_states).",
    "topics.reference": "Topic name (reference).",
    "topics.cycle_events": "Topic name (cycle_events).",
}


@dataclass(frozen=True)
class MrilcSettings:
    """The learner's settings besides the model (see :data:`DEFAULTS`)."""

    patience: int
    noise_floor: float
    learn: bool
    joint_names: tuple[str, ...]      # () = those of the first START
    injection_target: str
    shaper_family: str
    topics: dict[str, str]            # joint_states, reference, cycle_events
    max_abs_position: float = MAX_ABS_POSITION   # rad or m: a sample at or beyond it is implausible
    max_abs_effort: float = MAX_ABS_EFFORT       # N or N m


def _number(name: str, value: Any) -> float:
    """The numeric parameter ``name`` checked against :data:`RANGES` (an int for integer ones)."""
    low, high, whole = RANGES[name]
    label = f"parameter {name}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise MrilcError(f"{label} must be a finite number, got {value!r}")
    if whole:
        integer(label, value, error=MrilcError)
    x = in_range(label, value, low, high, error=MrilcError)
    return int(x) if whole else x


def _numbers(name: str, value: Any) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise MrilcError(f"parameter {name} must be a list of numbers, got {value!r}")
    out = tuple(value)
    if not out or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v))
                      for v in out):
        raise MrilcError(f"parameter {name} must be a non-empty list of finite numbers, got {list(out)!r}")
    return tuple(float(v) for v in out)


def _text(name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise MrilcError(f"parameter {name} must be a string, got {value!r}")
    return value


#: the list-valued parameters (non-empty lists of finite numbers)
_LISTS = ("mrilc.controller.numerator", "mrilc.controller.denominator", "mrilc.check.omegas", "mrilc.check.zetas")


def check_parameter(name: str, value: Any) -> None:
    """Check one parameter's value on its own: its type, and its range (:data:`RANGES`) or choices.

    What depends on several parameters together (a controller that does not stabilise the nominal
    plant, a Q cut-off above Nyquist, convergence) is checked by :func:`model_from_params`.

    Raises
    ------
    MrilcError
        An unknown name, or a value of the wrong type, out of range or not one of the choices.
    """
    if name not in DEFAULTS:
        raise MrilcError(f"unknown MRILC parameter {name}")
    if name in RANGES:
        _number(name, value)
    elif name in _LISTS:
        _numbers(name, value)
    elif name == "mrilc.learn":
        if not isinstance(value, bool):
            raise MrilcError(f"parameter mrilc.learn must be true or false, got {value!r}")
    elif name == "joint_names":
        if isinstance(value, str) or not all(isinstance(n, str) for n in value):
            raise MrilcError(f"parameter joint_names must be a list of strings, got {value!r}")
    else:
        text = _text(name, value)
        choices = {"mrilc.law": M.LAWS, "mrilc.injection": M.INJECTIONS}.get(name)
        if choices is not None and text not in choices:
            raise MrilcError(f"parameter {name} must be one of {', '.join(choices)}, got {text!r}")


def model_from_params(params: Mapping[str, object] | None = None, require_convergence: bool = True
                      ) -> tuple[MrilcModel, MrilcSettings]:
    """The MRILC model and settings from the learner node's parameters (:data:`DEFAULTS` for
    those not given; keys not starting with ``mrilc.``, ``sensor.``, ``topics.`` or ``joint_names`` are ignored,
    so a mixed parameter set can be passed).

    Raises
    ------
    MrilcError
        An unknown ``mrilc.*`` name, a value of the wrong type or out of range, a model that cannot
        be built (unstable reference model, Q cut-off above Nyquist, ...), or, with
        ``require_convergence``, a learning law that fails seed 000's check (naming the worst
        plant and frequency).
    """
    given = dict(params or {})
    unknown = sorted(k for k in given if k.startswith("mrilc.") and k not in DEFAULTS)
    if unknown:
        raise MrilcError(f"unknown MRILC parameter(s) {', '.join(unknown)} (known: "
                         f"{', '.join(k for k in DEFAULTS if k.startswith('mrilc.'))})")
    p: dict[str, Any] = {k: given.get(k, v) for k, v in DEFAULTS.items()}
    for name, value in p.items():
        check_parameter(name, value)
    num = {k: _number(k, p[k]) for k in RANGES}
    law_name, injection, names = p["mrilc.law"], p["mrilc.injection"], p["joint_names"]
    law = M.LawConfig(law=law_name, gamma=num["mrilc.gamma"], lam=num["mrilc.lambda"], gain=num["mrilc.robust_gain"],
                      q_cutoff_hz=num["mrilc.q_cutoff_hz"], q_order=int(num["mrilc.q_order"]))
    plant_set = M.paper_plant_set(_numbers("mrilc.check.omegas", p["mrilc.check.omegas"]),
                                  _numbers("mrilc.check.zetas", p["mrilc.check.zetas"]))
    model = MrilcModel(
        M.controller(_numbers("mrilc.controller.numerator", p["mrilc.controller.numerator"]),
                     _numbers("mrilc.controller.denominator", p["mrilc.controller.denominator"])),
        M.mck_plant(num["mrilc.nominal.omega"], num["mrilc.nominal.zeta"]), plant_set, 1.0 / num["mrilc.rate"],
        injection, law, omega_min=2 * math.pi * num["mrilc.check.min_frequency_hz"])
    if require_convergence:
        model.require_convergence()
    settings = MrilcSettings(int(num["mrilc.patience"]), num["mrilc.noise_floor"], p["mrilc.learn"],
                             tuple(n for n in names if n), _text("mrilc.injection_target", p["mrilc.injection_target"]),
                             _text("mrilc.shaper_family", p["mrilc.shaper_family"]),
                             {k: _text(f"topics.{k}", p[f"topics.{k}"])
                              for k in ("joint_states", "reference", "cycle_events")},
                             num["sensor.max_abs_position"], num["sensor.max_abs_effort"])
    return model, settings

