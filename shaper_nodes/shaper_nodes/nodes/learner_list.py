"""The learner node's LIST mode: learn the shaper from each cycle's residual vibration (seed 003).

After each cycle of a repeated task it measures the residual vibration of the tip
accelerometer (M) and its phase against the unshaped vibration (phi), updates the 2-impulse
shaper (A1, T2) by the Learning Input Shaping Technique (:mod:`shaper_nodes.core.learning.list`)
and sends it to the shaper node with source "learner". Started as ``learner`` with ``mode:=list``
(the default; see :mod:`.learner` for what both modes share, and config/learner.yaml).

Interfaces (names are parameters)
---------------------------------
topics.imu (sensor_msgs/Imu, sensor QoS), topics.cycle_events, ``<shaper>/active_shaper``
    Inputs (the IMU reliable with topics.imu_reliable, acknowledged to a lockstep sim plant).
    A cycle is learned from only if it ran with the shaper the learner sent (or
    unshaped: the reference) from START to END; missing, stale, gappy, saturated or
    non-finite accelerometer data is reported and skipped, never learned from. A sample at or
    beyond the sensor's range (``sensor.max_abs_accel``) is saturated: the cycle is refused
    with the reason (log and ``/diagnostics``).
``<shaper>/set_shaper``
    Where the learned shaper goes (family "custom", source "learner").
~/hold (std_srvs/SetBool)
    true: stop exploring and apply the best parameters so far (held until false, or until M at
    them rises above ``list.rollback_factor`` times the best); false: learn again.
~/reports (shaper_msgs/CycleReport)
    One per finished cycle, published after the new shaper was accepted: M (residual_rms and
    metric "M"), phi, the parameters used and next, the action taken.
state_file
    ``{"version": 1, "structure", "saved_at", "learner"}``, checked entry by entry at start
    (:func:`~shaper_nodes.core.learning.list.learner_from_state`).

Start-up: with a saved state the learner sends its shaper at once; otherwise it sets the
identity shaper so that the next cycle runs unshaped and becomes the phase reference, and the
initial guess unless one is given (``initial.frequency_hz`` > 0).

Parameters: :data:`PARAMETERS` (``list.*``: the core's :class:`ListConfig`, ``list.*`` ranges
held against it by the tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import Imu

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_nodes.core.cycles import STAND_IN_SPAN
from shaper_nodes.core.learning.list import (
    ListConfig,
    ListError,
    ListLearner,
    ListParams,
    ListSession,
    learner_from_state,
    list_config,
)
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL
from shaper_nodes.core.shaping import Mode, ShaperError, none_shaper
from shaper_nodes.recordings.cdr_sensors import CdrError, decode_imu
from shaper_nodes.ros.conversions import shaper_to_msg
from shaper_nodes.ros.lockstep_reader import IMU_RELIABLE_DOC, STREAM_QOS, LockstepReader, subscribe_draining
from shaper_nodes.ros.parameters import Spec, declare, flat, param, table, topic
from shaper_nodes.ros.qos import IMU_QOS, LATCHED

from .learner_base import LearnerBase

_D = ListConfig()


def _check(key: str) -> Any:
    """The core's check of one ``list.*`` value."""
    return lambda v: list_config({key: v})


@dataclass(frozen=True)
class InitialParams:
    """initial.*: the initial guess."""

    frequency_hz: float = param(0.0, "Initial guess: mode frequency, Hz (0 = from the first, unshaped, cycle).",
                                (0.0, 1000.0), read_only=True)
    damping_ratio: float = param(0.0, "Initial guess: damping ratio.", (0.0, 0.95), read_only=True,
                                 check=lambda v: ListParams.from_mode(Mode.from_hz(10.0, v)))


