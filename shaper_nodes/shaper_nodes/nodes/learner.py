"""The learner node: after each cycle of a repeated task, learn from the residual vibration.

``mode`` chooses the scheme, each a thin adapter over its ROS-free core:

list (default, :mod:`.learner_list`)
    The Learning Input Shaping Technique of seed 003: a two-impulse shaper tuned from the tip
    accelerometer's residual vibration, sent to the shaper node with source "learner"
    (config/learner.yaml).
mrilc (:mod:`.learner_mrilc`)
    Model-Reference Iterative Learning Control of seed 000: a feedforward profile learned so that
    the loop matches a reference model, installed at the injection point; the shaper is designed
    on the reference model (config/mrilc.yaml).

What both share lives here, once:

- the cycle events (``topics.cycle_events``): at a cycle's END the node waits up to ``end_wait``
  s for the samples stamped up to it (they come on other topics and may still be on their way),
  then hands the cycle to the adapter;
- ``~/reports`` (shaper_msgs/CycleReport): one per finished cycle, after the update was sent; a
  skipped cycle has the metric "skipped" = 1 and the reason in the log (a cycle too long, with
  saturated or implausible samples also on ``/diagnostics``, throttled per kind);
- ``~/hold`` (std_srvs/SetBool): true stops learning and applies the best so far, false learns
  again;
- ``state_file``: the learner's whole state, saved atomically after every update and reloaded at
  start, checked fully first (size, JSON, nesting depth, then every entry by the mode's core); a
  file that cannot be loaded is reported (log, and ``/diagnostics`` as ``learner: state_file``,
  published again with the start-up request), moved aside to ``<file>.corrupt`` if it can be
  (in a read-only folder it stays, and is refused again at the next start) and ignored: the
  learner starts afresh, never fails to start (:func:`shaper_nodes.core.learning.state_file.load_state`);
- ``max_cycle_duration``: a cycle longer than this is refused, and its samples are dropped as soon
  as a sample stamped past the limit arrives (said once, on the log and ``/diagnostics``), so that
  memory stays bounded whatever the cycle events do;
- the shaper node's ``set_shaper`` (and the MRILC injection point) through clients whose waits
  are bounded by ``service_timeout``: a lost reply is reported on the log and ``/diagnostics``,
  and the start-up request is sent again until it is answered.

The work happens after a cycle's END, in this node, never on the shaper's real-time path.
Parameters: :data:`PARAMETERS` here, and the adapter's (``list.*`` or ``mrilc.*``).
"""

from __future__ import annotations

import pathlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from std_srvs.srv import SetBool

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_nodes.core.learning.samples import MAX_CYCLE_DURATION
from shaper_nodes.core.learning.state_file import load_state, write_atomic
from shaper_nodes.ros.conversions import time_to_sec
from shaper_nodes.ros.diagnostics import ERROR, WARN, Diagnostics
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import Spec, declare, param, table
from shaper_nodes.ros.shaper_client import ShaperClient, wait_for

SOURCE = "learner"
STATE_VERSION = 1
MODES = ("list", "mrilc")
T = TypeVar("T")

@dataclass(frozen=True)
class LearnerParams:
    """The parameters every mode has (the adapters add theirs)."""

    mode: str = param("list", "Learning mode: 'list' (Learning Input Shaping Technique, seed 003) or 'mrilc'"
                      " (Model-Reference Iterative Learning Control, seed 000).", choices=MODES, read_only=True)
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


#: the parameters every mode has (derived from LearnerParams)
PARAMETERS: tuple[Spec, ...] = table(LearnerParams)


