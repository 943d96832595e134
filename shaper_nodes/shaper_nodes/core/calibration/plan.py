"""The calibration plan: which poses, how each is excited, in which order, and how long it takes.

A plan visits poses of the arm and, at each, excites the structure with short moves and lets
it ring freely. Poses are a grid over the joints that change the dynamics (``grid_joints``,
ranges and counts) with the other joints at ``base_pose``, or an explicit list. Joints listed
in ``follow`` move with the grid so that the tool keeps its orientation, e.g. a UR arm's
wrist_1 with gains (-1, -1) on shoulder_lift and elbow: q_f = base_f + sum_j g_fj (q_j - base_j).

The excitation at a pose p is one out-and-back move of the ``excitation_joints`` by
``amplitude`` (rad, signed per joint): a trajectory with two waypoints, p + delta at T/2 and
p at T, both at rest, then p held for ``decay`` s. joint_trajectory_controller joins waypoints that carry positions,
velocities and accelerations with quintic polynomials, so each half is the minimum-jerk-like
quintic s(u) = 10 u^3 - 15 u^4 + 6 u^5, whose largest speed is 1.875 |delta| / (T/2) and
largest acceleration 5.7735 |delta| / (T/2)^2 (jerk bounded). T/2 is the least time that keeps
both within the excitation's speed and acceleration bounds. After it the arm is at p again
and rings freely for ``decay`` s; this repeats ``repeats`` times, so every free decay is
recorded at the pose itself. Repeats vary the mix: repeat r >= 1 halves the excursion of
excitation joint r - 1 (cyclically), so each mode is excited in other proportions and an
estimate pulled by what the identification's model leaves out (heavily damped modes, a close
neighbour) moves between repeats: the spread enters the reported uncertainty and the
repeats' agreement check. Approaches between poses are single quintic moves within the
approach bounds, followed by ``settle`` s at rest.

Order: the home pose first (its modes give the fallback shaper), then the grid in serpentine
order (each row reversed in turn, so consecutive poses are neighbours) or an explicit list
by nearest neighbour; back to home at the end.

Every bound is checked before anything moves: a plan that leaves the joint limits, exceeds a
speed or acceleration limit, or is too large is refused with :class:`PlanError` naming the
problem.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shaper_nodes.core.checks import finite_values, in_range, integer

#: peak speed and acceleration of the quintic s(u) over a move of length 1 and duration 1
QUINTIC_SPEED = 1.875
QUINTIC_ACCELERATION = 10.0 / math.sqrt(3.0)
#: bounds that keep a plan a calibration (not a task)
MAX_POSES = 100
MAX_GRID_COUNT = 10
MAX_REPEATS = 10
MAX_AMPLITUDE = 0.2  # rad, the largest excitation of one joint
MAX_DECAY = 10.0  # s
MIN_MOVE_TIME = 0.05  # s, shortest half-excitation or approach


#: a pose to visit: name, joint positions, its place on the grid (None off the grid)
Target = tuple[str, np.ndarray, "tuple[int, ...] | None"]


class PlanError(ValueError):
    """A plan that cannot or must not be executed; the message says why."""


@dataclass(frozen=True)
class Limits:
    """Per-joint position range (rad), largest speed (rad/s) and acceleration (rad/s^2)."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True)
class PlanConfig:
    """What to calibrate and how (see the module docstring; units rad, s, Hz)."""

    joint_names: tuple[str, ...]
    limits: Limits
    base_pose: np.ndarray
    home_pose: np.ndarray
    grid_joints: tuple[str, ...] = ()
    grid_lower: tuple[float, ...] = ()
    grid_upper: tuple[float, ...] = ()
    grid_counts: tuple[int, ...] = ()
    poses: tuple[tuple[float, ...], ...] = ()
    follow: dict[str, tuple[float, ...]] = field(default_factory=dict)
    excitation_joints: tuple[str, ...] = ()
    amplitude: tuple[float, ...] = ()
    excitation_velocity: float = 0.5
    excitation_acceleration: float = 10.0
    repeats: int = 3
    decay: float = 2.0
    approach_velocity: float = 0.5
    approach_acceleration: float = 2.0
    settle: float = 1.0


@dataclass(frozen=True)
class Waypoint:
    """A point of a move: time from the move's start (s) and joint positions (rad), at rest."""

    time: float
    positions: np.ndarray


