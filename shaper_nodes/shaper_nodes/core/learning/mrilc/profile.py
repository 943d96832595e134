"""A move's correction and the joint limits it must hold, free of ROS (MRILC per move, :mod:`.moves`).

The correction of each joint's commanded profile is a sum over cubic B-splines on uniform knots inside the move
(:func:`spline_basis`: the correction and its first two derivatives zero at the move's start and end);
:class:`Profile` holds the commanded profile at its sample times with the basis there. :class:`JointLimits`
(position range, velocity and acceleration bounds) is checked on the profile's samples: :func:`excess` and
:func:`profile_excess` measure a breach, :func:`project` projects coefficients onto the corrections that keep
the profile inside (in the norm of the learning's weighted matrix; at most :data:`PROJECTION_ROUNDS` x 8 sweeps
of Hildreth's method over the violated samples), and :func:`clip_into` clips the points sent, so that a
correction that meets a limit with equality holds it exactly, not to rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .model import MrilcError

#: rounds of the projection's active-set loop per joint
PROJECTION_ROUNDS = 8
#: what a limit may be exceeded by, relative to it (rounding: a row the projection meets with equality)
TOLERANCE = 1e-12

Array = npt.NDArray[np.float64]


def spline_basis(times: npt.ArrayLike, spacing: float, count: int) -> tuple[Array, Array, Array]:
    """Cubic B-splines ``b_i`` (i < ``count``) on knots ``i * spacing``, at ``times`` (s), and their derivatives.

    b_i has support [i spacing, (i + 4) spacing]; outside it b_i, b_i', b_i'' are zero, so a sum of
    them and its first two derivatives vanish at 0 and after (count + 3) spacing.

    Returns
    -------
    (b, b', b'') : three (len(times), count) arrays: 1, 1/s, 1/s^2.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise MrilcError(f"the knot spacing must be finite and > 0 s, got {spacing!r}")
    if count < 1:
        raise MrilcError(f"the basis needs at least one function, got {count}")
    t = np.asarray(times, dtype=float)[:, None] / spacing - np.arange(count)[None, :]  # in knot units
    out = [np.zeros_like(t) for _ in range(3)]
    for k in range(4):  # the uniform cubic B-spline on [0, 4], piece by piece (u in [0, 1) within piece k)
        sel = (t >= k) & (t < k + 1)
        u = t[sel] - k
        out[0][sel], d1, d2 = _piece(k, u)
        out[1][sel], out[2][sel] = d1 / spacing, d2 / spacing**2
    return out[0], out[1], out[2]


def _piece(k: int, u: Array) -> tuple[Array, Array, Array]:
    """Piece ``k`` of the uniform cubic B-spline: value and first two derivatives, in knot units."""
    if k == 0:
        return u**3 / 6, u**2 / 2, u
    if k == 1:
        return (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6, (-9 * u**2 + 6 * u + 3) / 6, -3 * u + 1
    if k == 2:
        return (3 * u**3 - 6 * u**2 + 4) / 6, (9 * u**2 - 12 * u) / 6, 3 * u - 2
    return (1 - u) ** 3 / 6, -((1 - u) ** 2) / 2, 1 - u


@dataclass(frozen=True)
class JointLimits:
    """Joint limits the corrected profile must hold: position range, rad; |velocity| rad/s; |acceleration| rad/s^2."""

    position_min: Array
    position_max: Array
    velocity: Array
    acceleration: Array

    def __post_init__(self) -> None:
        n = np.asarray(self.velocity).size
        for name in ("position_min", "position_max", "velocity", "acceleration"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (n,) or not np.all(np.isfinite(a)):
                raise MrilcError(f"joint limits: {name} must be {n} finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, a)
        if np.any(self.velocity <= 0) or np.any(self.acceleration <= 0) or np.any(self.position_max
                                                                                  <= self.position_min):
            raise MrilcError("joint limits: velocity and acceleration must be > 0 and position_max > position_min")

    def violation(self, q: Array, v: Array, a: Array) -> float:
        """The largest excess of a (samples, joints) profile over the limits (0: all held), in its own unit."""
        return float(max(np.max(self.position_min - q, initial=0.0), np.max(q - self.position_max, initial=0.0),
                         np.max(np.abs(v) - self.velocity, initial=0.0),
                         np.max(np.abs(a) - self.acceleration, initial=0.0)))


@dataclass(frozen=True)
class Profile:
    """A move's commanded profile at its sample times (each (samples, joints)) and the basis there."""

    positions: Array
    velocities: Array
    accelerations: Array
    basis: tuple[Array, Array, Array]

    def correction(self, coefficients: Array) -> tuple[Array, Array, Array]:
        """dq, dq', dq'' (samples, joints) of ``coefficients`` (basis, joints)."""
        return tuple(b @ coefficients for b in self.basis)  # type: ignore[return-value]

    def corrected(self, coefficients: Array) -> tuple[Array, Array, Array]:
        dq, dv, da = self.correction(coefficients)
        return self.positions + dq, self.velocities + dv, self.accelerations + da


def _rows(profile: Profile, limits: JointLimits, joint: int) -> tuple[Array, Array, Array]:
    """Joint ``joint``'s limits as rows ``a c <= slack`` on its coefficients c, the slack held at >= 0 (where the
    uncorrected profile is already past a limit, the correction may not take it further), and each row's scale."""
    b0, b1, b2 = profile.basis
    a = np.vstack([b0, -b0, b1, -b1, b2, -b2])
    j = joint
    lo, hi = limits.position_min[j], limits.position_max[j]
    vm, am = limits.velocity[j], limits.acceleration[j]
    slack = np.concatenate([hi - profile.positions[:, j], profile.positions[:, j] - lo,
                            vm - profile.velocities[:, j], vm + profile.velocities[:, j],
                            am - profile.accelerations[:, j], am + profile.accelerations[:, j]])
    n = b0.shape[0]
    scale = np.concatenate([np.full(2 * n, max(abs(hi), abs(lo), 1.0)), np.full(2 * n, vm), np.full(2 * n, am)])
    return a, np.maximum(slack, 0.0), scale


def excess(coefficients: Array, profile: Profile, limits: JointLimits) -> float:
    """The largest amount by which the correction of ``coefficients`` takes the profile past a limit (0: none).

    A sample where the uncorrected profile is already past a limit counts only by what the correction
    adds there. Units of the limit broken (rad, rad/s or rad/s^2).
    """
    worst = 0.0
    for j in range(coefficients.shape[1]):
        a, slack, _ = _rows(profile, limits, j)
        worst = max(worst, float(np.max(a @ coefficients[:, j] - slack)))
    return worst


def _bounds(limits: JointLimits, base: tuple[Array, Array, Array] | None, shape: tuple[int, ...]
            ) -> tuple[Array, Array, Array, Array]:
    """Per sample and joint: the lowest and highest position, the largest |velocity| and |acceleration| a corrected
    profile may have; where the uncorrected ``base`` is already past a limit, its own value there."""
    lo = np.broadcast_to(limits.position_min, shape)
    hi = np.broadcast_to(limits.position_max, shape)
    vm = np.broadcast_to(limits.velocity, shape)
    am = np.broadcast_to(limits.acceleration, shape)
    if base is not None:
        lo, hi = np.minimum(lo, base[0]), np.maximum(hi, base[0])
        vm, am = np.maximum(vm, np.abs(base[1])), np.maximum(am, np.abs(base[2]))
    return lo, hi, vm, am


def clip_into(q: Array, v: Array, a: Array, limits: JointLimits, base: tuple[Array, Array, Array] | None = None
              ) -> tuple[Array, Array, Array]:
    """A corrected (samples, joints) profile's points clipped into ``limits`` (rad, rad/s, rad/s^2), so that
    :func:`profile_excess` is exactly 0; with ``base``, the uncorrected profile: where it is already past a limit,
    into its own value there. After :func:`project` the points move by rounding only (1e-12 relative at most)."""
    lo, hi, vm, am = _bounds(limits, base, np.shape(q))
    return np.clip(q, lo, hi), np.clip(v, -vm, vm), np.clip(a, -am, am)


def profile_excess(q: Array, v: Array, a: Array, limits: JointLimits,
                   base: tuple[Array, Array, Array] | None = None) -> float:
    """The largest excess of a corrected (samples, joints) profile over ``limits`` (0: all held), in the unit of
    the limit broken; with ``base``, where the uncorrected profile is already past a limit, over its own value."""
    lo, hi, vm, am = _bounds(limits, base, np.shape(q))
    return float(max(np.max(lo - q, initial=0.0), np.max(q - hi, initial=0.0),
                     np.max(np.abs(v) - vm, initial=0.0), np.max(np.abs(a) - am, initial=0.0)))


def project(coefficients: Array, profile: Profile, limits: JointLimits, feasible: Array | None = None,
            metric: Array | None = None, margin: float = 1e-5) -> Array:
    """The coefficients nearest ``coefficients`` whose correction keeps the profile inside ``limits``.

    Nearest in the norm of ``metric`` (symmetric positive definite over the coefficients flattened
    joint-major, e.g. the learner's G^T W G + rho I, so that the limits cost as little of the step's
    effect on the output as they can; default the Euclidean norm): at most :data:`PROJECTION_ROUNDS` x 8
    sweeps of Hildreth's method over the violated samples (limits tightened by ``margin``, relative), then
    the least change that meets the rows still violated (at most :data:`PROJECTION_ROUNDS` times); if a
    violation remains, the step from ``feasible`` (coefficients known to hold the limits, default
    zero) is shortened until none does, so the result holds them (:func:`excess` at most :data:`TOLERANCE`
    relative, rounding). Where the
    uncorrected profile is past a limit, the correction may not take it further.
    """
    c = np.array(coefficients, dtype=float)
    basis, joints = c.shape
    base = np.zeros_like(c) if feasible is None else np.asarray(feasible, dtype=float)
    if excess(base, profile, limits) > 1e-9:
        raise MrilcError(f"the feasible coefficients break the joint limits by {excess(base, profile, limits):.3g}")
    blocks, slacks, scales = [], [], []
    for j in range(joints):
        a, slack, scale = _rows(profile, limits, j)
        used = np.any(a != 0, axis=1)  # samples the basis reaches
        full = np.zeros((int(used.sum()), basis * joints))
        full[:, j * basis:(j + 1) * basis] = a[used]
        blocks.append(full)
        slacks.append(slack[used])
        scales.append(scale[used])
    rows, slack, scale = np.vstack(blocks), np.concatenate(slacks), np.concatenate(scales)
    bound = np.where(slack > margin * scale, slack - margin * scale, slack)  # rows x <= bound
    target = c.T.ravel()
    if metric is None:
        x = np.asarray(_hildreth(rows, bound, target), dtype=float)
    else:
        r = np.linalg.cholesky(np.asarray(metric, dtype=float)).T  # metric = r^T r; z = r x
        rows_z = np.linalg.solve(r.T, rows.T).T                  # rows r^-1
        x = np.asarray(np.linalg.solve(r, _hildreth(rows_z, bound, r @ target)), dtype=float)
    for _ in range(PROJECTION_ROUNDS):  # what Hildreth left violated: the least change that meets those rows
        over = rows @ x - bound
        bad = over > 0
        if not bad.any():
            break
        x = x - np.linalg.lstsq(rows[bad], over[bad], rcond=None)[0]
    start = base.T.ravel()
    step = x - start
    grow = rows @ step
    room = np.maximum(slack - rows @ start, 0.0)  # the start holds the limits (to TOLERANCE)
    pos = grow > TOLERANCE * scale
    alpha = float(np.min(np.append(room[pos] / grow[pos], 1.0))) if pos.any() else 1.0
    return np.asarray((start + max(0.0, min(1.0, alpha)) * step).reshape(joints, basis).T)


def _hildreth(a: Array, bound: Array, target: Array) -> Array:
    """The point nearest ``target`` with ``a x <= bound`` by Hildreth's dual coordinate ascent over the rows
    that ``target`` or an iterate violates, at most :data:`PROJECTION_ROUNDS` x 8 sweeps (near the nearest point
    when it stops early; :func:`project` makes the result feasible)."""
    x = target.copy()
    active = np.flatnonzero(a @ x > bound)
    if active.size == 0:
        return x
    lam: dict[int, float] = {}
    norms = np.einsum("ij,ij->i", a, a)
    for _ in range(PROJECTION_ROUNDS * 8):
        moved = 0.0
        for i in active:
            if norms[i] <= 0:
                continue
            old = lam.get(int(i), 0.0)
            new = max(0.0, old + (float(a[i] @ x) - bound[i]) / norms[i])
            if new != old:
                x -= (new - old) * a[i]
                lam[int(i)] = new
                moved = max(moved, abs(new - old) * math.sqrt(norms[i]))
        more = np.flatnonzero(a @ x > bound)
        grown = np.union1d(active, more)
        if moved <= 1e-12 * (1.0 + float(np.max(np.abs(x)))) and grown.size == active.size:
            break
        active = grown
    return x
