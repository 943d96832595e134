"""What the learner node's modes share, apart from the node that chooses the mode
(:mod:`.learner`), so that the modes (:mod:`.learner_list`, :mod:`.learner_mrilc`) type their host
against :class:`LearnerBase` and no module imports one that imports it back.

:class:`LearnerBase` holds the parameters every mode has (:class:`LearnerParams`), the shaper
client, the state file (restore, save), the cycle reports and the notices; :class:`Mode` is what a
mode gives the node.
"""

from __future__ import annotations

import pathlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.task import Future

from shaper_msgs.msg import CycleEvent, CycleReport, ShapedGoal
from shaper_nodes.core.learning.goal_shaping import GoalBook, GoalRecord
from shaper_nodes.core.learning.samples import MAX_CYCLE_DURATION
from shaper_nodes.core.learning.state_file import load_state, write_state
from shaper_nodes.core.stamps import stamp_to_sec
from shaper_nodes.ros.diagnostics import ERROR, WARN, Diagnostics
from shaper_nodes.ros.parameters import Spec, declare, param, table
from shaper_nodes.ros.qos import SHAPED_GOALS_QOS
from shaper_nodes.ros.shaper_client import ShaperClient, wait_for

#: refusal classes that are a fault of the sensor (reported as such: ERROR, status "sensor")
SENSOR_FAULTS = ("sensor", "saturated")

SOURCE = "learner"
STATE_VERSION = 1
MODES = ("list", "mrilc", "mrilc_moves", "speed_moves")
T = TypeVar("T")

@dataclass(frozen=True)
class LearnerParams:
    """The parameters every mode has (the adapters add theirs)."""

    mode: str = param("list", "Learning mode: 'list' (Learning Input Shaping Technique, seed 003; per move with"
                      " list.per_move), 'mrilc' (Model-Reference Iterative Learning Control, seed 000), 'mrilc_moves'"
                      " (MRILC per move: a joint profile correction per move, nodes/learner_moves_mrilc.py) or"
                      " 'speed_moves' (a time-scaling factor learned per move, nodes/learner_speed.py).",
                      choices=MODES, read_only=True)
    shaper: str = param("/shaper", "Fully qualified name of the shaper node.", read_only=True)
    state_file: str = param("", "Where the learner's state is saved and reloaded ('' = not saved).", read_only=True)
    max_cycle_duration: float = param(
        MAX_CYCLE_DURATION, "Longest cycle, s: a longer one is refused and its samples"
        " dropped at the limit (bounds the learner's memory).", (1.0, 86400.0), read_only=True)
    stale_after: float = param(0.1, "A cycle whose last sample is older than this at END is stale, s.", (0.0, 60.0),
                               read_only=True)
    end_wait: float = param(0.5, "At a cycle's END, wait up to this long for samples stamped up to END, s.",
                            (0.0, 10.0))
    service_timeout: float = param(
        5.0, "Time to wait for the shaper node's services (and the injection point's), and"
        " then for their answer, s.", (0.1, 600.0))
    shaped_goals: str = param(
        "/shaper/shaped_goals", "The shaper node's record of what each goal was shaped with (shaper_msgs/ShapedGoal):"
        " the per-move learners refuse a cycle whose goal was not shaped as they expect ('' = not watched).",
        read_only=True)


#: the parameters every mode has (derived from LearnerParams)
PARAMETERS: tuple[Spec, ...] = table(LearnerParams)


class Mode(Protocol):
    """What a learning mode gives the node (see :mod:`.learner_list`, :mod:`.learner_mrilc`)."""

    #: the cycle events topic
    events_topic: str
    #: whether a START the learner missed is stood in for by a later event's start stamp (ros/cycle_events.py):
    #: ``on_event`` then gets it with ``stood_in`` (a mode that cannot check it saw the window says "END without
    #: its START", as before)
    stands_in: bool

    def describe(self) -> str:
        """One line for the start-up log."""

    def latest(self) -> float:
        """Stamp of the newest sample received, s (the END wait waits for it to reach END)."""

    def ready(self) -> bool:
        """Whether the services the start-up needs have appeared."""

    async def start(self) -> bool:
        """Send the start-up shaper (and profile); False if an answer did not come (send again)."""

    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        """A cycle event; at the end of a cycle, learn, send, and return the cycle's report. ``stood_in``: a
        START the learner missed, made from a later event of its cycle."""

    async def hold(self, on: bool) -> tuple[bool, str]:
        """Hold at the best so far (``on``), or learn again; (success, message)."""

    def state(self) -> dict[str, Any] | None:
        """The learner's state document (what the state file holds besides version and time)."""


