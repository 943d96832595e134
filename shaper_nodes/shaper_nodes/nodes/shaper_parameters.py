"""The shaper node's parameters: their class (:class:`ShaperParams`, whose table :data:`PARAMETERS` is declared
by nodes/shaper.py) and what their values mean: the active shaper's design (:func:`design_from_params`), the
joint limits (:func:`limits_from_params`). See config/shaper.yaml.

The node reads its parameters typed (``ShaperParams``, :func:`shaper_nodes.ros.parameters.declare`); the
functions here only interpret them.
"""

from __future__ import annotations

import pathlib
from collections.abc import Iterable
from dataclasses import dataclass, field

from rclpy.parameter import Parameter

from shaper_nodes.core.shaping import (
    DEFAULT_MAX_GAIN,
    FAMILIES,
    MAX_DESIGN_MODES,
    MAX_GAIN,
    Mode,
    Shaper,
    ShaperError,
    design,
    discretize,
    modes_from_hz,
    none_shaper,
)
from shaper_nodes.core.shaping.limits import JointLimits, urdf_limits
from shaper_nodes.core.shaping.policy import FREQUENCY_RANGE_HZ, MIN_INSENSITIVITY, check_design
from shaper_nodes.core.shaping.trajectory import MAX_TRAJECTORY_SAMPLES
from shaper_nodes.ros.parameters import Spec, param, table, topic

DESIGN_PARAMS = ("shaper.family", "shaper.frequency_hz", "shaper.damping_ratio",
                 "shaper.frequencies_hz", "shaper.damping_ratios",
                 "shaper.derivative_order", "shaper.vibration_tolerance", "shaper.insensitivity",
                 "discretization")
DISCRETIZATIONS = ("split", "round", "exact")
TOPICS = {
    "array_in": "~/commands", "array_out": "/forward_position_controller/commands",
    "stream_in": "~/joint_trajectory_stream", "stream_out": "/joint_trajectory_controller/joint_trajectory",
    "trajectory_in": "~/joint_trajectory", "trajectory_out": "/joint_trajectory_controller/joint_trajectory",
}
_PROBE = Mode.from_hz(10.0, 0.05)  # a mode to hold one design parameter against the core
#: default of limits.max_trajectory_samples (see there)
DEFAULT_MAX_SAMPLES = 5_000
#: choices of the stream_executor parameter
STREAM_EXECUTORS = ("thread", "take", "node")