@dataclass(frozen=True)
class PoseStep:
    """One pose of the plan: where, how to get there, and its excitation."""

    index: int
    name: str
    pose: np.ndarray
    approach: tuple[Waypoint, ...]
    excitations: tuple[tuple[Waypoint, ...], ...]  # one trajectory per repeat
    repeats: int
    decay: float
    settle: float
    grid_index: tuple[int, ...] | None = None  # its place on the grid, if it is a grid pose
    home: bool = False

    @property
    def excitation_time(self) -> float:
        """Duration of the commanded excursion (the excitation trajectory then holds for ``decay``), s."""
        return self.excitations[0][-2].time

    @property
    def duration(self) -> float:
        """Simulated/robot time of the step: approach with its rest, repeats x (excitation + decay), s."""
        return self.approach[-1].time + sum(e[-1].time for e in self.excitations)


@dataclass(frozen=True)
class Plan:
    """The ordered steps, the final move home, and the configuration that made them."""

    config: PlanConfig
    start: np.ndarray
    steps: tuple[PoseStep, ...]
    back_home: tuple[Waypoint, ...]

    @property
    def duration(self) -> float:
        """Robot time of the whole plan, s (excluding the controller's and the network's latency)."""
        return sum(s.duration for s in self.steps) + self.back_home[-1].time

    def travel(self) -> float:
        """Sum over moves of the largest joint displacement, rad (what the order keeps short)."""
        pts = [self.start] + [s.pose for s in self.steps] + [self.config.home_pose]
        return float(sum(np.max(np.abs(b - a)) for a, b in itertools.pairwise(pts)))

    def describe(self) -> str:
        """The plan as text: poses, their joint values, excitation, durations."""
        c = self.config
        ex = ", ".join(f"{j} {a:+.3g}" for j, a in zip(c.excitation_joints, c.amplitude, strict=True))
        lines = [f"calibration plan: {len(self.steps)} poses, {self.steps[0].repeats} excitations each"
                 f" (out and back: {ex} rad, {self.steps[0].excitation_time:.3f} s, then {c.decay:g} s free"
                 " decay; from the second on one joint's excursion halved in turn); approach at <="
                 f" {c.approach_velocity:g} rad/s, {c.approach_acceleration:g} rad/s^2,"
                 f" then {c.settle:g} s at rest",
                 f"joints: {', '.join(c.joint_names)}"]
        for s in self.steps:
            lines.append(f"  {s.index:3d} {s.name:<12} [" + ", ".join(f"{v:+.4f}" for v in s.pose)
                         + f"]  {s.duration:6.2f} s")
        lines.append(f"  then back home ({self.back_home[-1].time:.2f} s)")
        lines.append(f"duration: {self.duration:.1f} s of robot time ({self.duration / 60:.1f} min), travel"
                     f" {self.travel():.2f} rad")
        return "\n".join(lines)


def approach(pose: np.ndarray, duration: float, settle: float) -> tuple[Waypoint, ...]:
    """A move to ``pose`` in ``duration`` s, then held for ``settle`` s (a rest inside the trajectory, so
    the controller keeps executing and a lockstep simulator keeps time running)."""
    return (Waypoint(duration, pose),) + ((Waypoint(duration + settle, pose),) if settle > 0 else ())


def excursion(delta: np.ndarray, joints: Sequence[int], repeat: int) -> np.ndarray:
    """The excursion of repeat ``repeat``: ``delta``, with excitation joint ``repeat - 1`` (cyclically) halved
    from the second repeat on (module docstring)."""
    d = np.asarray(delta, dtype=float).copy()
    if repeat >= 1 and len(joints) > 1:
        d[joints[(repeat - 1) % len(joints)]] *= 0.5
    return d


def quintic_time(distance: np.ndarray, velocity: np.ndarray | float, acceleration: np.ndarray | float) -> float:
    """Least duration of a rest-to-rest quintic move over ``distance`` (per joint) within the bounds."""
    d = np.abs(np.asarray(distance, dtype=float))
    t_v = QUINTIC_SPEED * d / np.asarray(velocity, dtype=float)
    t_a = np.sqrt(QUINTIC_ACCELERATION * d / np.asarray(acceleration, dtype=float))
    return max(MIN_MOVE_TIME, float(np.max(np.maximum(t_v, t_a))))


def _index(names: Sequence[str], wanted: Sequence[str], what: str) -> list[int]:
    missing = [w for w in wanted if w not in names]
    if missing:
        raise PlanError(f"{what} names joints that are not in joint_names: {missing}")
    if len(set(wanted)) != len(wanted):
        raise PlanError(f"{what} lists a joint twice: {list(wanted)}")
    return [list(names).index(w) for w in wanted]