class Mode(Protocol):
    """What a learning mode gives the node (see :mod:`.learner_list`, :mod:`.learner_mrilc`)."""

    #: the cycle events topic
    events_topic: str

    def describe(self) -> str:
        """One line for the start-up log."""

    def latest(self) -> float:
        """Stamp of the newest sample received, s (the END wait waits for it to reach END)."""

    def ready(self) -> bool:
        """Whether the services the start-up needs have appeared."""

    async def start(self) -> bool:
        """Send the start-up shaper (and profile); False if an answer did not come (send again)."""

    async def on_event(self, msg: CycleEvent, stamp: float) -> CycleReport | None:
        """A cycle event; at the end of a cycle, learn, send, and return the cycle's report."""

    async def hold(self, on: bool) -> tuple[bool, str]:
        """Hold at the best so far (``on``), or learn again; (success, message)."""

    def state(self) -> dict[str, Any] | None:
        """The learner's state document (what the state file holds besides version and time)."""


class LearnerNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

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
        mode = str(p.mode)
        if mode == "mrilc":
            from .learner_mrilc import MrilcMode

            self.mode: Mode = MrilcMode(self)
        else:
            from .learner_list import ListMode

            self.mode = ListMode(self)
        # a coroutine callback: rclpy runs it as a task (its typing knows only plain callbacks)
        self.create_subscription(CycleEvent, self.mode.events_topic, self._on_event, 100)  # type: ignore[arg-type]
        self.create_service(SetBool, "~/hold", self._on_hold, callback_group=MutuallyExclusiveCallbackGroup())
        # steady clock: with use_sim_time, ROS time stands still while the lockstep plant is idle
        self._startup = self.create_timer(0.2, self._start, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._waiting_logged = False
        self.get_logger().info(f"{self.mode.describe()}; shaper {self.shaper.srv_name}")

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
            write_atomic(self.state_path, {"version": STATE_VERSION, **doc, "saved_at": time.time()})
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
        the core names, such as "too_long" or "saturated", also on /diagnostics)."""
        text = f"cycle {msg.cycle} not learned from: {why}"
        if not (refusal and self.diagnostics.report(refusal, WARN, text)):  # logged there unless throttled
            self.get_logger().warning(text)
        return self.report(msg, window, ["skipped"], [1.0])

    def notice(self, text: str | None) -> None:
        """A notice of the core's sample bookkeeping (a cycle passing its duration limit), if any."""
        if text:
            self.diagnostics.report("too_long", WARN, text)

    # ----------------------------------------------------------------- callbacks
    async def _start(self) -> None:
        """Until the start-up request is answered: send it (the learner's shaper, or the identity)."""
        if not self.mode.ready():
            if not self._waiting_logged:
                self.get_logger().info(f"waiting for {self.shaper.srv_name}")
                self._waiting_logged = True
            return
        self._startup.cancel()
        if self.state_problem:  # again, now that the graph is up (the first report may have had no listener)
            self.diagnostics.publish("state_file", ERROR, self.state_problem, [("kind", "state_file")])
        if not await self.mode.start():
            self.get_logger().warning("start-up request unanswered; sending it again")
            self._startup.reset()

    async def _on_event(self, msg: CycleEvent) -> None:
        stamp = time_to_sec(msg.header.stamp)
        if msg.event == CycleEvent.END:  # the last samples of the cycle may still be on their way
            deadline = time.monotonic() + float(self.params.value.end_wait)
            while self.mode.latest() < stamp and time.monotonic() < deadline:
                await self.sleep(0.01)
        report = await self.mode.on_event(msg, stamp)
        if report is not None:
            self._report_pub.publish(report)

    async def _on_hold(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        resp.success, resp.message = await self.mode.hold(bool(req.data))
        self.save()
        self.get_logger().info(resp.message)
        return resp


def main(args: list[str] | None = None) -> int:
    from . import learner_list, learner_mrilc

    return run_node(LearnerNode, "learner", args, tables={
        "every mode": PARAMETERS, "mode list": learner_list.PARAMETERS, "mode mrilc": learner_mrilc.PARAMETERS},
        examples=(
        with_config("shaper_nodes", "learner", "learner.yaml"),
        with_config("shaper_nodes", "learner", "mrilc.yaml")))


if __name__ == "__main__":
    raise SystemExit(main())
