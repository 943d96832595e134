"""The identifier node's parameters (config/identifier.yaml): :class:`IdentifierParams`, whose table
:data:`PARAMETERS` nodes/identifier.py declares.

Split from :mod:`shaper_nodes.nodes.identifier` (which imports them from here, as before) to keep the node module
short.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from shaper_nodes.core.identification import METHODS, ModeFit, recommend_shaper
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL
from shaper_nodes.ros.lockstep_reader import IMU_RELIABLE_DOC
from shaper_nodes.ros.parameters import Spec, param, table, topic


def validate_method(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"unknown identification method {method!r}; known: {sorted(METHODS)}")
    return method

def _check_band(value: Any) -> None:
    lo, hi = (float(x) for x in value)
    if hi > 0.0 and not 0.0 <= lo < hi:
        raise ValueError(f"parameter band_hz must be [low, high] with 0 <= low < high, got {[lo, hi]}")


_PROBE = ModeFit(2 * math.pi * 10.0, 0.02, 0.5, 0.002, 1.0, "fit")  # to hold one value against the core

@dataclass(frozen=True)
class SensorParams:
    """sensor.*: the accelerometer's range."""

    max_abs_accel: float = param(MAX_ABS_ACCEL, "Accelerometer range, m/s^2: a cycle with a sample at or beyond"
                                 " it is refused as saturated (default 16 g).", (1e-3, 1e6))


@dataclass(frozen=True)
class WatchParams:
    """watch.*: the drift watch."""

    enabled: bool = param(True, "Drift watch: rate every buffered cycle's mode against the active shaper's working"
                          " band and warn on /diagnostics when it leaves it.", read_only=True)
    tolerance: float = param(0.05, "Drift watch: the working band is where the active shaper keeps V under this,"
                             " fraction.", (0.001, 0.5))
    confirm: int = param(2, "Drift watch: cycles in a row outside the band before the warning.", (1, 1000))
    max_uncertainty: float = param(
        0.02, "Drift watch: a mode whose one-sigma frequency uncertainty exceeds this"
        " fraction of its frequency is not rated (a fit to a residual at the noise floor, where the shaper leaves"
        " nothing to identify).", (1e-4, 1.0))
    baseline_cycles: int = param(
        1, "Drift watch: the first watched cycles (of each move with watch.scheduler; since the active shaper's"
        " latest change without) whose identified modes, all of them, make the watch's baseline: a mode outside"
        " the band that is the same as a baseline mode outside the band (present from the start, as the position"
        " loop's damped pole) is not drift and does not count toward watch.confirm. A cycle where nothing was"
        " identified counts too; a payload changed within these cycles is in the baseline. 0: no baseline, every"
        " mode outside the band counts.", (0, 100), read_only=True)
    baseline_margin: float = param(
        0.03, "Drift watch: the same mode as a baseline mode if its frequency is within 3 combined one-sigma"
        " uncertainties plus the larger of this fraction and the baseline mode's damping ratio (its resonance's"
        " half-power half-width) of the baseline mode's frequency, and its damping ratio within a factor 2;"
        " fraction (a payload moves the arm's modes 5-30 %).", (0.0, 0.5), read_only=True)
    max_shift: float = param(
        0.3, "Drift watch: the most a payload change moves a mode, fraction: a mode outside the band more than"
        " this above the shaper's highest design mode is none of the modes the shaper was designed for, moved,"
        " and does not count toward watch.confirm (a higher mode a learner uncovers). Modes below are all rated.",
        (0.0, 100.0), read_only=True)
    scheduler: str = param(
        "", "Drift watch: fully qualified name of the scheduler whose ~/shaper_at gives the shaper each cycle's"
        " move ran with (its START's joints, start and goal), for a shaper node that shapes each goal through it"
        " (action.scheduler); each cycle is rated against that shaper. Empty: the active shaper.", read_only=True)


@dataclass(frozen=True)
class TopicParams:
    """topics.*: the inputs."""

    imu: str = topic("/tip_imu", "imu")
    joint_states: str = topic("/joint_states", "joint_states")
    cycle_events: str = topic("/cycle_events", "cycle_events")
    imu_reliable: bool = param(False, IMU_RELIABLE_DOC, read_only=True)


@dataclass(frozen=True)
class IdentifierParams:
    """The identifier node's parameters (see config/identifier.yaml)."""

    shaper: str = param("/shaper", "Fully qualified name of the shaper node to apply shapers to.", read_only=True)
    buffer_cycles: int = param(5, "Finished cycles kept for identification.", (1, 1000), read_only=True)
    method: str = param("fit", "Default identification method: " + ", ".join(f"{k} ({v})" for k, v in METHODS.items()),
                        check=lambda v: validate_method(v))
    max_modes: int = param(2, "Default largest number of modes to identify.", (1, 8))
    target_vibration: float = param(
        0.05, "Default worst-case percentage vibration the recommended shaper must meet,"
        " fraction.", (0.001, 0.5), check=lambda v: recommend_shaper([_PROBE], v, families=("zv",)))
    uncertainty_sigmas: float = param(
        2.0, "Half-width of the uncertainty band the worst case is taken over, in standard"
        " deviations.", (0.0, 10.0), check=lambda v: recommend_shaper([_PROBE], 0.05, sigmas=v, families=("zv",)))
    band_hz: tuple[float, ...] = param([0.0, 0.0], "Frequency band searched, Hz ([0, 0]: up to Nyquist).",
                                       check=_check_band)
    min_samples: int = param(100, "Fewest accelerometer samples in a cycle's residual window.", (10, 10**7))
    sensor: SensorParams = field(default_factory=SensorParams)
    settle_tolerance: float = param(1e-6, "Band within which the joints count as at rest after a move, rad or m.",
                                    (0.0, 1e3))
    service_timeout: float = param(5.0, "Time to wait for the shaper node's set_shaper service, and then for its"
                                   " answer, s.", (0.1, 600.0))
    watch: WatchParams = field(default_factory=WatchParams)
    topics: TopicParams = field(default_factory=TopicParams)


#: the identifier node's parameters (derived from IdentifierParams)
PARAMETERS: tuple[Spec, ...] = table(IdentifierParams)
