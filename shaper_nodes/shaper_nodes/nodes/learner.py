"""The learner node: after each cycle of a repeated task, learn from the residual vibration.

``mode`` chooses the scheme, each a thin adapter over its ROS-free core:

list (default, :mod:`.learner_list`)
    The Learning Input Shaping Technique of seed 003: a two-impulse shaper tuned from the tip
    accelerometer's residual vibration, sent to the shaper node with source "learner"
    (config/learner.yaml). With ``list.per_move`` (:mod:`.learner_moves`): one factor per move,
    each learned from its own cycles and kept by the scheduler over its schedule.
mrilc (:mod:`.learner_mrilc`)
    Model-Reference Iterative Learning Control of seed 000: a feedforward profile learned so that
    the loop matches a reference model, installed at the injection point; the shaper is designed
    on the reference model (config/mrilc.yaml).
mrilc_moves (:mod:`.learner_moves_mrilc`)
    MRILC per move on a robot arm: per move, a correction of the joints' commanded profile learned from
    the move's residual window of the tool accelerometer, added to that move's goals by the learner's
    own FollowJointTrajectory proxy between the shaper node and the controller.
speed_moves (:mod:`.learner_speed`)
    Learning to move faster, per move: a time-scaling factor per move, raised while the move's settled residual
    (tool accelerometer) stays within a tolerance and the joint limits hold, applied by the learner's own
    FollowJointTrajectory proxy in front of the shaper node's (scaling before shaping).

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

import time
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from std_srvs.srv import SetBool

from shaper_msgs.msg import CycleEvent
from shaper_nodes.ros.conversions import time_to_sec
from shaper_nodes.ros.cycle_events import EventStream, Handled
from shaper_nodes.ros.diagnostics import ERROR
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.qos import SERVICE_QOS

from .learner_base import MODES, PARAMETERS, SOURCE, STATE_VERSION, LearnerBase, LearnerParams, Mode

__all__ = ["MODES", "PARAMETERS", "SOURCE", "STATE_VERSION", "LearnerNode", "LearnerParams", "Mode", "main"]


class LearnerNode(LearnerBase):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        p = self.params.value
        mode = str(p.mode)
        if mode == "mrilc":
            from .learner_mrilc import MrilcMode

            self.mode = MrilcMode(self)
        elif mode == "mrilc_moves":
            from .learner_moves_mrilc import MrilcMovesMode

            self.mode = MrilcMovesMode(self)
        elif mode == "speed_moves":
            from .learner_speed import SpeedMovesMode

            self.mode = SpeedMovesMode(self)
        else:
            from .learner_list import ListMode, declare_list

            declared = declare_list(self)
            if declared[0].value.list.per_move:
                from .learner_moves import MovesMode

                self.mode = MovesMode(self, declared)
            else:
                self.mode = ListMode(self, declared)
        # a coroutine callback: rclpy runs it as a task (its typing knows only plain callbacks)
        self.events = EventStream()
        self.create_subscription(CycleEvent, self.mode.events_topic, self._on_event, 100)  # type: ignore[arg-type]
        self.create_service(SetBool, "~/hold", self._on_hold, callback_group=MutuallyExclusiveCallbackGroup(),
                            qos_profile=SERVICE_QOS)
        # steady clock: with use_sim_time, ROS time stands still while the lockstep plant is idle
        self._startup = self.create_timer(0.2, self._start, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._waiting_logged = False
        self.get_logger().info(f"{self.mode.describe()}; shaper {self.shaper.srv_name}")


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
        handled = self.events.handle(msg)  # a START this node missed stood in for by the event's start stamp
        for event in handled:  # which goals ran in which cycle (learner_base.LearnerBase.goals), whatever the mode
            self.goal_event(event.msg, event.stamp)
        if msg.event == CycleEvent.END:  # the last samples of the cycle may still be on their way
            deadline = time.monotonic() + float(self.params.value.end_wait)
            while self.mode.latest() < stamp and time.monotonic() < deadline:
                await self.sleep(0.01)
        # the START stood in for goes to the modes that check the window (the others say "END without its START")
        for event in handled if self.mode.stands_in else [Handled(msg, stamp)]:
            if event.stood_in:
                self.get_logger().warning(f"cycle {msg.cycle}: its START was missed; stood in for by the"
                                          f" {'END' if msg.event == CycleEvent.END else 'MOTION_END'}'s start"
                                          f" stamp, {event.stamp:.3f} s")
            report = await self.mode.on_event(event.msg, event.stamp, event.stood_in)
            if report is not None:
                self._report_pub.publish(report)

    async def _on_hold(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        resp.success, resp.message = await self.mode.hold(bool(req.data))
        self.save()
        self.get_logger().info(resp.message)
        return resp


def main(args: list[str] | None = None) -> int:
    from . import learner_list, learner_moves_mrilc, learner_mrilc, learner_speed_parameters

    return run_node(LearnerNode, "learner", args, tables={
        "every mode": PARAMETERS, "mode list": learner_list.PARAMETERS, "mode mrilc": learner_mrilc.PARAMETERS,
        "mode mrilc_moves": learner_moves_mrilc.PARAMETERS,
        "mode speed_moves": learner_speed_parameters.PARAMETERS},
        examples=(
        with_config("shaper_nodes", "learner", "learner.yaml"),
        with_config("shaper_nodes", "learner", "mrilc.yaml")))


if __name__ == "__main__":
    raise SystemExit(main())
