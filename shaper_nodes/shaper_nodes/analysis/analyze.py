"""The analysis of a recording: per cycle, over the bag, and what the learners would have done.

Per cycle (:class:`CycleRow`): the residual vibration, RMS and peak of the tip acceleration
magnitude from the time the positions have come to rest after the motion until the cycle's end
(:func:`shaper_nodes.core.cycles.evaluate_cycle`, the measure every component of the suite
uses), the settling time of the acceleration into a band, and the shaper that was active.

Over the bag: the spectrum of the residual windows (Welch, averaged over cycles); the modes,
identified in every cycle's residual window (:func:`~shaper_nodes.core.identification.identify`)
and combined across cycles (cycles in which no mode stands out of the noise, e.g. well shaped
ones, are left out with a note); the recommended shaper
(:func:`~shaper_nodes.core.identification.recommend_shaper`, on the modes that ring only: a mode
damped above ``Options.max_damping`` or at the accelerometer's noise floor is reported but not
designed on, and without a ringing mode the verdict is "no shaper needed") and its predicted residual
vibration: for a linear plant the residual of a cycle is the unshaped residual times the
percentage vibration V of the shaper at the mode, so the unshaped level U is estimated as the
median of RMS / V_active over the cycles whose active shaper lets V >= 0.2 through, and the
prediction is U V_recommended (at the identified mode and at the worst point of its uncertainty
box), on top of which comes the sensor noise.

Learner replays: those of :data:`~.replay.LEARNER_REPLAYS` that the options ask for
(:mod:`.replay`: LIST and MRILC fed the recording as the live nodes are fed).
"""

from __future__ import annotations

import numpy as np

from shaper_nodes.recordings import BagError

from .cycle_rows import (  # noqa: F401 (the names of the analysis, re-exported)
    BAND_SIGMAS,
    CHANGED_DURING,
    DEFAULT_SETTLE_TOLERANCE,
    OFFSET_LIMIT,
    SETTLE_SIGMAS,
    CycleRow,
    _active_shaper,
    _band,
    _cycle_issue,
    _cycles,
    _noise,
    _positions,
    _remove_mean,
    _segment,
    reached_rest,
)
from .options import Options
from .outcome import Analysis
from .replay import LEARNER_REPLAYS, LearnerReplay
from .segment import CycleSpan
from .streams import Recording
from .verdict import (  # noqa: F401 (the names of the analysis, re-exported)
    MIN_SPECTRUM_SAMPLES,
    MIN_V_FOR_LEVEL,
    _group_recommendation,
    _identify,
    _prediction,
    _recommend,
    _spectrum,
    _unshaped,
    main_group,
    plant_changes,
    shaper_of,
)


def analyze(rec: Recording, options: Options | None = None) -> Analysis:
    """Analyse an extracted recording (see the module docstring).

    Raises
    ------
    BagError
        No cycle could be found (no events and no motion), or bad options.
    """
    opt = options or Options()
    notes = list(rec.notes)
    spans, segmentation, seg_notes = _segment(rec, opt)
    notes += seg_notes
    if not spans:
        raise BagError(f"{rec.path}: no cycles found ({'; '.join(seg_notes) or 'no cycle events and no motion'})")
    acc = rec.accel
    remove_mean = _remove_mean(acc.values, opt.remove_mean)
    if remove_mean and opt.remove_mean == "auto":
        notes.append(f"the accelerometer has an offset of {np.linalg.norm(np.nanmedian(acc.values, axis=0)):.3g} m/s^2"
                     " (gravity, bias): each window's mean is removed")
    tolerance, accel_noise, noise_notes = _noise(rec, opt)
    notes += noise_notes
    rows, traces, windows = _cycles(rec, spans, opt, remove_mean, tolerance, accel_noise, notes)
    for i, r in enumerate(rows):
        if r.issue:
            notes.append(f"cycle {r.cycle} (#{i}): {r.issue}; left out of the modes and the prediction")
    spectrum = _spectrum(windows)
    groups, id_notes = _identify(windows, rows, opt, accel_noise)
    notes += id_notes
    main, main_note = main_group(groups, rows)
    if main_note:
        notes.append(main_note)
    modes = main.modes if main is not None else []
    if len(groups) > 1:
        for g in groups:
            g.recommendation = _group_recommendation(g.modes, opt, accel_noise)
    recommendation, level, predicted = _recommend(rows if main is None or len(groups) == 1
                                                  else [rows[i] for i in main.rows], modes, opt, notes, accel_noise)
    if main is not None:
        main.recommendation = recommendation
    replays = _replays(rec, spans, segmentation, opt, notes)
    out = Analysis(rec, opt, segmentation, rows, traces, spectrum, modes, recommendation, level, predicted,
                   replays, notes, remove_mean, groups, tolerance, accel_noise)
    out.headline = plant_changes(out, main)
    return out


def _replays(rec: Recording, spans: list[CycleSpan], segmentation: str, opt: Options, notes: list[str]
             ) -> dict[str, LearnerReplay]:
    """learner name -> its replay, for the learners asked for (unknown ones are noted)."""
    replays: dict[str, LearnerReplay] = {}
    for name in opt.learners:
        fn = LEARNER_REPLAYS.get(name)
        if fn is None:
            notes.append(f"learner replay {name!r}: not available (known: {sorted(LEARNER_REPLAYS)})")
            continue
        replays[name] = fn(rec, spans, segmentation, opt.learner_params)
    return replays