def _vector(name: str, values: Any, n: int) -> np.ndarray:
    v = finite_values(name, values, PlanError)
    if v.size == 1 and n > 1:
        v = np.full(n, float(v[0]))
    if v.size != n:
        raise PlanError(f"{name} needs {n} values (one per joint), got {v.size}")
    return v


def make_limits(n: int, lower: Any, upper: Any, velocity: Any, acceleration: Any) -> Limits:
    lim = Limits(_vector("limits.lower", lower, n), _vector("limits.upper", upper, n),
                 _vector("limits.max_velocity", velocity, n), _vector("limits.max_acceleration", acceleration, n))
    if np.any(lim.lower >= lim.upper):
        raise PlanError(f"limits.lower must be below limits.upper for every joint, got {lim.lower.tolist()} and"
                        f" {lim.upper.tolist()}")
    if np.any(lim.velocity <= 0) or np.any(lim.acceleration <= 0):
        raise PlanError("limits.max_velocity and limits.max_acceleration must be > 0")
    return lim


def grid_axis(lower: float, upper: float, count: int, home: float) -> np.ndarray:
    """``count`` values evenly from ``lower`` to ``upper`` (the middle for one), with the home pose's
    value added when it lies inside and is not on them already: home is always a grid point, so the
    schedule there is what was measured there."""
    axis = np.linspace(lower, upper, count) if count > 1 else np.array([0.5 * (lower + upper)])
    if lower <= home <= upper and not np.any(np.abs(axis - home) < 1e-6):
        axis = np.sort(np.append(axis, home))
    return axis


def _grid(c: PlanConfig, names: tuple[str, ...]) -> list[Target]:
    gi = _index(names, c.grid_joints, "grid.joints")
    k = len(gi)
    if not (len(c.grid_lower) == len(c.grid_upper) == len(c.grid_counts) == k):
        raise PlanError(f"grid.lower, grid.upper and grid.counts need one value per grid joint ({k}), got"
                        f" {len(c.grid_lower)}, {len(c.grid_upper)} and {len(c.grid_counts)}")
    axes = []
    for j, lo, hi, cnt in zip(c.grid_joints, c.grid_lower, c.grid_upper, c.grid_counts, strict=True):
        cnt = integer(f"grid.counts of {j}", cnt, 1, MAX_GRID_COUNT, PlanError)
        if cnt > 1 and not hi > lo:
            raise PlanError(f"grid of {j}: upper {hi:g} must exceed lower {lo:g}")
        axes.append(grid_axis(lo, hi, cnt, float(c.home_pose[names.index(j)])))
    total = math.prod(a.size for a in axes)
    if any(a.size > MAX_GRID_COUNT for a in axes):
        raise PlanError(f"a grid axis has more than {MAX_GRID_COUNT} values")
    if total > MAX_POSES:
        raise PlanError(f"the grid has {total} poses; at most {MAX_POSES} are planned")
    follow = {}
    for fj, gains in c.follow.items():
        g = finite_values(f"follow gains of {fj}", gains, PlanError)
        if g.size != k:
            raise PlanError(f"follow.{fj} needs one gain per grid joint ({k}), got {g.size}")
        if fj in c.grid_joints:
            raise PlanError(f"joint {fj} cannot both follow and be a grid joint")
        follow[_index(names, [fj], "follow")[0]] = g
    # serpentine: the last grid joint varies fastest, reversed on every other row
    ordered = _serpentine(list(itertools.product(*[range(a.size) for a in axes])), [a.size for a in axes])
    poses: list[Target] = []
    for combo in ordered:
        p = c.base_pose.copy()
        for i, ax, ci in zip(gi, axes, combo, strict=True):
            p[i] = ax[ci]
        for fi, g in follow.items():
            p[fi] = c.base_pose[fi] + float(g @ (p[gi] - c.base_pose[gi]))
        poses.append(("grid " + ",".join(str(ci) for ci in combo), p, tuple(int(x) for x in combo)))
    return poses


def _serpentine(combos: list[tuple[int, ...]], sizes: list[int]) -> list[tuple[int, ...]]:
    """Boustrophedon order: consecutive grid points differ in one index by one."""
    if len(sizes) <= 1:
        return combos
    out: list[tuple[int, ...]] = []
    inner = _serpentine([c[1:] for c in combos if c[0] == 0], sizes[1:])
    for i in range(sizes[0]):
        row = inner if i % 2 == 0 else inner[::-1]
        out.extend((i, *c) for c in row)
    return out


