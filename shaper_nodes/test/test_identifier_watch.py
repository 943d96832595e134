"""The identifier's drift watch names the shaper it rated: the active shaper, or with ``watch.scheduler`` the shaper
the scheduler gave the cycle's move (nodes/identifier_watch.py over the core's check, core/identification/drift.py).
The rating itself over DDS: tests/test_identifier_node.py."""

from __future__ import annotations

import math
from types import SimpleNamespace

from shaper_nodes.core.identification import ModeFit
from shaper_nodes.core.identification.drift import Baseline, DriftWatch, check_mode
from shaper_nodes.core.shaping.families import Mode, design
from shaper_nodes.nodes.identifier_watch import DriftRating


def outside_check():
    """A ZV designed at 4 Hz against a mode at 4.6 Hz: outside its 5 % band."""
    zv = design("zv", (Mode(2 * math.pi * 4.0, 0.02),))
    return check_mode(zv.amplitudes, zv.times, [4.0], ModeFit(2 * math.pi * 4.6, 0.02, 0.01, 0.001, 1.0, "fit"), 0.05)


def rating(move_shapers) -> DriftRating:
    node = SimpleNamespace(params=SimpleNamespace(value=SimpleNamespace(watch=SimpleNamespace(confirm=2))),
                           new_watch=lambda: DriftWatch(2, baseline=Baseline(2, 0.03)))
    return DriftRating(node, move_shapers)


def test_the_check_names_the_active_shaper_unless_told_which_shaper_it_rated():
    check = outside_check()
    assert "where the active shaper keeps V under 5 %" in check.describe()
    told = check.describe("the shaper the scheduler gave this move")
    assert "where the shaper the scheduler gave this move keeps V under 5 %" in told
    assert "active shaper" not in told


def test_the_warning_names_the_active_shaper_or_the_schedulers_shaper_for_the_move():
    active = rating(None)
    assert active.band() == "the active shaper's working band"
    assert active.rated() == "the active shaper"
    scheduled = rating(SimpleNamespace(client=SimpleNamespace(srv_name="/scheduler/shaper_at")))
    assert scheduled.band() == "the working band of the shaper the scheduler gave this move (/scheduler/shaper_at)"
    assert "active" not in scheduled.band() + outside_check().describe(scheduled.rated())


def test_a_mode_set_aside_says_since_when_it_is_there():
    """A mode outside the band present since the watch's first cycles: the status says whose first cycles (the
    move's with watch.scheduler, the active shaper's without) and "not drift"."""
    from shaper_nodes.core.identification.drift import rate_modes

    zv = design("zv", (Mode(2 * math.pi * 4.0, 0.02),))
    pole = ModeFit(2 * math.pi * 34.0, 0.55, 0.2, 0.01, 1.0, "fit")
    baseline = Baseline(1, 0.03)
    baseline.take([pole])
    rated = rate_modes(zv.amplitudes, zv.times, [4.0], [pole], 0.05, baseline)
    assert rated is not None and rated.aside is not None and rated.aside.baseline is pole and not rated.drift
    scheduled = rating(SimpleNamespace(client=SimpleNamespace(srv_name="/scheduler/shaper_at")))
    text = rated.describe(scheduled.rated(), scheduled.since())
    assert "mode 34 Hz" in text and "outside" in text
    assert text.endswith("present since the move's first cycles (34 Hz zeta 0.55 then): not drift"), text
    assert rating(None).since() == "the active shaper's first cycles"
