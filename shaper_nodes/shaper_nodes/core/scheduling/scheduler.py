"""Gain-scheduled shaping: the shaper from the fuzzy rule base at the present pose, rate-limited,
with the learner's corrections kept per operating region. Free of ROS (the scheduler node wraps it).

The same shaper is available for any pose, not only the present one (:meth:`Scheduler.at`): the
scheduler node answers ``~/shaper_at`` with it, so that a whole trajectory can be shaped for the
modes at the pose it ends at. :func:`premise_values` picks the premise joints out of a pose given
as names and positions, in linear time, and names what is wrong with it.

Policy with the learner
-----------------------
The scheduler decides the mode; the learner learns a correction. A correction is the ratio of
the learner's two-impulse shaper (A1 at 0, 1 - A1 at T2) to the scheduled ZV at the same pose,
(r_T, r_A) = (T2 / T2_s, A1 / A1_s), kept per rule. At a pose z the corrections are
interpolated with the rules' weights, r(z) = sum_i w_i(z) r_i, and the shaper sent is the
scheduled ZV with T2 = r_T(z) T2_s(z) and A1 = r_A(z) A1_s(z). When the learner sends a shaper
at z, the dominant rule i* (largest weight: the operating region) takes the change that makes
r(z) equal what the learner found, r_i* += (r_learned - r(z)) / w_i*, so the learner's shaper
is exactly what is applied at that pose, and moving away and back restores it.

With several modes the scheduled shaper is a convolution of one factor per mode, and a ratio of
two impulses means nothing. The learner's two-impulse shaper is then kept as an extra factor of
the dominant region and convolved with the scheduled shaper wherever that region dominates:
LIST learns the residual the schedule leaves (its reference cycle is the scheduled one, since
the learner's identity shaper keeps the factor at identity), and the schedule still follows
the pose underneath.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.shaping.families import convolve, design
from shaper_nodes.core.shaping.types import Mode, Shaper, ShaperError

from .fuzzy import FuzzyError, Interpolation, RuleBase

#: A1 of a corrected shaper stays within these bounds
A1_BOUNDS = (0.05, 0.95)
#: most joints a pose may name; a larger pose is refused before any work on it
MAX_POSE_JOINTS = 10_000
#: a premise change that moves no membership grade by more than this reuses the last evaluation
#: (:meth:`Scheduler.moved`). Why it is safe: each rule's firing strength (a product of p grades in
#: [0, 1]) then moves by at most p * GRADE_TOLERANCE, the normalised weights of R rules by at most
#: 2 R p * GRADE_TOLERANCE / sum(mu) in all (sum(mu) = 1 on a triangular partition, as calibration
#: writes), and the interpolated model or mode parameters by that fraction of the rules' spread:
#: about 1e-5 relative for 8 rules, three orders of magnitude below the least change that sends a
#: new shaper (``relative_change``, 1 % by default) and below any identified mode's uncertainty.
#: The comparison is always with the premises of the last evaluation, so small moves do not add up.
GRADE_TOLERANCE = 1e-6


def premise_values(premises: Sequence[str], names: Sequence[str], positions: Sequence[float]) -> list[float]:
    """The positions of the premise joints, in the order of ``premises``, from a pose.

    Parameters
    ----------
    premises : sequence of str
        The premise joints' names.
    names, positions : sequences
        The pose: joint names in any order (other joints are ignored) and one position per name
        (rad or m).

    Returns
    -------
    list of float
        One finite value per premise.

    Raises
    ------
    InputError
        ``too_large`` (more than :data:`MAX_POSE_JOINTS` names), ``wrong_size`` (positions and
        names differ in number), ``missing_joint``, ``duplicate_joint`` (a premise joint named
        twice) or ``non_finite``; the message names the joints. The work is linear in the pose.
    """
    return _values(premises, premise_index(premises, names, positions), positions)


def premise_index(premises: Sequence[str], names: Sequence[str], positions: Sequence[float]) -> list[int]:
    """Where the premise joints are in a pose's ``names`` (see :func:`premise_values`, which raises the
    same errors but ``non_finite``)."""
    if len(names) > MAX_POSE_JOINTS:
        raise InputError("too_large", f"{len(names)} joint names exceed the limit of {MAX_POSE_JOINTS}")
    if len(positions) != len(names):
        raise InputError("wrong_size", f"{len(positions)} positions for {len(names)} names")
    wanted = set(premises)
    index: dict[str, int] = {}
    twice: list[str] = []
    for i, name in enumerate(names):
        if name in wanted:
            if name in index:
                twice.append(name)
            else:
                index[name] = i
    missing = [j for j in premises if j not in index]
    if missing:
        raise InputError("missing_joint", f"missing premise joints {missing} (the pose names {len(names)} joints)")
    if twice:
        raise InputError("duplicate_joint", f"premise joints named more than once: {sorted(set(twice))}")
    return [index[j] for j in premises]


def _values(premises: Sequence[str], index: list[int], positions: Sequence[float]) -> list[float]:
    """The positions at ``index`` (one per premise), refused (``non_finite``) if not all finite."""
    z = [float(positions[i]) for i in index]
    bad = [f"{j} = {v!r}" for j, v in zip(premises, z, strict=True) if not math.isfinite(v)]
    if bad:
        raise InputError("non_finite", "non-finite premise values: " + ", ".join(bad))
    return z


def relative_change(old: Sequence[Mode], new: Sequence[Mode]) -> float:
    """Largest relative change between two mode lists: |d omega| / omega, and |d zeta| / max(zeta,
    0.01) (so a damping ratio near 0 does not count every change as large); inf if the number of
    modes differs."""
    if len(old) != len(new):
        return math.inf
    change = 0.0
    for a, b in zip(old, new, strict=True):
        change = max(change, abs(b.omega - a.omega) / a.omega, abs(b.zeta - a.zeta) / max(a.zeta, 0.01))
    return change


@dataclass
class Scheduler:
    """The rule base, how to interpolate ('model' or 'modes'), the shaper family, corrections."""

    rule_base: RuleBase
    method: str = "model"
    family: str = "zv"
    corrections: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: per rule, the learner's extra factor for schedules on several modes (None: none yet)
    factors: list[Shaper | None] = field(default_factory=list)
    #: the last pose layout seen: its names and where the premise joints are in it
    _layout: tuple[tuple[str, ...], list[int]] | None = field(default=None, init=False, repr=False, compare=False)
    #: per premise, the change that moves no grade by more than GRADE_TOLERANCE (rad or m)
    _tolerance: np.ndarray = field(default_factory=lambda: np.zeros(0), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.method not in ("model", "modes"):
            raise FuzzyError(f"interpolation must be 'model' or 'modes', got {self.method!r}")
        design(self.family, [Mode(1.0, 0.05)])  # the family exists and designs from a mode
        if self.corrections.size == 0:
            self.corrections = np.ones((len(self.rule_base.rules), 2))
        if not self.factors:
            self.factors = [None] * len(self.rule_base.rules)
        self._tolerance = self.rule_base.premise_tolerance(GRADE_TOLERANCE)

    def moved(self, z: Sequence[float], last: Interpolation) -> bool:
        """Whether the premise values ``z`` (finite) differ from those of ``last`` enough to evaluate
        again: some premise moved by more than its tolerance (a change of :data:`GRADE_TOLERANCE`
        in a membership grade; compared as given, before clamping, so that what a clamping report
        says stays true too), or a premise went in or out of the range."""
        zin, _, clamped = self.rule_base.clamp(z)
        return clamped != last.clamped or bool(np.any(np.abs(zin - last.z_in) > self._tolerance))

    def evaluate(self, z: Sequence[float]) -> Interpolation:
        out = self.rule_base.evaluate(z, self.method)
        if not out.modes:
            raise FuzzyError("the interpolated model has no lightly damped mode at "
                             + ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.rule_base.premises, out.z, strict=True)))
        return out

    def premise_values(self, names: Sequence[str], positions: Sequence[float]) -> list[float]:
        """The premise values of a pose (see :func:`premise_values`).

        The premise joints' places are looked up once per name layout: a stream of joint states
        with the same names costs a comparison of the names and the finiteness checks per message.
        """
        premises = self.rule_base.premises
        layout = self._layout  # read once: the node calls this from two threads
        if layout is not None and len(names) == len(layout[0]) and tuple(names) == layout[0]:
            if len(positions) != len(names):
                raise InputError("wrong_size", f"{len(positions)} positions for {len(names)} names")
            return _values(premises, layout[1], positions)
        index = premise_index(premises, names, positions)
        self._layout = (tuple(names), index)
        return _values(premises, index, positions)

    def clamping(self, interp: Interpolation) -> str:
        """What was clamped to the rule base's range at the pose of ``interp`` ("" if nothing)."""
        out = [f"{n} = {v:.6g} outside [{lo:g}, {hi:g}]" for n, v, (lo, hi), c in
               zip(self.rule_base.premises, interp.z_in, self.rule_base.ranges, interp.clamped, strict=True) if c]
        return ("premise " + "; ".join(out) + ": clamped, not extrapolated") if out else ""

    def at(self, z: Sequence[float]) -> tuple[Interpolation, Shaper]:
        """The rule base at the premise values ``z`` and the shaper to apply there (exactly what
        the schedule applies at that pose: :meth:`shaper` of :meth:`evaluate`).

        Raises
        ------
        FuzzyError
            Wrong number of values, non-finite values, no rule firing, or no lightly damped mode.
        ShaperError
            If the family cannot be designed on the interpolated modes.
        """
        interp = self.evaluate(z)
        return interp, self.shaper(interp)

    def correction(self, interp: Interpolation) -> tuple[float, float]:
        """(r_T, r_A) at the pose of ``interp``."""
        r = interp.weights @ self.corrections
        return float(r[0]), float(r[1])

    def scheduled(self, interp: Interpolation) -> Shaper:
        """The family's shaper on the interpolated modes, without corrections."""
        return design(self.family, interp.modes)

    def shaper(self, interp: Interpolation) -> Shaper:
        """The shaper to apply at the pose of ``interp``: scheduled, times the region's correction."""
        base = self.scheduled(interp)
        if len(base.modes) > 1:
            factor = self.factors[interp.dominant]
            if factor is None:
                return base
            amps, times = convolve((base.amplitudes, base.times), (factor.amplitudes, factor.times))
            return Shaper(amps, times, "custom", base.modes)
        r_t, r_a = self.correction(interp)
        if self.family != "zv" or len(base) != 2 or (r_t == 1.0 and r_a == 1.0):
            return base
        a1 = min(max(base.amplitudes[0] * r_a, A1_BOUNDS[0]), A1_BOUNDS[1])
        return Shaper(np.array([a1, 1.0 - a1]), np.array([0.0, base.times[1] * r_t]), "custom", base.modes)

    def learn(self, interp: Interpolation, learned: Shaper) -> tuple[int, tuple[float, float]]:
        """Take the learner's shaper at the pose of ``interp``; returns (region, its correction): the
        ratios (r_T, r_A) on one mode, the factor's (T2 s, A1) on several (module docstring).

        Raises
        ------
        ShaperError
            If the family is not ZV or the learner's shaper is not two impulses.
        """
        if self.family != "zv":
            raise ShaperError(f"learner corrections need the scheduler's family 'zv', not {self.family!r}")
        if len(learned) != 2 or learned.times[1] <= 0:
            raise ShaperError(f"a learner correction is a two-impulse shaper, got {len(learned)} impulses")
        base = self.scheduled(interp)
        if len(base.modes) > 1:
            self.factors[interp.dominant] = learned
            return interp.dominant, (float(learned.times[1]), float(learned.amplitudes[0]))
        wanted = np.array([learned.times[1] / base.times[1], learned.amplitudes[0] / base.amplitudes[0]])
        i = interp.dominant
        now = interp.weights @ self.corrections
        self.corrections[i] = self.corrections[i] + (wanted - now) / interp.weights[i]
        return i, (float(self.corrections[i, 0]), float(self.corrections[i, 1]))
