"""Joint limits the shaper's output must respect, and the checks of an output against them.

The shaper node is the last software before a robot's controller, so what it passes on is held
against the robot's limits where the output is made, for every path:

- positions within ``[lower, upper]`` per joint (streamed samples and whole trajectories);
- for whole trajectories also ``|velocity| <= velocity`` and ``|acceleration| <= acceleration``
  per joint, on the shaped trajectory's own derivatives (what joint_trajectory_controller will
  be commanded).

A limit that is not set is infinite (no check). Limits come from the node's parameters and, when
a URDF is given, from its ``<limit>`` elements (:func:`urdf_limits`); where both give a limit the
tighter one holds (:meth:`JointLimits.tighter`). URDF has no acceleration limits.

A violation raises :class:`~shaper_nodes.core.checks.InputError` of kind ``beyond_limits`` naming
the joint, the sample (and its time for trajectories), the value and the limit; the caller then
passes nothing on.

A positive shaper (non-negative impulses) keeps a single filter's output inside the range of its
input, but not across a bumpless switch: a step shaped by a slow filter, then a step back shaped
by a fast one, leaves the output below both inputs for a while. Hence the check on the output
itself, not on the input.
"""

from __future__ import annotations

import functools
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from shaper_nodes.core.checks import InputError

#: a limit at or beyond this magnitude counts as unset (URDF parsers use huge sentinels)
UNSET = 1e300


