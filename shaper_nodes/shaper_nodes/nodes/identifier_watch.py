"""The identifier's drift watch: each buffered cycle's mode rated against the shaper it ran with (the shaper node's
active shaper, or with ``watch.scheduler`` the shaper the scheduler gave the cycle's move, :mod:`.identifier_moves`),
and the status ``identifier: drift`` on /diagnostics (the identifier node's module docstring says when it warns).
The rating is the core's (:mod:`shaper_nodes.core.identification.drift`); this is its glue to the node.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_nodes.core.identification import IdentificationError, ModeFit, identify_records
from shaper_nodes.core.identification.drift import DriftWatch, Rating, rate_modes
from shaper_nodes.ros.conversions import msg_hz
from shaper_nodes.ros.diagnostics import OK, WARN

from .identifier_moves import MoveShapers


class DriftRating:
    """The drift watch of the identifier ``node`` (its parameters ``watch.*``, ``band_hz``, ``method``,
    ``max_modes``; its diagnostics): :meth:`on_active` follows the active shaper, :meth:`rate` rates one cycle.

    Parameters
    ----------
    node : IdentifierNode
        The identifier node (its ``params``, ``diagnostics`` and logger).
    move_shapers : MoveShapers or None
        With ``watch.scheduler``: the shaper each move ran with, and each move's own watch; None: the active shaper.
    """

    def __init__(self, node: Any, move_shapers: MoveShapers | None) -> None:
        self.node = node
        self.move_shapers = move_shapers
        self.watch: DriftWatch = node.new_watch()
        self.active: ShaperMsg | None = None
        self._warned = False

    def on_active(self, msg: ShaperMsg) -> None:
        if self.active is None or msg.revision != self.active.revision:
            self.watch.reset(baseline=True)  # the modes since this shaper came
        self.active = msg

    def rate(self, cycle: int, record: tuple[np.ndarray, np.ndarray]) -> None:
        """Rate this cycle's mode against the shaper it ran with (see the module docstring)."""
        active, watch = self.active, self.watch
        if self.move_shapers is not None:  # the move's shaper, and its own watch
            active, why, move_watch = self.move_shapers.shaper(cycle)
            if active is None or move_watch is None:
                self.node.get_logger().info(f"cycle {cycle}: drift watch: not rated ({why})")
                return
            watch = move_watch
        if active is None or len(active.amplitudes) < 2 or active.family == "none":
            return
        p = self.node.params.value
        lo, hi = (float(x) for x in p.band_hz)
        try:
            modes = identify_records([record], method=str(p.method), max_modes=int(p.max_modes),
                                     band_hz=(lo, hi) if hi > 0.0 else None)
        except IdentificationError as err:
            watch.baseline.take([])  # (a watched cycle: the baseline closes after its cycles, modes or none)
            self.quiet(cycle, watch, f"cycle {cycle}: no mode identified in the residual ({err}): the residual is"
                       " at the noise floor")
            return
        sharp = [m for m in modes if m.omega > 0 and m.omega_std <= float(p.watch.max_uncertainty) * m.omega]
        # every sharp mode, at any strength (the plant's, not only the rated); a fit at the noise floor is none
        if watch.baseline.take(sharp):
            self.node.get_logger().info(
                f"cycle {cycle}: drift watch: baseline {watch.baseline.taken}/{watch.baseline.cycles}:"
                f" {watch.baseline.describe()}")
        rating = self.worst(active, sharp, watch)
        if rating is None:
            found = ", ".join(f"{m.hz:.4g} Hz (+-{100 * m.omega_std / m.omega:.2g} %)" for m in modes if m.omega > 0)
            self.quiet(cycle, watch, f"cycle {cycle}: no mode identified sharply enough to rate ({found or 'none'};"
                       f" watch.max_uncertainty {100 * float(p.watch.max_uncertainty):.3g} %): the residual"
                       " is at the noise floor")
            return
        watch.update(rating)
        check = rating.check
        text = f"cycle {cycle}: {rating.describe(self.rated(), self.since())}"
        values = [("cycle", str(cycle)), ("mode_hz", f"{check.mode_hz:.6g}"), ("zeta", f"{check.zeta:.4g}"),
                  ("vibration", f"{check.vibration:.4g}"), ("tolerance", f"{check.tolerance:.4g}"),
                  ("band_low_hz", f"{check.band_hz[0]:.6g}" if check.band_hz else "none"),
                  ("band_high_hz", f"{check.band_hz[1]:.6g}" if check.band_hz else "none"),
                  ("outside_in_a_row", str(watch.outside_in_a_row)), ("shaper_revision", str(active.revision)),
                  ("not_drift", "no" if rating.aside is None else "baseline" if rating.aside.baseline is not None
                   else "above"),
                  ("set_aside", str(len(rating.set_aside))),
                  # every sharp mode of the cycle, Hz, strongest first (the learner's payload from the drift)
                  ("modes_hz", ",".join(f"{m.hz:.6g}" for m in sorted(sharp, key=lambda m: -m.amplitude)))]
        if watch.warning:
            text = (f"the mode has drifted out of {self.band()} ({watch.outside_in_a_row} cycles in a row): {text};"
                    " retune the shaper (~/identify with apply)")
        self.verdict(text, values)

    def rated(self) -> str:
        """The shaper the watch rates against, in words: the active shaper, or with watch.scheduler the shaper the
        scheduler gave the cycle's move."""
        return "the active shaper" if self.move_shapers is None else "the shaper the scheduler gave this move"

    def since(self) -> str:
        """Since when the watch's baseline was taken, in words (what a mode set aside says)."""
        return "the active shaper's first cycles" if self.move_shapers is None else "the move's first cycles"

    def band(self) -> str:
        """Whose working band the watch rates against, in words (what the warning says)."""
        if self.move_shapers is None:
            return "the active shaper's working band"
        return f"the working band of {self.rated()} ({self.move_shapers.client.srv_name})"

    def verdict(self, text: str, values: list[tuple[str, str]]) -> None:
        """The status ``drift``: WARN while the watch warns (with watch.scheduler: while any move's watch does)."""
        drifted = self.move_shapers.drifted() if self.move_shapers is not None else (
            ["the task"] if self.watch.warning else [])
        if drifted and self.move_shapers is not None:
            text = f"{len(drifted)} move(s) drifted out of their shaper's working band ({', '.join(drifted)}); {text}"
            values = [*values, ("drifted_moves", str(len(drifted)))]
        if drifted:
            if not self._warned:
                self.node.get_logger().warning(text)
            self._warned = True
            self.node.diagnostics.publish("drift", WARN, text, values)
        else:
            if self._warned:
                self.node.get_logger().info(f"the mode is back inside the working band: {text}")
            self._warned = False
            self.node.diagnostics.publish("drift", OK, text, values)

    def quiet(self, cycle: int, watch: DriftWatch, text: str) -> None:
        """A cycle with nothing to rate: the shaper works (see DriftWatch.quiet)."""
        watch.quiet()
        self.verdict(text, [("cycle", str(cycle)), ("outside_in_a_row", "0")])

    def worst(self, active: ShaperMsg, modes: list[ModeFit], watch: DriftWatch) -> Rating | None:
        """The core's rating of the sharp ``modes`` against ``active`` with ``watch``'s baseline: the modes nearest
        each design mode and the strongest (the one that rings most, which a payload may have moved below every
        design mode), the modes present since the baseline and those far above every design mode set aside
        (:func:`~shaper_nodes.core.identification.drift.rate_modes`)."""
        tol = float(self.node.params.value.watch.tolerance)
        design = [hz for hz in map(msg_hz, active.design_modes) if hz > 0]
        return rate_modes(active.amplitudes, active.times, design, modes, tol, watch.baseline, watch.max_shift)