@dataclass(frozen=True)
class DesignParams:
    """shaper.*: the active shaper's design (:func:`design_from_params`), and the largest gain of a custom one."""

    family: str = param("none", "Shaper family: " + ", ".join(f"{k} ({v})" for k, v in FAMILIES.items()
                                                             if k != "custom"),
                        check=lambda v: design(v, [_PROBE]))
    frequency_hz: float = param(10.0, "Natural frequency of the mode to shape for, Hz (undamped); not used, and"
                                " a change refused, while shaper.frequencies_hz is set. Below command_rate / 4.",
                                FREQUENCY_RANGE_HZ,
                                check=lambda v: design("zv", [Mode.from_hz(v, 0.05)]))
    damping_ratio: float = param(0.05, "Damping ratio of the mode to shape for, dimensionless; not used, and a"
                                 " change refused, while shaper.frequencies_hz is set.", (0.0, 0.95),
                                 check=lambda v: design("zv", [Mode.from_hz(10.0, v)]))
    frequencies_hz: tuple[float, ...] = param(
        None, "Several modes: their natural frequencies, Hz (undamped), one per entry"
        " of shaper.damping_ratios. When set (non-empty), the family is designed on all these modes (the"
        " single-mode designs convolved; si designs them jointly) and shaper.frequency_hz and"
        " shaper.damping_ratio are not used (a change of either is refused)."
        f" At most {MAX_DESIGN_MODES} modes, each below command_rate / 4."
        " A change of the number of modes sets both lists at once (ros2 param load, or one atomic set).",
        type=Parameter.Type.DOUBLE_ARRAY, check=lambda v: modes_from_hz(v, [0.05] * len(v)))
    damping_ratios: tuple[float, ...] = param(
        None, "Several modes: their damping ratios, dimensionless, in [0, 0.95], one per"
        " entry of shaper.frequencies_hz (see there).", type=Parameter.Type.DOUBLE_ARRAY,
        check=lambda v: modes_from_hz([10.0] * len(v), v))
    derivative_order: int = param(2, "n of the ZV-D^n family (family zvdn): 0 = ZV, 1 = ZVD, 2 = ZVDD.", (0, 10),
                                  check=lambda v: design("zvdn", [_PROBE], derivative_order=v))
    vibration_tolerance: float = param(
        0.05, "EI, multi-hump EI and SI families: tolerated percentage vibration,"
        " fraction (0.05 = 5 %).", (0.001, 0.3), check=lambda v: design("ei", [_PROBE], vibration_tolerance=v))
    insensitivity: float = param(
        0.4, "SI family: width of the band where V <= vibration_tolerance, fraction of"
        " the design frequency (0.4 = +-20 %).", (MIN_INSENSITIVITY, 1.5),
        check=lambda v: design("si", [_PROBE], insensitivity=v))
    max_gain: float = param(
        DEFAULT_MAX_GAIN, "Largest gain sum |A| of a custom shaper sent to ~/set_shaper:"
        " 1 (default) admits non-negative impulses only; larger allows negative impulses, whose output may"
        f" overshoot the input by up to this factor. In [1, {MAX_GAIN:g}].", (1.0, MAX_GAIN),
        check=lambda v: design("custom", amplitudes=[1.0], times=[0.0], max_gain=v))


@dataclass(frozen=True)
class LimitParams:
    """limits.*: input bounds and joint limits (:func:`limits_from_params`)."""

    max_abs_value: float = param(
        1e6, "Largest magnitude of any input value (position rad or m, velocity,"
        " acceleration in their SI units): a larger, finite value is implausible and refused before it reaches"
        " the filters, so their state keeps its precision and no sum overflows.", (1e-3, 1e12))
    max_trajectory_samples: int = param(
        DEFAULT_MAX_SAMPLES, "Most samples of a shaped whole trajectory (its span"
        " plus the shaper's duration, times command_rate); a longer one is refused before any work. Sending a"
        " trajectory's message holds the Python interpreter in rclpy's conversion for a time that grows with it,"
        " and the stream waits that long: about 0.4 ms per 1000 samples on a 2-core machine (docs/shaping.md)."
        f" The default, {DEFAULT_MAX_SAMPLES} (10 s at 500 Hz, 5 s at 1 kHz), keeps that wait under two periods"
        " at 1 kHz; raise it for longer trajectories if the stream can wait longer while one is shaped."
        f" At most {MAX_TRAJECTORY_SAMPLES}.", (100, MAX_TRAJECTORY_SAMPLES))
    position_lower: tuple[float, ...] = param(
        None, "Lowest position of each joint (rad or m), one per joint_names entry, in"
        " that order; empty (default): none (or the URDF's). No output passes below it.",
        read_only=True, type=Parameter.Type.DOUBLE_ARRAY)
    position_upper: tuple[float, ...] = param(
        None, "Highest position of each joint (rad or m), one per joint_names entry;"
        " empty (default): none (or the URDF's). No output passes above it.",
        read_only=True, type=Parameter.Type.DOUBLE_ARRAY)
    velocity: tuple[float, ...] = param(
        None, "Largest |velocity| of each joint (rad/s or m/s), one per joint_names entry;"
        " .inf for none on a joint; empty (default): none (or the URDF's). Whole trajectories whose shaped"
        " velocities pass it, and streamed points whose shaped velocities pass it, are refused.",
        read_only=True, type=Parameter.Type.DOUBLE_ARRAY)
    acceleration: tuple[float, ...] = param(
        None, "Largest |acceleration| of each joint (rad/s^2 or m/s^2), one per"
        " joint_names entry; .inf for none on a joint; empty (default): none (URDF has none). As limits.velocity.",
        read_only=True, type=Parameter.Type.DOUBLE_ARRAY)
    urdf_file: str = param(
        "", "A URDF file whose <limit> elements (position, velocity) hold for the joints"
        " too; where a parameter above also sets a limit, the tighter one holds. Every joint of joint_names must"
        " be a revolute, prismatic or continuous joint of it. Empty (default): no URDF.", read_only=True)