def _nearest_order(start: np.ndarray, poses: list[Target]) -> list[Target]:
    left, out, here = list(poses), [], start
    while left:
        k = min(range(len(left)), key=lambda i: float(np.max(np.abs(left[i][1] - here))))
        out.append(left.pop(k))
        here = out[-1][1]
    return out


def make_plan(c: PlanConfig, start: Sequence[float] | np.ndarray | None = None) -> Plan:
    """The plan for ``c``, starting where the arm is (``start``; default the home pose).

    Raises
    ------
    PlanError
        The configuration is inconsistent, or a pose, an excitation or a move leaves the
        limits; the message names the joint, the value and the limit.
    """
    names = tuple(c.joint_names)
    n = len(names)
    if n == 0 or len(set(names)) != n:
        raise PlanError(f"joint_names must be distinct, at least one; got {list(names)}")
    lim = c.limits
    base = _vector("base_pose", c.base_pose, n)
    home = _vector("home_pose", c.home_pose, n)
    here = home if start is None else _vector("start", start, n)
    c = PlanConfig(**{**c.__dict__, "base_pose": base, "home_pose": home})
    integer("excitation.repeats", c.repeats, 1, MAX_REPEATS, PlanError)
    in_range("excitation.decay", c.decay, 0.2, MAX_DECAY, error=PlanError)
    in_range("approach.settle", c.settle, 0.0, 60.0, error=PlanError)
    for name, v, cap in (("excitation.max_velocity", c.excitation_velocity, lim.velocity),
                         ("excitation.max_acceleration", c.excitation_acceleration, lim.acceleration),
                         ("approach.max_velocity", c.approach_velocity, lim.velocity),
                         ("approach.max_acceleration", c.approach_acceleration, lim.acceleration)):
        in_range(name, v, 0.0, math.inf, lo_open=True, error=PlanError)
        over = [f"{j} ({cj:g})" for j, cj in zip(names, cap, strict=True) if v > cj]
        if over:
            raise PlanError(f"{name} {v:g} exceeds the limit of joint(s) {', '.join(over)}")
    ei = _index(names, c.excitation_joints, "excitation.joints")
    if not ei:
        raise PlanError("excitation.joints is empty: nothing would excite the structure")
    amp = finite_values("excitation.amplitude", c.amplitude, PlanError)
    if amp.size != len(ei):
        raise PlanError(f"excitation.amplitude needs one value per excitation joint ({len(ei)}), got {amp.size}")
    if np.any(np.abs(amp) > MAX_AMPLITUDE) or np.any(amp == 0):
        raise PlanError(f"excitation.amplitude must be non-zero and within +-{MAX_AMPLITUDE:g} rad per joint, got"
                        f" {amp.tolist()}")
    if c.poses and c.grid_joints:
        raise PlanError("give either a grid (grid.joints) or an explicit list of poses, not both")
    if c.poses:
        if len(c.poses) > MAX_POSES:
            raise PlanError(f"{len(c.poses)} poses given; at most {MAX_POSES} are planned")
        listed: list[Target] = [(f"pose {i}", _vector(f"poses[{i}]", p, n), None) for i, p in enumerate(c.poses)]
        targets = _nearest_order(home, listed)
    elif c.grid_joints:
        targets = _grid(c, names)
    else:
        raise PlanError("nothing to calibrate: give grid.joints with ranges and counts, or poses")
    delta = np.zeros(n)
    delta[ei] = amp
    deltas = [excursion(delta, ei, r) for r in range(int(c.repeats))]
    half = quintic_time(delta, c.excitation_velocity, c.excitation_acceleration)
    steps = []
    # home first: on the grid it is that grid pose, else an extra pose. Absolute tolerance only: a
    # relative one (allclose's default 1e-5) would take a grid value micro-radians from home for home
    # too and drop that grid pose from the plan.
    on_grid = [t for t in targets if np.allclose(t[1], home, rtol=0.0, atol=1e-9)]
    first: Target = ("home", home, on_grid[0][2] if on_grid else None)
    visit = [first] + [t for t in targets if not np.allclose(t[1], home, rtol=0.0, atol=1e-9)]
    prev = here
    for k, (name, pose, gidx) in enumerate(visit):
        for what, p in (("pose", pose), ("excited pose", pose + delta)):
            low = [f"{j} {v:+.4f} < {lo:+.4f}" for j, v, lo in zip(names, p, lim.lower, strict=True) if v < lo]
            high = [f"{j} {v:+.4f} > {hi:+.4f}" for j, v, hi in zip(names, p, lim.upper, strict=True) if v > hi]
            if low or high:
                raise PlanError(f"{name}: the {what} leaves the joint limits: {'; '.join(low + high)}")
        t_app = quintic_time(pose - prev, c.approach_velocity, c.approach_acceleration)
        excitations = tuple((Waypoint(half, pose + d), Waypoint(2 * half, pose), Waypoint(2 * half + c.decay, pose))
                            for d in deltas)
        steps.append(PoseStep(k, name, pose, approach(pose, t_app, c.settle), excitations, int(c.repeats),
                              float(c.decay), float(c.settle), gidx, k == 0))
        prev = pose
    back = (Waypoint(quintic_time(home - prev, c.approach_velocity, c.approach_acceleration), home),)
    return Plan(c, here, tuple(steps), back)