def _per_joint(name: str, values: Sequence[float], n: int, default: float, positive: bool) -> np.ndarray:
    """One limit per joint from a parameter list: empty = unset (``default``) for every joint."""
    if len(values) == 0:
        return np.full(n, default)
    arr = np.asarray(values, dtype=float)
    if arr.size != n:
        raise ValueError(f"{name} has {arr.size} entries, one per joint ({n}) or none expected")
    if np.any(np.isnan(arr)):
        raise ValueError(f"{name} has NaN entries; leave the list empty for no limit")
    if positive and np.any(arr <= 0.0):
        raise ValueError(f"{name} must be > 0 (got {arr.tolist()}); use .inf for no limit on a joint")
    return arr


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in the node's joint order; infinite where unset.

    Attributes
    ----------
    names : tuple of str
        The joints, in the order of the arrays.
    lower, upper : (J,) arrays
        Position limits, rad or m (-inf / +inf: none).
    velocity, acceleration : (J,) arrays
        Magnitude limits, rad/s and rad/s^2 or m/s and m/s^2 (+inf: none).
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    @classmethod
    def unset(cls, names: Sequence[str]) -> JointLimits:
        n = len(names)
        return cls(tuple(names), np.full(n, -math.inf), np.full(n, math.inf), np.full(n, math.inf),
                   np.full(n, math.inf))

    @classmethod
    def from_lists(cls, names: Sequence[str], lower: Sequence[float] = (), upper: Sequence[float] = (),
                   velocity: Sequence[float] = (), acceleration: Sequence[float] = ()) -> JointLimits:
        """Limits from parameter lists, one entry per joint or empty for none.

        Raises
        ------
        ValueError
            A list of the wrong length, NaN entries, non-positive velocity or acceleration limits,
            or a lower limit above the upper one (the message names the list and joint).
        """
        n = len(names)
        lo = _per_joint("limits.position_lower", lower, n, -math.inf, positive=False)
        hi = _per_joint("limits.position_upper", upper, n, math.inf, positive=False)
        bad = np.flatnonzero(lo > hi)
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"limits.position_lower {lo[k]:g} is above limits.position_upper {hi[k]:g}"
                             f" for joint {names[k]!r}")
        return cls(tuple(names), lo, hi,
                   _per_joint("limits.velocity", velocity, n, math.inf, positive=True),
                   _per_joint("limits.acceleration", acceleration, n, math.inf, positive=True))

    def tighter(self, other: JointLimits) -> JointLimits:
        """The tighter of two sets of limits for the same joints."""
        if other.names != self.names:
            raise ValueError("limits for different joints cannot be combined")
        lo, hi = np.maximum(self.lower, other.lower), np.minimum(self.upper, other.upper)
        bad = np.flatnonzero(lo > hi)
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"the position limits of joint {self.names[k]!r} do not overlap"
                             f" ([{self.lower[k]:g}, {self.upper[k]:g}] and [{other.lower[k]:g}, {other.upper[k]:g}])")
        return JointLimits(self.names, lo, hi, np.minimum(self.velocity, other.velocity),
                           np.minimum(self.acceleration, other.acceleration))

    @property
    def any_position(self) -> bool:
        return bool(np.any(np.isfinite(self.lower)) or np.any(np.isfinite(self.upper)))

    @cached_property
    def _set(self) -> dict[str, bool]:
        """Per field, whether any joint has a limit on it (a field without one has nothing to check)."""
        return {"positions": self.any_position, "velocities": bool(np.any(np.isfinite(self.velocity))),
                "accelerations": bool(np.any(np.isfinite(self.acceleration)))}

    @cached_property
    def sample_bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Per joint (lowest, highest) position a shaped sample may take, as Python floats, unset limits
        replaced by the largest finite double: ``lo <= v <= hi`` then holds exactly when ``v`` is finite
        and within the position limits (a NaN fails every comparison), the check of
        :meth:`check_positions` plus finiteness in one comparison per joint."""
        big = sys.float_info.max
        return (tuple(max(float(v), -big) for v in self.lower), tuple(min(float(v), big) for v in self.upper))

    def input_bounds(self, max_abs: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """As :attr:`sample_bounds` for an input sample that must also lie within ``max_abs`` in magnitude
        (``max_abs`` finite): ``lo <= v <= hi`` holds exactly when ``v`` passes the magnitude check of
        :func:`~shaper_nodes.core.checks.finite_array` and :meth:`check_positions`."""
        lo, hi = self.sample_bounds
        return tuple(max(v, -max_abs) for v in lo), tuple(min(v, max_abs) for v in hi)

    def describe(self) -> str:
        """One line for the node's start-up log: which limits are set."""
        parts = []
        for label, arr in (("position", np.isfinite(self.lower) | np.isfinite(self.upper)),
                           ("velocity", np.isfinite(self.velocity)),
                           ("acceleration", np.isfinite(self.acceleration))):
            parts.append(f"{label} on {int(arr.sum())} of {len(self.names)} joints")
        return "limits: " + ", ".join(parts)

    # ------------------------------------------------------------------ checks
    def check_positions(self, what: str, positions: np.ndarray, times: np.ndarray | None = None) -> None:
        """Positions (J,) or (N, J) within [lower, upper]; InputError ``beyond_limits`` naming the first
        violation (``what``: e.g. "the shaped command")."""
        if not self._set["positions"]:  # no limit: nothing can pass one
            return
        p = np.atleast_2d(positions)
        over = (p > self.upper) | (p < self.lower)
        if over.any():
            self._refuse(what, "position", over, p, times, self.lower, self.upper)

    def check(self, field: str, what: str, values: np.ndarray, times: np.ndarray | None = None) -> None:
        """Values (J,) or (N, J) of a trajectory field ("positions", "velocities" or "accelerations")
        within their limits."""
        if not self._set[field]:  # no limit on this field: nothing can pass one
            return
        v = np.atleast_2d(values)
        if field == "positions":
            self.check_positions(what, v, times)
            return
        label, lim = {"velocities": ("velocity", self.velocity),
                      "accelerations": ("acceleration", self.acceleration)}[field]
        over = np.abs(v) > lim
        if over.any():
            self._refuse(what, label, over, v, times, -lim, lim)

    def check_trajectory(self, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
                         accelerations: np.ndarray, what: str = "the shaped trajectory") -> None:
        """A whole trajectory's positions, velocities and accelerations within the limits."""
        for field, values in (("positions", positions), ("velocities", velocities), ("accelerations", accelerations)):
            self.check(field, what, values, times)

    def _refuse(self, what: str, label: str, over: np.ndarray, values: np.ndarray, times: np.ndarray | None,
                lower: np.ndarray, upper: np.ndarray) -> None:
        k, j = (int(i) for i in np.argwhere(over)[0])
        v = float(values[k, j])
        where = f" at sample {k}" + (f" (t = {float(times[k]):.4f} s)" if times is not None else "") \
            if values.shape[0] > 1 else ""
        bound = float(upper[j] if v > upper[j] else lower[j])
        raise InputError("beyond_limits", f"{what} would pass the {label} limit of joint {self.names[j]!r}{where}:"
                         f" {v:.6g} beyond {bound:.6g} ({int(over.sum())} values beyond limits; nothing passed on)")


