"""What the bag analysis is asked to do: :class:`Options` (the CLI's options), apart from the analysis so that its
parts (:mod:`.cycle_rows`, :mod:`.verdict`) take it without importing :mod:`.analyze`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from shaper_nodes.core.identification import MAX_RINGING_DAMPING, NOISE_FLOOR_SIGMAS


@dataclass(frozen=True)
class Options:
    """What the analysis is asked to do (the CLI's options).

    settle_tolerance : rad or m, positions at rest; band : settling band, m/s^2 (a float) or
    a fraction of the cycle's peak (a string ending in %); remove_mean : "auto", "yes", "no";
    segmentation : "auto", "events", "motion"; method, max_modes, band_hz : identification;
    target, sigmas, min_saving : recommendation (:func:`recommend_shaper`); max_damping : damping ratio
    above which an identified mode does not ring (default :data:`MAX_RINGING_DAMPING`, 0.3), and
    noise_sigmas : a mode whose initial amplitude is at most this many accelerometer noise standard
    deviations (per axis, measured on the recording) is at the noise floor (default
    :data:`NOISE_FLOOR_SIGMAS`, 1): such modes are reported but neither designed on nor used to choose
    the shaper, and a group of cycles with no ringing mode gets "no shaper needed"; identify_cycles : most
    cycles identified (evenly spread over the usable ones; 0 = all); learners : names of
    :data:`LEARNER_REPLAYS` to run; learner_params : parameters as the live learner node takes
    them; motion_threshold : speed (rad/s or m/s) above which a sample moves when the cycles come
    from the motion (default: from the top speed and the measured noise).
    """

    settle_tolerance: float | None = None
    band: str = "5%"
    remove_mean: str = "auto"
    segmentation: str = "auto"
    positions: str = "auto"
    method: str = "fit"
    max_modes: int = 3
    band_hz: tuple[float, float] | None = None
    target: float = 0.05
    sigmas: float = 2.0
    identify_cycles: int = 20
    learners: tuple[str, ...] = ("list", "mrilc")
    learner_params: Mapping[str, object] = field(default_factory=dict)
    motion_threshold: float | None = None
    min_saving: float = 0.2
    max_damping: float = MAX_RINGING_DAMPING
    noise_sigmas: float = NOISE_FLOOR_SIGMAS