class LearnerBase(Node):
    """The learner node less the choice of its mode (:class:`.learner.LearnerNode`). Extra arguments go
    to ``Node``."""

    #: the learning mode (set by the node that chooses it)
    mode: Mode

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("learner", *args, **kwargs)
        self.params = declare(self, LearnerParams)
        p = self.params.value
        path = str(p.state_file)
        self.state_path = pathlib.Path(path).expanduser() if path else None
        self.state_problem = ""  # why the state file was not loaded ("" if it was, or there was none)
        self.max_cycle_duration = float(p.max_cycle_duration)
        self.diagnostics = Diagnostics(self)
        self.shaper = ShaperClient(self, str(p.shaper), SOURCE, self.service_timeout, self.diagnostics)
        # the END wait's sleeps (the waiting callback holds its own group; Node has its own _timers)
        self._sleep_group = MutuallyExclusiveCallbackGroup()
        self._report_pub = self.create_publisher(CycleReport, "~/reports", 10)
        #: each cycle's goals as the shaper node shaped them (``shaped_goals``; core/learning/goal_shaping.py),
        #: fed in the default callback group, where the cycle events are handled one at a time
        self.goals = GoalBook()
        if str(p.shaped_goals).strip():
            self.create_subscription(ShapedGoal, str(p.shaped_goals).strip(), self._on_shaped_goal, SHAPED_GOALS_QOS)

    def _on_shaped_goal(self, msg: ShapedGoal) -> None:
        self.goals.shaped(GoalRecord(int(msg.shaped_with), str(msg.detail), tuple(msg.joint_names),
                                     tuple(float(x) for x in msg.goal_positions), str(msg.shaper.source),
                                     int(msg.shaper.revision), stamp_to_sec(msg.header.stamp)))

    def goal_event(self, msg: CycleEvent, stamp: float) -> None:
        """A cycle event stamped ``stamp`` s as it is taken (before its handling waits for anything), a START stood
        in for included: for :attr:`goals`."""
        if msg.event == CycleEvent.START:
            self.goals.start(int(msg.cycle), list(msg.joint_names), list(msg.goal_positions), stamp)
        elif msg.event == CycleEvent.END:
            self.goals.end(int(msg.cycle))

    def service_timeout(self) -> float:
        return float(self.params.value.service_timeout)

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of wall time without blocking the executor."""
        await wait_for(self, Future(), seconds, self._sleep_group)

    # ----------------------------------------------------------------- state file
    def restore(self, build: Callable[[dict[str, Any]], T], expected: dict[str, Any] | None = None) -> T | None:
        """The state saved in ``state_file``, built by ``build`` from the document (which checks it
        and raises on anything wrong); None when there is none, or when it cannot be loaded (then
        it is reported and moved aside if it can be). Never raises."""
        loaded = load_state(self.state_path, STATE_VERSION, build, "learner state", expected)
        if loaded.problem:
            self.state_problem = loaded.problem
            self.diagnostics.report("state_file", ERROR, loaded.problem)
        elif loaded.state is not None:
            self.get_logger().info(f"resumed from {self.state_path}")
        return loaded.state

    def save(self) -> None:
        """Save the learner's state (if a state file is configured); a failure is logged, not fatal."""
        doc = self.mode.state() if self.state_path is not None else None
        if self.state_path is None or doc is None:
            return
        try:
            write_state(self.state_path, {"version": STATE_VERSION, **doc, "saved_at": time.time()})
        except OSError as err:
            self.get_logger().error(f"could not save the learner state to {self.state_path}: {err}")

    # ----------------------------------------------------------------- reports
    def report(self, msg: CycleEvent, window: tuple[float, float], names: Sequence[str] = (),
               values: Sequence[float] = (), residual: float = 0.0) -> CycleReport:
        """The report of the cycle that ``msg`` ended (window: the residual window, s)."""
        report = CycleReport(source=SOURCE, cycle=int(msg.cycle), window_start=float(window[0]),
                             window_end=float(window[1]), residual_rms=float(residual))
        report.header.stamp = msg.header.stamp
        report.metric_names, report.metric_values = list(names), [float(v) for v in values]
        return report

    def skipped(self, msg: CycleEvent, window: tuple[float, float], why: str, refusal: str = "") -> CycleReport:
        """The report of a cycle not learned from (logged with the reason; a ``refusal`` of a class
        the core names, such as "too_long" or "saturated", also on /diagnostics; a sensor's fault,
        "sensor" or "saturated", as an ERROR in the status ``<node>: sensor``)."""
        text = f"cycle {msg.cycle} not learned from: {why}"
        fault = refusal in SENSOR_FAULTS
        if not (refusal and self.diagnostics.report(refusal, ERROR if fault else WARN, text,
                                                    name="sensor" if fault else None)):  # logged unless throttled
            self.get_logger().warning(text)
        return self.report(msg, window, ["skipped"], [1.0])

    def unended(self, open_cycles: dict[int, Any], msg: CycleEvent, *also: dict[int, Any]) -> None:
        """The cycles of ``open_cycles`` (their START handled, popped at their END) other than ``msg``'s: their
        END never came (lost while this node was paused past the DDS lease or out of the graph, or the motion
        source stopped mid-cycle). Each is reported as not learned from (log and ``~/reports``) and forgotten,
        with its entries in ``also``; a START that replaced it dropped it silently (session 13's walk)."""
        for cycle in [c for c in open_cycles if c != int(msg.cycle)]:
            open_cycles.pop(cycle)
            for other in also:
                other.pop(cycle, None)
            lost = CycleEvent(header=msg.header, event=CycleEvent.END, cycle=cycle, task=msg.task)
            why = (f"its END never came (events lost, or this node paused or out of the graph); cycle {msg.cycle}"
                   f" {'began' if msg.event == CycleEvent.START else 'ended'} since")
            self._report_pub.publish(self.skipped(lost, (float("nan"), float("nan")), why))

    def notice(self, text: str | None) -> None:
        """A notice of the core's sample bookkeeping (a cycle passing its duration limit), if any."""
        if text:
            self.diagnostics.report("too_long", WARN, text)