@functools.lru_cache(maxsize=64)
def bounds_check(lo: tuple[float, ...], hi: tuple[float, ...]) -> Callable[[Sequence[float]], bool]:
    """``f(v)``: whether ``v`` has ``len(lo)`` values and ``lo[j] <= v[j] <= hi[j]`` for every j (a NaN fails any
    comparison), the truth of ``len(v) == len(lo) and all(map(le, lo, v)) and all(map(le, v, hi))``, written out
    as one chained comparison per value, the bounds in the function's closure: the streamed sample's checks
    (:attr:`JointLimits.sample_bounds`, :meth:`JointLimits.input_bounds`) with no ``map`` object or call per
    check, cheaper as a sample at 1 kHz meets them (cold caches). Cached per bounds."""
    n = len(lo)
    if n < 1 or len(hi) != n:
        raise ValueError(f"bounds of {n} and {len(hi)} values: one (lowest, highest) pair per joint, at least one")
    ls, hs = [f"l{j}" for j in range(n)], [f"h{j}" for j in range(n)]
    body = " and ".join(f"{a} <= v[{j}] <= {b}" for j, (a, b) in enumerate(zip(ls, hs, strict=True)))
    source = (f"def make({', '.join(ls + hs)}):\n"
              f"    def within(v):\n"
              f"        return len(v) == {n} and {body}\n"
              f"    return within\n")
    namespace: dict[str, Any] = {}
    exec(compile(source, f"<bounds check, {n} joints>", "exec"), namespace)  # our own source text
    within: Callable[[Sequence[float]], bool] = namespace["make"](*(float(x) for x in lo), *(float(x) for x in hi))
    return within


def urdf_limits(urdf: str, names: Sequence[str]) -> JointLimits:
    """The ``<limit>`` elements of the URDF document ``urdf`` for the joints ``names``.

    Revolute and prismatic joints give position (``lower``/``upper``) and ``velocity`` limits;
    continuous joints only a velocity limit. A joint of ``names`` missing from the URDF, or of
    another type (fixed, floating, planar), is an error: the node would otherwise shape a joint
    whose limits the integrator believes are checked.

    Raises
    ------
    ValueError
        Not a URDF, a missing joint or an unsupported joint type (named).
    """
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as err:
        raise ValueError(f"the URDF is not well-formed XML: {err}") from None
    if root.tag != "robot":
        raise ValueError(f"the URDF's root element is <{root.tag}>, not <robot>")
    joints = {j.get("name"): j for j in root.iter("joint")}
    n = len(names)
    lo, hi, vel = np.full(n, -math.inf), np.full(n, math.inf), np.full(n, math.inf)
    for i, name in enumerate(names):
        joint = joints.get(name)
        if joint is None:
            raise ValueError(f"joint {name!r} is not in the URDF (it has {sorted(k for k in joints if k)})")
        kind = joint.get("type")
        if kind not in ("revolute", "prismatic", "continuous"):
            raise ValueError(f"joint {name!r} is {kind!r} in the URDF; only revolute, prismatic and continuous"
                             " joints are shaped")
        limit = joint.find("limit")
        if limit is None:
            if kind != "continuous":
                raise ValueError(f"{kind} joint {name!r} has no <limit> in the URDF (required by URDF for it)")
            continue
        v = _attr(limit, "velocity", name)
        if v is not None and 0.0 < v < UNSET:
            vel[i] = v
        if kind != "continuous":
            lower, upper = _attr(limit, "lower", name), _attr(limit, "upper", name)
            lo[i] = lower if lower is not None and abs(lower) < UNSET else -math.inf
            hi[i] = upper if upper is not None and abs(upper) < UNSET else math.inf
            if lo[i] > hi[i]:
                raise ValueError(f"joint {name!r} has lower limit {lo[i]:g} above its upper limit {hi[i]:g}"
                                 " in the URDF")
    return JointLimits(tuple(names), lo, hi, vel, np.full(n, math.inf))


def _attr(elem: ET.Element, key: str, joint: str) -> float | None:
    raw = elem.get(key)
    if raw is None:
        return None
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"joint {joint!r}: <limit {key}={raw!r}> is not a number") from None
    if math.isnan(value):
        raise ValueError(f"joint {joint!r}: <limit {key}> is NaN")
    return value