@dataclass(frozen=True)
class GraphWatchParams:
    """graph_watch.*: the look at the ROS graph around the command path (ros/graph_watch.py)."""

    period: float = param(
        1.0, "Period of the look at the ROS graph around the command path, s of wall"
        " time: another node of this node's name, several publishers on an input, another publisher on an"
        " output, a wrong message type or incompatible QoS on either, reported on /diagnostics (status"
        " '<node>: graph') and logged once each (ros/graph_watch.py). A look asks for the node names and the"
        " endpoint counts; every endpoint with its QoS only when those changed, a middleware event waits, or every"
        " 10 looks. 0 disables it.", (0.0, 3600.0),
        read_only=True)


@dataclass(frozen=True)
class TopicParams:
    """topics.*: the inputs and outputs (defaults: :data:`TOPICS`)."""

    array_in: str = topic(TOPICS["array_in"], "array_in")
    array_out: str = topic(TOPICS["array_out"], "array_out")
    stream_in: str = topic(TOPICS["stream_in"], "stream_in")
    stream_out: str = topic(TOPICS["stream_out"], "stream_out")
    trajectory_in: str = topic(TOPICS["trajectory_in"], "trajectory_in")
    trajectory_out: str = topic(TOPICS["trajectory_out"], "trajectory_out")


@dataclass(frozen=True)
class ActionParams:
    """action.*: the FollowJointTrajectory proxy (nodes/trajectory_action.py, ros/pose_shaper.py)."""

    server_name: str = param("~/follow_joint_trajectory", "FollowJointTrajectory action served by this node;"
                             " empty: no action server.", read_only=True)
    controller: str = param("/joint_trajectory_controller/follow_joint_trajectory", "The controller's"
                            " FollowJointTrajectory action that shaped goals are forwarded to.", read_only=True)
    server_timeout: float = param(
        2.0, "How long a goal waits for the controller's action server and for its"
        " answer to the goal request, and (with action.scheduler) for the scheduler's answer, s.", (0.01, 3600.0),
        read_only=True)
    scheduler: str = param(
        "", "Fully qualified name of a scheduler node (e.g. '/scheduler'): each goal is then"
        " shaped with the shaper <scheduler>/shaper_at gives for the goal trajectory's final point (the modes"
        " where the move ends), not with the active shaper, which stays as it is. If the scheduler is absent,"
        " does not answer within action.server_timeout, refuses the pose, or its shaper fails this node's checks,"
        " the goal is shaped with the active shaper and a warning says why. Empty (default): the active shaper.",
        read_only=True)