@dataclass(frozen=True)
class ListGroup:
    """list.*: the learner's settings (the core's ListConfig, through list_config)."""

    structure: str = param(_D.structure, "Impulse structure: 'zv2' (the paper's 2 impulses) or 'zvd3' (the learned"
                           " pair convolved with itself).", read_only=True, check=_check("structure"))
    rule: str = param(_D.rule, "Update rule: 'components' (signed M sin/cos phi) or 'paper'.", read_only=True,
                      check=_check("rule"))
    highpass_hz: float = param(_D.highpass_hz, "High-pass cut-off removing drift before M and phi, Hz (0 = none).",
                               (0.0, 1000.0), read_only=True, check=_check("highpass_hz"))
    window_delay: float = param(0.0, "Residual window starts this long after MOTION_END, s (0 = the T2 upper"
                                " bound).", (0.0, 60.0), read_only=True, check=_check("window_delay"))
    a1_bounds: tuple[float, ...] = param(list(_D.a1_bounds), "Bounds of A1, [low, high].", read_only=True,
                                         check=_check("a1_bounds"))
    t2_bounds: tuple[float, ...] = param([0.0, 0.0], "Bounds of T2, s ([0, 0] = 0.5 to 2 times the initial T2).",
                                         read_only=True, check=_check("t2_bounds"))
    max_step_a1: float = param(_D.max_step_a1, "Largest change of A1 per cycle.", (1e-6, 1.0), read_only=True,
                               check=_check("max_step_a1"))
    max_step_t2: float = param(_D.max_step_t2, "Largest change of T2 per cycle, fraction of T2.", (1e-6, 10.0),
                               read_only=True, check=_check("max_step_t2"))
    phase_trials: int = param(_D.phase_trials, "Most cycles varying one parameter before switching to the other.",
                              (1, 100), read_only=True, check=_check("phase_trials"))
    switch_tol: float = param(_D.switch_tol, "Relative step below which a parameter counts as converged.",
                              (0.0, 0.99), read_only=True, check=_check("switch_tol"))
    rollback_factor: float = param(_D.rollback_factor, "Roll back to the best parameters when M exceeds this times"
                                   " the best M.", (1.0, 100.0), read_only=True, check=_check("rollback_factor"))
    patience: int = param(_D.patience, "Hold at the best parameters after this many trials in a row without a"
                          " better M (0 = never).", (0, 1000), read_only=True, check=_check("patience"))
    saturation: float = param(0.0, "Accelerometer full scale, m/s^2: a cycle reaching it is rejected (0 = no"
                              " limit).", (0.0, 1e6), read_only=True, check=_check("saturation"))
    min_samples: int = param(_D.min_samples, "Fewest accelerometer samples in the residual window.", (2, 10**7),
                             read_only=True, check=_check("min_samples"))
    per_move: bool = param(False, "Learn one LIST factor per move (start and goal of each cycle's START event),"
                           " kept by the scheduler named by 'shaper' and applied over its schedule to that move's"
                           " goals (nodes/learner_moves.py); false: one shaper for the task.", read_only=True)
    start: str = param("schedule", "With per_move: where a new move's factor starts: 'schedule' (the schedule's"
                       " lowest mode at its goal, asked of <shaper>/shaper_at) or 'identified' (the mode identified in"
                       " its reference cycle: LIST per move with no calibration, the scheduler's family 'none').",
                       choices=("schedule", "identified"), read_only=True)
    drift_status: str = param("identifier: drift", "With per_move: the /diagnostics status whose WARN (a drift"
                              " warning: the plant changed) restarts every move's learning from the current schedule,"
                              " once per warning episode (an OK ends it); '' = not watched.", read_only=True)


@dataclass(frozen=True)
class SensorParams:
    """sensor.*: the accelerometer's range."""

    max_abs_accel: float = param(MAX_ABS_ACCEL, "Accelerometer range, m/s^2: a cycle with a sample at or beyond"
                                 " it is refused as saturated (default 16 g).", (1e-3, 1e6), read_only=True,
                                 check=lambda v: ListSession(ListLearner(), max_abs_accel=v))


@dataclass(frozen=True)
class TopicParams:
    """topics.*: the inputs."""

    imu: str = topic("/tip_imu", "imu")
    cycle_events: str = topic("/cycle_events", "cycle_events")
    imu_reliable: bool = param(False, IMU_RELIABLE_DOC, read_only=True)


