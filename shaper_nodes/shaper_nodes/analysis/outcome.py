"""What the bag analysis found: :class:`Analysis` (one recording's cycles, modes, recommendation and notes), apart
from :mod:`.analyze` so that :mod:`.verdict` takes it without importing the analysis."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shaper_nodes.core.identification import ModeFit, Recommendation, ringing_issue

from .cycle_rows import CycleRow
from .groups import ModeGroup
from .options import Options
from .replay import LearnerReplay
from .streams import Recording


@dataclass
class Analysis:
    recording: Recording
    options: Options
    segmentation: str
    cycles: list[CycleRow]
    traces: list[tuple[np.ndarray, np.ndarray]]  # per cycle: time from START (s), acceleration (N, 3)
    spectrum: tuple[np.ndarray, np.ndarray] | None  # Hz, (m/s^2)^2/Hz
    modes: list[ModeFit]
    recommendation: Recommendation | None
    unshaped_level: float
    predicted: dict
    replays: dict[str, LearnerReplay]
    notes: list[str]
    removed_mean: bool
    groups: list[ModeGroup] = field(default_factory=list)  # several when cycles see different modes
    settle_tolerance: float = float("nan")  # positions at rest within this (rad or m), as used
    accel_noise: float = float("nan")  # accelerometer noise per axis, m/s^2 (third differences' MAD)
    headline: list[str] = field(default_factory=list)  # what changed between groups of cycles, first in reports

    def ringing_issue(self, mode: ModeFit) -> str:
        """Why ``mode`` is not used for the shaper ("" if it is): it does not ring (damping ratio above
        ``options.max_damping``) or is at the noise floor (see :class:`Options`)."""
        return ringing_issue(mode, self.options.max_damping, self.accel_noise if math.isfinite(self.accel_noise)
                             else 0.0, self.options.noise_sigmas)

    @property
    def origin(self) -> float:
        """Whole second at or before the first accelerometer sample: reports give times from it, s."""
        return float(math.floor(self.recording.accel.t[0]))