@dataclass(frozen=True)
class ShaperParams:
    """The shaper node's parameters (see config/shaper.yaml)."""

    joint_names: tuple[str, ...] = param(
        None, "Joints to shape, in the order of Float64MultiArray data and of the outputs.",
        read_only=True, type=Parameter.Type.STRING_ARRAY)
    command_rate: float = param(500.0, "Rate of the streamed setpoints and of whole-trajectory resampling, Hz.",
                                (1.0, 10000.0), read_only=True, check=lambda v: discretize(none_shaper(), v))
    shaper: DesignParams = field(default_factory=DesignParams)
    discretization: str = param(
        "split", "Impulse times between samples: 'split' linearly between the two samples"
        " (default), 'round', or 'exact' (the split corrected so the FIR meets the shaper's conditions at its"
        " modes exactly).", choices=DISCRETIZATIONS,
        check=lambda v: discretize(design("zv", [_PROBE]), 500.0, v))
    limits: LimitParams = field(default_factory=LimitParams)
    stream_executor: str = param(
        "take", "Who takes the streamed inputs (array_in, stream_in): 'take' (default), a lean second"
        " node of this process, '<name>_stream', with nothing but those two subscriptions, served on a thread of its"
        " own by a take loop (one wait set built once, no rclpy executor: ros/take_loop.py; about half the echo"
        " node's CPU per message); the topics stay this node's: ~/commands is /<name>/commands; 'thread': the same"
        " lean node spun by rclpy's SingleThreadedExecutor on its thread; 'node': this node's executor, with its"
        " services, parameters and timers (one thread; every wake-up of the executor then waits on all"
        " of them, which costs the stream CPU and latency: docs/results/benchmarks.md).",
        choices=STREAM_EXECUTORS, read_only=True)
    queue_depth: int = param(
        100, "Depth of the streamed inputs' subscription queues (array_in, stream_in), messages:"
        " how long a burst or a stall of the node may last without a sample being dropped (100 = 0.1 s at"
        " 1 kHz); a dropped sample is counted on /diagnostics.", (1, 100000), read_only=True)
    allowed_sources: tuple[str, ...] = param(
        ["parameters", "service", "learner", "scheduler", "identification", "user"],
        "Sources allowed to change the active shaper (update policy).", read_only=True)
    retime_sources: tuple[str, ...] = param(
        None, "Sources whose changes re-time the motion already commanded (time-varying"
        " shaping: pending impulses follow the new shaper, e.g. 'scheduler' for pose-dependent modes) instead of"
        " the bumpless switch that leaves it to the old shaper. Default none.", read_only=True,
        type=Parameter.Type.STRING_ARRAY)
    error_throttle: float = param(
        1.0, "Least time between two error logs or diagnostics of the same class of bad input, s.", (0.0, 3600.0))
    diagnostics_period: float = param(1.0, "Period of the diagnostics summary, s.", (0.05, 3600.0), read_only=True)
    graph_watch: GraphWatchParams = field(default_factory=GraphWatchParams)
    topics: TopicParams = field(default_factory=TopicParams)
    action: ActionParams = field(default_factory=ActionParams)


#: the shaper node's parameters (derived from ShaperParams; see config/shaper.yaml)
PARAMETERS: tuple[Spec, ...] = table(ShaperParams)

def describe(s: Shaper) -> str:
    """One line on a shaper: its family, impulses, duration (ms) and modes (Hz, damping ratio)."""
    modes = ", ".join(f"{m.hz:.4g} Hz zeta {m.zeta:.3g}" for m in s.modes)
    return f"{s.family} ({len(s)} impulses, {s.duration * 1e3:.1f} ms{', ' + modes if modes else ''})"


def design_from_params(p: ShaperParams, rate: float) -> tuple[Shaper, str]:
    """The shaper the design parameters ``p`` give (``p.shaper`` and ``p.discretization``), and the
    discretization method; ``rate`` is the command rate, Hz.

    Raises
    ------
    ShaperError
        The values do not make a shaper (the message names the parameter).
    """
    method = str(p.discretization)
    if method not in DISCRETIZATIONS:
        raise ShaperError(f"discretization must be 'split', 'round' or 'exact', got {method!r}")
    s = p.shaper
    family = str(s.family).strip().lower()
    if family == "custom":
        raise ShaperError("family 'custom' is set through the ~/set_shaper service, not parameters")
    modes, name = modes_from_params(s)
    shaper = design(family, modes,
                    derivative_order=int(s.derivative_order),
                    vibration_tolerance=float(s.vibration_tolerance),
                    insensitivity=float(s.insensitivity))
    check_design(shaper, rate, name)  # the check every path that sets the shaper makes (~/set_shaper too)
    return shaper, method