def subscribe_imu(node: Any, topics: TopicParams, on_sample: Callable[[float, tuple[float, float, float]], None],
                  group: Any) -> LockstepReader:
    """Subscribe ``node`` to the accelerometer (``topics.imu``; RELIABLE and deep with ``topics.imu_reliable``)
    and call ``on_sample(t, (ax, ay, az))`` with each sample. The node acknowledges the samples it took, so a
    lockstep sim plant that names it in ``lockstep.readers`` waits for it, from the moment its subscription
    matched the accelerometer's publisher (the LIST modes' one input glue). The samples are taken raw, every
    queued one per wake-up; bytes that are not an Imu are dropped with a throttled error (their gap counts as
    lost)."""
    name = topics.imu
    reader: LockstepReader | None = None
    log = node.get_logger()

    def on_imu(raw: bytes) -> None:
        try:
            t, a = decode_imu(raw)
        except CdrError as err:
            log.error(f"{name}: a message dropped: {err}", throttle_duration_sec=1.0)
            return
        on_sample(t, a)
        if reader is not None:
            reader.took(name, t)
    # poll=0: the samples stay in the caller's callback group (a polled subscription is taken on the node's
    # timer, in a group of its own), so they are handled in order with the cycle events of that group
    sub = subscribe_draining(node, Imu, name, on_imu, STREAM_QOS if topics.imu_reliable else IMU_QOS, poll=0,
                             callback_group=group)
    # announced to a lockstep plant once the accelerometer's publisher matched: no sample is lost before
    reader = LockstepReader(node, {name: None}, ready=lambda: sub.get_publisher_count() > 0)
    return reader


@dataclass(frozen=True)
class ListModeParams:
    """The LIST mode's parameters (see config/learner.yaml)."""

    initial: InitialParams = field(default_factory=InitialParams)
    list: ListGroup = field(default_factory=ListGroup)
    sensor: SensorParams = field(default_factory=SensorParams)
    topics: TopicParams = field(default_factory=TopicParams)


#: the LIST mode's parameters (derived from ListModeParams)
PARAMETERS: tuple[Spec, ...] = table(ListModeParams)


def _describe(params: ListParams | None) -> str:
    return "no shaping (reference cycle next)" if params is None else f"A1 {params.a1:.5f}, T2 {params.t2:.5f} s"


def declare_list(node: LearnerBase) -> tuple[Any, ListConfig]:
    """Declare the LIST mode's parameters on ``node``; returns them and the core's ListConfig of ``list.*``."""
    params = declare(node, ListModeParams)
    try:
        return params, list_config(flat(params.value.list))
    except ListError as err:
        raise ValueError(str(err)) from None


