"""The learner's watch of the drift warning: one status on ``/diagnostics``, acted on once per warning episode.

The identifier's drift watch (:mod:`.identifier`) publishes the status ``identifier: drift`` on
``/diagnostics`` after every cycle it rates: WARN while the mode stays out of the active shaper's working band
(``watch.confirm`` cycles in a row and after), OK when it is back inside or the residual is at the noise
floor, ERROR when a sensor fault leaves it unable to rate. :class:`DriftWarnings` subscribes to
``/diagnostics`` and calls its ``on_warning`` coroutine at the first WARN of the status it watches (its name
is the learner's ``list.drift_status``, ``mrilc_moves.drift_status`` or ``speed.drift_status``), not at the
WARNs that repeat it; an OK ends the episode, so the next WARN is a new one. An ERROR (cannot rate) neither
starts nor ends an episode. The flag is saved in the learner's state file at both ends of an episode, so that
a restarted learner neither acts twice on one episode nor misses the next. Statuses of other names are
ignored; a status of the watched name with a level that is not a ``diagnostic_msgs/DiagnosticStatus`` level
(OK, WARN, ERROR, STALE) is ignored and reported (log and ``/diagnostics``, throttled, kind ``drift_status``).

The per-move modes (LIST per move, MRILC per move, speed per move) share the rest of the glue here: the state
file's flag (:data:`FLAG`, read back by :func:`saved_flag`) and the log line that names the moves relearned
(:meth:`DriftWarnings.relearn_line`).
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray

from shaper_nodes.core.learning.moves import MoveError
from shaper_nodes.ros.diagnostics import WARN, Diagnostics

from .learner_base import LearnerBase

#: diagnostic_msgs/DiagnosticStatus levels, as integers
LEVEL_OK, LEVEL_WARN, LEVEL_ERROR, LEVEL_STALE = 0, 1, 2, 3
#: the state file's key of the episode flag (:attr:`DriftWarnings.warned`)
FLAG = "drift_warned"
#: the cycles whose identified modes :class:`DriftWarnings` keeps (the latest)
KEPT_CYCLES = 64


def saved_flag(doc: dict[str, Any], error: type[Exception] = MoveError) -> bool:
    """The episode flag of a saved state document (False when it has none). Raises ``error`` naming a flag that
    is not true or false."""
    warned = doc.get(FLAG, False)
    if not isinstance(warned, bool):
        raise error(f"{FLAG} must be true or false, got {warned!r}")
    return warned


def level_of(value: Any) -> int | None:
    """A DiagnosticStatus ``level`` (a one-byte ``bytes`` as rclpy gives it, or an integer) as an integer; None
    if it is neither."""
    if isinstance(value, (bytes, bytearray)):
        return value[0] if len(value) == 1 else None
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    return None


class DriftWarnings:
    """Watch ``/diagnostics`` for the WARN of one status (module docstring).

    Parameters
    ----------
    node : LearnerBase
        The learner node (its ``/diagnostics`` reporter names bad statuses).
    status : str
        The watched status's full name (``"<node>: <name>"``); "" watches nothing.
    on_warning : coroutine function of str
        Called with the warning's message at the first WARN of an episode.
    warned : bool
        Whether an episode was under way when the learner last saved its state (a restarted learner does
        not act twice on one episode).
    """

    def __init__(self, node: LearnerBase, status: str, on_warning: Callable[[str], Awaitable[None]],
                 warned: bool = False) -> None:
        self.node = node
        self.status = status
        self.on_warning = on_warning
        #: a warning episode is under way (its first WARN was acted on; an OK ends it)
        self.warned = bool(warned)
        #: warning episodes acted on since start
        self.resets = 0
        #: the KeyValues of the WARN last acted on (key -> value; the mode the identifier measured)
        self.values: dict[str, str] = {}
        #: cycle -> the sharp modes (Hz) the watch identified in it (``modes_hz`` of its status, any level; the
        #: last :data:`KEPT_CYCLES` cycles; not saved: a restarted learner has none)
        self.modes: dict[int, list[float]] = {}
        #: cycle -> the move it ran (the learner's :meth:`ran`; the latest :data:`KEPT_CYCLES`, not saved)
        self.moved: dict[int, str] = {}
        self.diagnostics: Diagnostics = node.diagnostics
        if status:
            # the node's default group, as the cycle events': an episode's action never interleaves with a
            # cycle event's handling (a coroutine holds its group until it returns)
            node.create_subscription(DiagnosticArray, "/diagnostics", self._on_array, 100)  # type: ignore[arg-type]

    def relearn_line(self, keys: list[str], warning: str, what: str = "", origin: str = "from the current schedule"
                     ) -> str:
        """The one log line of a relearn: ``what`` (e.g. "the speed of ") of how many moves, from ``origin``, the
        moves' keys and the warning's message."""
        return (f"drift warning ({self.status}): relearning {what}{len(keys)} move{'' if len(keys) == 1 else 's'}"
                f" {origin}: {', '.join(keys) or 'none yet'} (the warning: {warning})")

    def _keep_modes(self, values: dict[str, str]) -> None:
        """Keep a status's ``modes_hz`` under its ``cycle`` (a status without them, or not numbers, is passed)."""
        try:
            cycle = int(values["cycle"])
            modes = [float(f) for f in values.get("modes_hz", "").split(",") if f.strip()]
        except (KeyError, ValueError):
            return
        modes = [f for f in modes if math.isfinite(f) and f > 0.0]
        if modes:
            self.modes[cycle] = modes
            for old in sorted(self.modes)[:-KEPT_CYCLES]:
                del self.modes[old]

    def ran(self, cycle: int, key: str) -> None:
        """A cycle's START named the move ``key`` (the latest :data:`KEPT_CYCLES` are kept)."""
        self.moved[cycle] = key
        for old in sorted(self.moved)[:-KEPT_CYCLES]:
            del self.moved[old]

    def drifted_mode(self, key: str, schedule_hz: float, band: float) -> float | None:
        """In a warning episode: the lowest mode (Hz) the watch identified in the move's latest cycle it has modes
        for, when that is further than ``band`` (a fraction) from the schedule's ``schedule_hz`` there (the plant
        changed at the move's goal); otherwise None (outside an episode, no modes, or within the band)."""
        if not self.warned:
            return None
        cycles = sorted((c for c, k in self.moved.items() if k == key and c in self.modes), reverse=True)
        if not cycles:
            return None
        hz = min(self.modes[cycles[0]])
        return None if abs(hz - schedule_hz) <= band * schedule_hz else hz

    async def _on_array(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name != self.status:
                continue
            level = level_of(status.level)
            self._keep_modes({str(kv.key): str(kv.value) for kv in status.values})
            if level == LEVEL_WARN:
                if not self.warned:
                    self.warned = True
                    self.values = {str(kv.key): str(kv.value) for kv in status.values}
                    self.resets += 1
                    await self.on_warning(str(status.message))
            elif level == LEVEL_OK:
                if self.warned:
                    self.warned = False
                    self.node.get_logger().info(f"'{self.status}' is OK again: the drift warning episode is over")
                    self.node.save()  # (a restarted learner acts on the next WARN)
            elif level not in (LEVEL_ERROR, LEVEL_STALE):
                self.diagnostics.report("drift_status", WARN,
                                        f"'{self.status}' with level {status.level!r}, not a DiagnosticStatus level"
                                        " (0 OK, 1 WARN, 2 ERROR, 3 STALE): ignored")