def modes_from_params(s: DesignParams) -> tuple[tuple[Mode, ...], str]:
    """The design modes: shaper.frequencies_hz with shaper.damping_ratios when set, else
    shaper.frequency_hz with shaper.damping_ratio; and the name of the parameter they came from
    (frequencies in Hz, damping ratios dimensionless).

    Raises
    ------
    ShaperError
        The lists do not make modes, or a mode is too slow to design for (the message names the
        parameter, its entry and its value in Hz).
    """
    freqs, zetas = list(s.frequencies_hz), list(s.damping_ratios)
    if not freqs and not zetas:
        mode = Mode.from_hz(float(s.frequency_hz), float(s.damping_ratio))
        mode.check_designable(f"shaper.frequency_hz {float(s.frequency_hz)!r} Hz, that is")
        return (mode,), "shaper.frequency_hz"
    try:
        modes = modes_from_hz(freqs, zetas)
    except ShaperError as err:
        raise ShaperError(f"shaper.frequencies_hz / shaper.damping_ratios: {err}") from None
    for i, (mode, hz) in enumerate(zip(modes, freqs, strict=True)):  # named by the parameter, in Hz
        mode.check_designable(f"shaper.frequencies_hz[{i}] {float(hz)!r} Hz, that is")
    return modes, "shaper.frequencies_hz"


#: the single-mode design parameters that shaper.frequencies_hz displaces
SINGLE_MODE = ("shaper.frequency_hz", "shaper.damping_ratio")


def ineffective(now: ShaperParams, proposed: ShaperParams, names: Iterable[str]) -> str | None:
    """Why a change of the parameters ``names`` from ``now`` to ``proposed`` cannot take effect, or
    None if it can: shaper.frequency_hz or shaper.damping_ratio changed while shaper.frequencies_hz
    is (and stays) set, which takes precedence (a value equal to the present one, as ``ros2 param
    load`` of a dump sends it, is no change)."""
    if not proposed.shaper.frequencies_hz:
        return None
    for name in SINGLE_MODE:
        if name not in names:
            continue
        field_name = name.split(".", 1)[1]
        old, new = getattr(now.shaper, field_name), getattr(proposed.shaper, field_name)
        if float(old) != float(new):
            hz = ", ".join(f"{f:g}" for f in proposed.shaper.frequencies_hz)
            return (f"{name} {float(new):g} cannot take effect: shaper.frequencies_hz is set ([{hz}] Hz) and takes"
                    " precedence; set shaper.frequencies_hz and shaper.damping_ratios instead, or empty both"
                    f" in the same atomic request that sets {name}")
    return None


def displacement(before: str, revision: int, source: str) -> str | None:
    """How a change by ``source`` displaces the active shaper of source ``before`` (revision
    ``revision``), in words; None if it is the same source's (no other source's shaper is replaced)."""
    if before == source:
        return None
    return f"replaces the shaper set by {before} (revision {revision})"


def limits_from_params(joint_names: list[str], lim: LimitParams) -> JointLimits:
    """The joint limits: the parameters' (``lim``, positions in rad or m, velocities in rad/s or m/s,
    accelerations in rad/s^2 or m/s^2), and the URDF's when limits.urdf_file is set (the tighter).

    Raises
    ------
    ValueError
        A list of the wrong length or with bad entries, or a URDF that cannot be read or lacks a joint.
    """
    limits = JointLimits.from_lists(joint_names, lim.position_lower, lim.position_upper, lim.velocity,
                                    lim.acceleration)
    urdf_file = str(lim.urdf_file).strip()
    if urdf_file:
        try:
            text = pathlib.Path(urdf_file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise ValueError(f"limits.urdf_file: cannot read {urdf_file}: {err}") from None
        try:
            limits = limits.tighter(urdf_limits(text, joint_names))
        except ValueError as err:
            raise ValueError(f"limits.urdf_file {urdf_file}: {err}") from None
    return limits