def plan_to_dict(plan: Plan) -> dict[str, Any]:
    """The plan as plain data (for plan.json and report.json)."""
    c = plan.config
    return {"joint_names": list(c.joint_names), "start": plan.start.tolist(),
            "excitation": {"joints": list(c.excitation_joints), "amplitude": list(map(float, c.amplitude)),
                           "half_time": plan.steps[0].excitations[0][0].time, "repeats": c.repeats,
                           "decay": c.decay},
            "approach": {"max_velocity": c.approach_velocity, "max_acceleration": c.approach_acceleration,
                         "settle": c.settle},
            "grid": {"joints": list(c.grid_joints), "lower": list(map(float, c.grid_lower)),
                     "upper": list(map(float, c.grid_upper)), "counts": list(map(int, c.grid_counts))},
            "poses": [{"index": s.index, "name": s.name, "positions": s.pose.tolist(),
                       "grid_index": None if s.grid_index is None else list(s.grid_index)} for s in plan.steps],
            "duration": plan.duration}


def config_to_dict(c: PlanConfig) -> dict[str, Any]:
    """Everything that makes the plan, as plain data (saved in plan.json and in the recording)."""
    return {"joint_names": list(c.joint_names),
            "limits": {"lower": c.limits.lower.tolist(), "upper": c.limits.upper.tolist(),
                       "max_velocity": c.limits.velocity.tolist(), "max_acceleration": c.limits.acceleration.tolist()},
            "base_pose": np.asarray(c.base_pose, float).tolist(), "home_pose": np.asarray(c.home_pose, float).tolist(),
            "grid": {"joints": list(c.grid_joints), "lower": [float(x) for x in c.grid_lower],
                     "upper": [float(x) for x in c.grid_upper], "counts": [int(x) for x in c.grid_counts]},
            "poses": [list(map(float, p)) for p in c.poses],
            "follow": {k: [float(x) for x in v] for k, v in c.follow.items()},
            "excitation": {"joints": list(c.excitation_joints), "amplitude": [float(x) for x in c.amplitude],
                           "max_velocity": c.excitation_velocity, "max_acceleration": c.excitation_acceleration,
                           "repeats": int(c.repeats), "decay": c.decay},
            "approach": {"max_velocity": c.approach_velocity, "max_acceleration": c.approach_acceleration,
                         "settle": c.settle}}


def config_from_dict(d: dict[str, Any]) -> PlanConfig:
    """The inverse of :func:`config_to_dict`; raises PlanError on a malformed mapping."""
    try:
        names = tuple(str(j) for j in d["joint_names"])
        lim = d["limits"]
        g, e, a = d["grid"], d["excitation"], d["approach"]
        return PlanConfig(
            names, make_limits(len(names), lim["lower"], lim["upper"], lim["max_velocity"], lim["max_acceleration"]),
            np.asarray(d["base_pose"], float), np.asarray(d["home_pose"], float),
            tuple(g["joints"]), tuple(g["lower"]), tuple(g["upper"]), tuple(int(x) for x in g["counts"]),
            tuple(tuple(p) for p in d["poses"]), {k: tuple(v) for k, v in d["follow"].items()},
            tuple(e["joints"]), tuple(e["amplitude"]), float(e["max_velocity"]), float(e["max_acceleration"]),
            int(e["repeats"]), float(e["decay"]), float(a["max_velocity"]), float(a["max_acceleration"]),
            float(a["settle"]))
    except (KeyError, TypeError, ValueError) as err:
        if isinstance(err, PlanError):
            raise
        raise PlanError(f"not a calibration plan: {err!r}") from None