class ListMode:
    """The LIST adapter of the learner node (see the module docstring)."""

    def __init__(self, node: LearnerBase, declared: tuple[Any, ListConfig]) -> None:
        self.node = node
        self.params, self.config = declared
        v = self.params.value
        self.structure = self.config.structure
        learner = node.restore(learner_from_state, {"structure": self.structure})
        self.session = ListSession(learner or ListLearner(self.config, self._initial_params(v)), self.structure,
                                   float(node.params.value.stale_after), node.max_cycle_duration,
                                   float(v.sensor.max_abs_accel), STAND_IN_SPAN)
        self.events_topic = v.topics.cycle_events
        self.imu_topic = v.topics.imu
        self.stands_in = True
        inputs = MutuallyExclusiveCallbackGroup()  # taken while an END's update awaits the shaper node
        subscribe_imu(node, v.topics, lambda t, a: node.notice(self.session.on_imu(t, a)), inputs)
        node.create_subscription(ShaperMsg, f"{node.shaper.srv_name.rsplit('/', 1)[0]}/active_shaper",
                                 self._on_active, LATCHED, callback_group=inputs)

    @staticmethod
    def _initial_params(v: ListModeParams) -> ListParams | None:
        hz = float(v.initial.frequency_hz)
        if hz <= 0.0:
            return None
        try:
            return ListParams.from_mode(Mode.from_hz(hz, float(v.initial.damping_ratio)))
        except ShaperError as err:
            raise ValueError(f"invalid initial mode: {err}") from None

    def describe(self) -> str:
        learner = self.session.learner
        resumed = learner.reference is not None
        return (f"LIST ({self.structure}, rule {self.config.rule}) on {self.imu_topic};"
                f" {'resuming' if resumed else 'starting'} with {_describe(learner.params if resumed else None)}")

    def state(self) -> dict[str, Any]:
        return {"structure": self.structure, "learner": self.session.learner.to_dict()}

    def latest(self) -> float:
        return float(self.session.latest_imu)

    def ready(self) -> bool:
        return self.node.shaper.service_is_ready()

    # ----------------------------------------------------------------- the shaper node
    async def start(self) -> bool:
        learner = self.session.learner
        ok, why, answer = await self._send(learner.params if learner.reference is not None else None)
        if answer.response is not None and not ok:
            self.node.get_logger().error(f"the shaper node refused the initial shaper: {why}")
        return answer.response is not None

    async def _send(self, params: ListParams | None) -> tuple[bool, str, Any]:
        if params is None:
            msg = ShaperMsg(family="none")
        else:
            msg = shaper_to_msg(params.shaper(self.structure), self.node.shaper.source, 0,
                                self.node.get_clock().now().to_msg())
        self.session.sent(params)
        return await self.node.shaper.send(msg, exact=params is not None)  # the learned impulses exactly

    # ----------------------------------------------------------------- inputs
    def _on_active(self, msg: ShaperMsg) -> None:
        self.session.on_shaper(msg.amplitudes, msg.times, msg.source, msg.revision)

    async def hold(self, on: bool) -> tuple[bool, str]:
        learner = self.session.learner
        if not on:
            learner.resume()
            return True, "learning resumed"
        params = learner.hold()
        ok, why = True, ""
        if params is not None:
            ok, why, _ = await self._send(params)
        return ok, f"holding at {_describe(params)}" + ("" if ok else f"; shaper node refused: {why}")

    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        result = self.session.on_event(msg.event, msg.cycle, stamp, msg.start_positions, msg.goal_positions,
                                       stood_in)
        if result is None:
            return None
        window = (result.start, result.end)
        update = result.update
        if update is None or update.action == "rejected" or update.next is None:
            return self.node.skipped(msg, window, result.skipped or (update.reason if update else ""), result.refusal)
        applied, why = True, ""
        if update.next != update.used:
            applied, why, _ = await self._send(update.next)
        self.node.save()
        used = update.used or ListParams(math.nan, math.nan)
        names = ["M", "phi", "iteration", "a1_used", "t2_used", "a1_next", "t2_next", "applied",
                 f"action.{update.action}", f"parameter.{update.parameter}"]
        values_ = [update.m, update.phi, float(update.iteration), used.a1, used.t2, update.next.a1, update.next.t2,
                   1.0 if applied else 0.0, 1.0, 1.0]
        report = self.node.report(msg, window, names, values_, residual=update.m)
        report.shaper_used = self._shaper_msg(update.used)
        report.shaper_next = self._shaper_msg(update.next)
        text = (f"cycle {msg.cycle}: M {update.m:.4g}, phi {math.degrees(update.phi):.1f} deg, {update.action}"
            f" ({update.parameter}): {_describe(update.used)} -> {_describe(update.next)}"
            + ("" if applied else f"; shaper node refused: {why}"))
        # one call site per severity: rclpy refuses a call site whose severity changes between calls
        if applied:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().error(text)
        return report

    def _shaper_msg(self, params: ListParams | None) -> ShaperMsg:
        shaper = none_shaper() if params is None else params.shaper(self.structure)
        return shaper_to_msg(shaper, self.node.shaper.source, 0)
