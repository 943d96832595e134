"""The scheduler node: the shaper follows the pose, by Takagi-Sugeno fuzzy interpolation (seed 004).

From /joint_states it takes the premise variables (the positions of the joints named in
``premises``), evaluates the rule base (operating points with their linear models and/or mode
parameters, in the parameter file, see config/scheduler.yaml and core/scheduling/fuzzy.py), and sends the
shaper designed on the interpolated mode(s) to the shaper node (``<shaper>/set_shaper``, source
"scheduler").

Rate limit (:mod:`shaper_nodes.core.scheduling.rate_limit`): a new shaper is sent only when a
mode moved by more than ``relative_change`` since the last one sent, at most once per
``min_interval`` s, never while the previous request is unanswered (a call unanswered for
``service_timeout`` s is given up, reported and sent again), and never faster than the shaper
node retires shapers bumplessly (the active shaper's duration divided by the number of shapers
it keeps alive, MAX_STAGES - 1).
Premises outside the rule base's range are clamped to it (never extrapolated) and reported
(a warning and a /diagnostics status). Joint states missing a premise joint or carrying
non-finite positions are refused and reported; without joint states for ``stale_timeout`` s
the scheduler stops updating and says so: for ``stale_timeout`` s of the node's clock *and* of the
steady clock since the last one arrived. With simulated time running faster than real time (a
lockstep plant at 20x) a live feed whose thread lags a few wall-clock milliseconds behind the plant
is a second of simulated time late, so the node's clock alone would call it stale after every goal;
a dead feed is still called stale once ``stale_timeout`` s passed on both clocks (on a robot, where
both are the same clock, nothing changes; while simulated time stands still, nothing is stale).

Cost at a fast joint state stream: /joint_states is taken on a lean node of its own
(``<name>_joint_states``, ros/side_node.py) served on a thread of its own by a take loop (``feed``
'take': one wait set built once, ros/take_loop.py; 'thread': rclpy's executor), so that each message
wakes a wait set of one subscription rather than all of this node's entities; the message gives
the latest premise values and their time, nothing more: it is taken serialized (``raw``) and only its
names, positions and stamp are read from the bytes (ros/raw_stream.py ``RawJointStates``; bytes that
are not a JointState are refused as ``malformed``), no message object is built. The subscription has no middleware event
handlers (rclpy's defaults, for an incompatible QoS or type, add two waitables to every wait: about a
tenth of the feed's CPU): instead, once a second, the node looks for joint-state publishers on the
graph of which none has matched for UNMATCHED_WARN s, and reports them (a WARN naming the topic).
The rule base is evaluated on the
``period`` timer, and only when the premises moved enough to matter: a change that moves no
membership grade by more than 1e-6 reuses the last evaluation (core/scheduling/scheduler.py,
GRADE_TOLERANCE, says why that is safe); ~/mode_estimate is still published at every period.
Until the first shaper is sent, each joint state wakes this node to try at once (also while
simulated time stands still).

Lockstep (``lockstep`` true, for a lockstep sim plant that names this node in its ``lockstep.readers`` with
``lockstep.lead`` one period): the rule base is evaluated on the poses' stamps instead of the timer, and each pose
is acknowledged to the plant once the shaper decided on it is answered, so that every retune takes effect at the
same step whatever the load (nodes/scheduler_lockstep.py). Off (the default), nothing of it runs.

Interfaces
----------
/joint_states (sensor_msgs/JointState)                in
~/mode_estimate (shaper_msgs/ModeEstimate, latched)   the interpolated mode(s), Hz and -
<shaper>/set_shaper (shaper_msgs/SetShaper)           out, source "scheduler" (or "learner")
~/set_shaper, ~/get_shaper, ~/active_shaper           the shaper node's interface, for the learner
~/shaper_at (shaper_msgs/ShaperAt)                    the shaper the schedule gives at any pose (or move)
~/set_move_shaper (shaper_msgs/SetMoveShaper)         the learner's correction of one move (nodes/scheduler_moves.py)
/diagnostics                                          clamping, refused or unmatched input, stale data

``~/shaper_at`` answers with the shaper this node would send at the request's pose (the family's
design on the interpolated modes, times the learner's correction of that region) and the
interpolated modes, without sending anything to the shaper node; the shaper node asks it for the
final pose of each whole trajectory (its parameter ``action.scheduler``), and names the move by
the trajectory's first point (``start``): a move the learner set a correction for
(``~/set_move_shaper``, per-move learning) gets the schedule convolved with the move's factor
instead of the region's correction (nodes/scheduler_moves.py). The premise joints are
picked from the pose by name; a pose without one of them, with non-finite values or with sizes
that differ is refused with the reason, and clamping is said in the message. The work is linear
in the pose and otherwise that of one scheduled design.

Policy with the learner (core/scheduling/scheduler.py): point the learner at this node (its parameter
``shaper: /scheduler``). The scheduler decides the mode; the learner's shapers are taken as a
correction of the scheduled ZV, kept per operating region (rule) and applied with every
scheduled shaper from then on. The learner's request itself is forwarded unchanged (source
"learner"), so the cycle it learns from runs with exactly its shaper. The identity shaper (the
learner's unshaped reference cycle) is forwarded too and holds the schedule until the learner
sends a shaper again. Other sources are refused here: they set the shaper node directly. A
learner's request the shaper node does not answer within ``service_timeout`` is answered to the
learner as refused, with the reason, and nothing is learned from it.

Parameters: :data:`PARAMETERS` (config/scheduler.yaml), and ``rules.<name>.*`` per rule.
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

from builtin_interfaces.msg import Time
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import JointState

from shaper_msgs.msg import ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper, ShaperAt
from shaper_nodes.core.checks import InputError
from shaper_nodes.core.scheduling import (
    FuzzyError,
    Interpolation,
    RateLimit,
    Scheduler,
    rule_base_from_dict,
)
from shaper_nodes.core.shaping import ShaperError
from shaper_nodes.ros.conversions import estimate_msg, shaper_to_msg
from shaper_nodes.ros.diagnostics import ERROR, WARN, Diagnostics
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import declare, declare_all, flat, read
from shaper_nodes.ros.qos import LATCHED, SERVICE_QOS
from shaper_nodes.ros.raw_stream import RawJointStates
from shaper_nodes.ros.shaper_client import PendingCall, ShaperClient
from shaper_nodes.ros.side_node import SideNode

from .scheduler_learner import LearnerInterface
from .scheduler_lockstep import MODES_QOS, LockstepPoses
from .scheduler_moves import MoveService
from .scheduler_parameters import PARAMETERS, RuleParams, SchedulerParams, rule_table

__all__ = ["PARAMETERS", "RuleParams", "SchedulerNode", "SchedulerParams", "main", "rule_table"]

SOURCE = "scheduler"
#: wall time between discovering the shaper's set_shaper service and the first request, s
DISCOVERY_SETTLE = 0.5
#: depth of the /joint_states subscription (reliable, volatile: rclpy's default profile)
JOINT_STATES_DEPTH = 50
#: refused joint states kept for the report (the count is exact; the diagnostics throttle anyway)
_REFUSALS_KEPT = 100
#: s that joint-state publishers may stay unmatched (discovery under way) before the scheduler warns
UNMATCHED_WARN = 3.0


class SchedulerNode(LearnerInterface, Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("scheduler", *args, **kwargs)
        self.params = declare(self, SchedulerParams)
        self.core = self._rule_base()
        self.premises = self.core.rule_base.premises
        p = self.params.value
        self.diagnostics = Diagnostics(self, lambda: float(self.params.value.error_throttle))
        shaper = p.shaper.rstrip("/")
        self.shaper = ShaperClient(self, shaper, SOURCE, lambda: float(self.params.value.service_timeout),
                                   self.diagnostics, get=True)
        self.create_subscription(ShaperMsg, f"{shaper}/active_shaper", self._on_active, LATCHED)
        self._active_pub = self.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)
        self._mode_pub = self.create_publisher(ModeEstimate, "~/mode_estimate", MODES_QOS if p.lockstep else LATCHED)
        self.create_service(SetShaper, "~/set_shaper", self._on_set_shaper, qos_profile=SERVICE_QOS)
        self.create_service(GetShaper, "~/get_shaper", self._on_get_shaper, qos_profile=SERVICE_QOS)
        self.create_service(ShaperAt, "~/shaper_at", self._on_shaper_at, qos_profile=SERVICE_QOS)
        self.moves = MoveService(self, float(p.move_tolerance))

        # latest (premise values, node clock and steady clock time they arrived s, their header stamp (sec,
        # nanosec)), set by the feed's thread
        self._pose: tuple[list[float], float, float, tuple[int, int]] | None = None
        self._poses = RawJointStates()
        self._interp: Interpolation | None = None  # the rule base at the latest evaluation
        self._estimate: ModeEstimate | None = None  # ... as published
        self._clamped = ""                         # ... what it clamped
        self._refusals: deque[str] = deque(maxlen=_REFUSALS_KEPT)  # from the feed's thread, reported here
        self.last_sent: Interpolation | None = None
        self._sent_at = -math.inf                  # node clock, s
        self._call: tuple[PendingCall, Interpolation] | None = None  # the scheduled shaper in flight
        self._forwarding = False                   # a learner's request in flight
        self._held_by_learner = False
        self._active: ShaperMsg | None = None
        self._answered: ShaperMsg | None = None  # the active shaper in the last accepted answer (lockstep)
        self.sent = 0
        self.refused = 0
        self._lockstep: LockstepPoses | None = None
        if p.lockstep:  # the poses' stamps drive the evaluations (nodes/scheduler_lockstep.py)
            self._lockstep = LockstepPoses(self, float(p.period), self._lockstep_tick, self._in_flight,
                                           lambda: self.last_sent is None)
        else:
            self.create_timer(float(p.period), self._tick)
        # wall clock (with use_sim_time the node clock stands still while a lockstep plant is idle):
        # notes when the shaper's set_shaper service appeared, see _service_settled
        self._ready_since: float | None = None
        self._watch = self.create_timer(0.05, self._watch_service, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._wake = self.create_guard_condition(self._on_wake)  # the feed's thread calls on this node
        self._feed = SideNode(self, "joint_states", lean=True, take=p.feed == "take")  # ros/take_loop.py
        # no middleware event handlers on the 500 Hz feed (rclpy's defaults add two waitables to every wait of
        # its executor, 13 % of its CPU under a profiler): an unmatched publisher is found by _watch_match instead
        self._feed_sub = self._feed.node.create_subscription(
            JointState, self.resolve_topic_name(p.joint_states), self._on_joint_states,
            JOINT_STATES_DEPTH, event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False), raw=True)
        self._unmatched_since: float | None = None
        self.create_timer(1.0, self._watch_match, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._feed.start()
        rb = self.core.rule_base
        self.get_logger().info(
            f"{len(rb.rules)} rules over {', '.join(self.premises)} (range "
            + ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in rb.ranges) + f"), interpolating {self.core.method},"
            f" {self.core.family} shapers to {shaper}")

    def _rule_base(self) -> Scheduler:
        """The rule base of the parameters (the table's and each rule's rules.<name>.*)."""
        p = self.params.value
        rules: dict[str, dict[str, Any]] = {}
        for name in p.rule_names:
            declare_all(self, rule_table(name))
            if f"rules.{name}.natural_frequency" in self._parameter_overrides:
                raise ValueError(f"rules.{name}.natural_frequency (rad/s) was renamed rules.{name}.frequency_hz (Hz):"
                                 " frequencies are in Hz on every interface (CHANGELOG); divide by 2 pi")
            rules[name] = flat(read(self, RuleParams, f"rules.{name}."))
        spec = {"premises": list(p.premises), "rules": rules, "range": list(p.range),
                "max_damping": float(p.max_damping)}
        try:
            return Scheduler(rule_base_from_dict(spec), p.interpolation, p.family)
        except (FuzzyError, ShaperError) as err:
            raise ValueError(f"invalid rule base: {err}") from None

    @property
    def _pending(self) -> bool:
        """A request of this node's is in flight."""
        return self._call is not None or self._forwarding

    # ----------------------------------------------------------------- helpers
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _rate_limit(self) -> RateLimit:
        p = self.params.value
        return RateLimit(float(p.relative_change), float(p.min_interval))

    def destroy_node(self) -> None:
        self._feed.close()
        super().destroy_node()

    # ----------------------------------------------------------------- inputs
    def _on_joint_states(self, raw: bytes) -> None:
        """On the feed's thread: the premise values and their time, one assignment; anything else is
        left to this node's executor (woken through ``_wake``). The message comes serialized, and only
        its names, positions and stamp are read (ros/raw_stream.py)."""
        try:
            names, positions, stamp = self._poses.decode(raw)
            z = self.core.premise_values(names, positions)
        except InputError as err:
            self.refused += 1  # (written by this thread only)
            self._refusals.append(str(err))
            self._wake.trigger()
            return
        if self._lockstep is not None:
            self._lockstep.put(z, stamp)
            self._wake.trigger()
            return
        self._pose = (z, self._now(), time.monotonic(), stamp)
        if self.last_sent is None:
            # the first shaper goes out as soon as a pose and the shaper node are there, also while
            # simulated time stands still (a lockstep plant at rest) and the period timer does not fire
            self._wake.trigger()

    def _on_wake(self) -> None:
        while self._refusals:
            self.diagnostics.report("input", ERROR, f"refused joint_states: {self._refusals.popleft()}")
        if self._lockstep is not None:
            self._lockstep.drain()
        elif self.last_sent is None:
            self._tick()

    def _on_active(self, msg: ShaperMsg) -> None:
        self._active = msg
        self._active_pub.publish(msg)

    # ----------------------------------------------------------------- scheduling
    def _tick(self, now: float | None = None) -> bool:
        """Evaluate the rule base at the latest pose and send its shaper if due. ``now``: the pose's time in
        lockstep (the rate limit counts on the poses' stamps, with the active shaper of the last answer); None: the
        node clock. False: a shaper is due but set_shaper is not settled yet."""
        self._poll_call()
        interp = self._evaluate()
        if interp is None or self._pending or self._held_by_learner:
            return True
        t = self._now() if now is None else now
        active = self._active if now is None else self._answered
        duration = active.times[-1] if active is not None and len(active.times) else 0.0
        if not self._rate_limit().due(self.last_sent.modes if self.last_sent else None, interp.modes,
                                      t - self._sent_at, duration):
            return True
        if not self._service_settled():
            return False
        self._send(interp, t)
        return True

    def _lockstep_tick(self, z: list[float], stamp: tuple[int, int], now: float) -> bool:
        self._pose = (z, now, time.monotonic(), stamp)
        return self._tick(now)

    def _in_flight(self) -> bool:
        """The scheduled shaper sent is still unanswered (its answer, if it came, taken)."""
        self._poll_call()
        return self._call is not None

    def _evaluate(self) -> Interpolation | None:
        """The rule base at the latest pose, published on ~/mode_estimate (None: no fresh pose).

        The last evaluation is reused while the premises stay within GRADE_TOLERANCE of its own."""
        pose = self._pose
        if pose is None:
            return None
        z, z_at, z_steady, (sec, nanosec) = pose
        stamp = Time(sec=sec, nanosec=nanosec)
        timeout = float(self.params.value.stale_timeout)
        if self._now() - z_at > timeout and time.monotonic() - z_steady > timeout:
            self.diagnostics.report("stale", WARN, f"no joint states for stale_timeout ({timeout:g} s of the node's"
                                    " clock and of the steady clock); not updating the shaper")
            return None
        interp, estimate = self._interp, self._estimate
        if interp is None or estimate is None or self.core.moved(z, interp):
            try:
                interp = self.core.evaluate(z)
            except FuzzyError as err:
                self.diagnostics.report("rule_base", ERROR, f"rule base: {err}")
                return None
            self._clamped = self.core.clamping(interp)
            estimate = _estimate(interp, stamp)
        else:
            estimate.header.stamp = stamp
        if self._clamped:
            self.diagnostics.report("clamped", WARN, self._clamped)
        self._mode_pub.publish(estimate)
        self._interp, self._estimate = interp, estimate
        return interp

    def _watch_service(self) -> None:
        if self.shaper.service_is_ready():
            if self._ready_since is None:
                self._ready_since = time.monotonic()
        else:
            self._ready_since = None
        if self._lockstep is not None:  # a shaper that waited for the service, or an answer that timed out
            self._lockstep.drain()

    def _watch_match(self) -> None:
        """Once a second: publishers of the joint states on the graph, none matched for UNMATCHED_WARN s
        (incompatible QoS or type): a WARN on the log and /diagnostics naming the topic."""
        sub = self._feed_sub
        graph = self._feed.node.count_publishers(sub.topic_name)
        if graph == 0 or sub.get_publisher_count() > 0:
            self._unmatched_since = None
            return
        now = time.monotonic()
        if self._unmatched_since is None:
            self._unmatched_since = now
        elif now - self._unmatched_since >= UNMATCHED_WARN:
            self.diagnostics.report("input", WARN, f"{sub.topic_name}: {graph} publisher(s) on the graph, none"
                                    f" matched for {UNMATCHED_WARN:g} s (incompatible QoS or message type)")

    def _service_settled(self) -> bool:
        """set_shaper has been discovered for DISCOVERY_SETTLE s: a request sent as soon as the
        service appears may be answered before DDS has matched the reply reader, and the reply is
        lost (then service_timeout sends it again, but late)."""
        return self._ready_since is not None and time.monotonic() - self._ready_since > DISCOVERY_SETTLE

    def _send(self, interp: Interpolation, now: float) -> None:
        try:
            shaper = self.core.shaper(interp)
        except ShaperError as err:
            self.diagnostics.report("design", ERROR, f"no shaper for the interpolated modes: {err}")
            return
        msg = shaper_to_msg(shaper, SOURCE, 0, self.get_clock().now().to_msg())
        if shaper.family != "custom":  # a family design: the shaper node designs it on the modes
            msg.amplitudes, msg.times = [], []
        self._sent_at = now
        call = self.shaper.set.start(self.shaper.request(msg))
        self._call = (call, interp)
        if self._lockstep is not None:  # the answer acknowledges its pose at once
            call.on_done(self._wake.trigger)

    def _poll_call(self) -> None:
        """The answer to the scheduled shaper in flight, if it came (or was given up: then it is
        reported, and the next tick sends again)."""
        if self._call is None:
            return
        answer = self._call[0].result()
        if answer is None:
            return
        interp, self._call = self._call[1], None
        if answer.response is not None and answer.response.success:
            self.last_sent = interp
            self._answered = answer.response.active
            self.sent += 1
        elif answer.response is not None:
            self.diagnostics.report("refused", WARN,
                                    f"shaper node refused the scheduled shaper: {answer.response.message}")
        elif not answer.timed_out:  # a timeout was reported by the client
            self.diagnostics.report("refused", WARN, f"scheduled shaper not sent: {answer.error}")

    # ----------------------------------------------------------------- the shaper at a given pose
    def _on_shaper_at(self, req: ShaperAt.Request, resp: ShaperAt.Response) -> ShaperAt.Response:
        """The shaper of the schedule at the request's pose (nothing is sent to the shaper node)."""
        try:
            interp, shaper = self.core.at(self.core.premise_values(req.pose.name, req.pose.position))
        except (InputError, FuzzyError, ShaperError) as err:
            resp.success, resp.message = False, f"no shaper for this pose: {err}"
            self.diagnostics.report("shaper_at", WARN, f"~/shaper_at refused: {err}")
            return resp
        shaper, move = self.moves.shaper(req, shaper, lambda: self.core.scheduled(interp))
        resp.shaper = shaper_to_msg(shaper, SOURCE, 0, self.get_clock().now().to_msg())
        resp.estimate = _estimate(interp, req.pose.header.stamp)
        modes = ", ".join(f"{m.hz:.4g} Hz zeta {m.zeta:.3g}" for m in interp.modes)
        region = self.core.rule_base.rules[interp.dominant].name or str(interp.dominant)
        clamped = self.core.clamping(interp)
        resp.success = True
        resp.message = (f"{shaper.family} ({len(shaper)} impulses, {shaper.duration * 1e3:.1f} ms) on {modes}"
                        f" at " + ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.premises, interp.z_in, strict=True))
                        + f" (region {region})" + (f"; {clamped}" if clamped else "") + move)
        return resp


def _estimate(interp: Interpolation, stamp: Any) -> ModeEstimate:
    """The interpolated mode(s) as a ModeEstimate (source "scheduler") stamped ``stamp``."""
    return estimate_msg(SOURCE, interp.modes, stamp=stamp)


def main(args: list[str] | None = None) -> int:
    return run_node(SchedulerNode, "scheduler", args, examples=(
        with_config("shaper_nodes", "scheduler", "scheduler.yaml"),))


if __name__ == "__main__":
    raise SystemExit(main())
