"""The learner node's MRILC mode (seed 000): learn a feedforward profile over cycles.

Started as ``learner`` with ``mode:=mrilc`` (see :mod:`.learner` for what both modes share, and
config/mrilc.yaml). The parameters' names, defaults, ranges and descriptions, and the
construction of the model from them, are in the ROS-free core
(:mod:`shaper_nodes.core.learning.mrilc`: DEFAULTS, RANGES, DESCRIPTIONS, model_from_params),
which offline replays (the bag analysis) share.

At start-up it builds the reference model G_m = C P_nom / (1 + C P_nom) from the configured
controller and nominal plant, runs the convergence check of seed 000 eq. (11) over the plant
set and refuses to start (naming the worst plant and frequency) if the learning law fails it,
sets the shaper node's shaper to a ``mrilc.shaper_family`` (ZVD) designed on G_m's lightly
damped mode (source "learner"), and installs its profile (zero, or the saved one).

After each cycle it takes the measured output y (``topics.joint_states`` positions, efforts for
u1 = u - u2) and the applied reference r_s (``topics.reference``, JointState positions stamped
at the start of the period they apply to) on the sample grid from START to END, computes
e = y_m - y with y_m = G_m r_s, updates u2 and installs it at the injection point
(``<mrilc.injection_target>/set_feedforward``, shaper_msgs/SetFeedforward) for the next cycle.

~/reports (shaper_msgs/CycleReport)
    One per cycle, after the profile was installed: metrics iteration, rms_e, rms_u1, rms_u2,
    applied, action.<learn|hold|rollback>; a skipped cycle has "skipped" = 1 and the reason in
    the log.
~/hold (std_srvs/SetBool)
    true: stop learning and install the best profile so far; false: learn again.
Divergence guard: when RMS(e) grows ``mrilc.patience`` iterations in a row (above
``mrilc.noise_floor``), learning stops and the best profile is installed (action "rollback").
state_file: ``{"version": 1, "mode": "mrilc", "saved_at", "joint_names", "sample_period",
"injection", "learner"}``, saved atomically after every cycle and reloaded at start, checked
entry by entry first (:func:`~shaper_nodes.core.learning.mrilc.learner_from_state`).
Bounded memory and implausible samples: see :class:`~shaper_nodes.core.learning.mrilc.MrilcSession`
(``max_cycle_duration``, ``sensor.max_abs_position``, ``sensor.max_abs_effort``).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from sensor_msgs.msg import JointState

from shaper_msgs.msg import CycleEvent, CycleReport, FeedforwardProfile
from shaper_msgs.srv import SetFeedforward
from shaper_nodes.core.learning.mrilc import (
    DEFAULTS,
    DESCRIPTIONS,
    RANGES,
    MrilcError,
    MrilcLearner,
    MrilcSession,
    check_parameter,
    learner_from_state,
    model_from_params,
)
from shaper_nodes.core.shaping import ShaperError, design
from shaper_nodes.recordings.cdr import JointStateDecoder, joint_state_efforts, little_endian
from shaper_nodes.ros.conversions import shaper_to_msg
from shaper_nodes.ros.lockstep_reader import subscribe_draining
from shaper_nodes.ros.parameters import Spec, declare_all, values
from shaper_nodes.ros.shaper_client import ServiceClient

from .learner_base import LearnerBase


def _check(name: str) -> Any:
    """The core's check of one value of parameter ``name``."""
    return lambda v: check_parameter(name, v)


#: the MRILC mode's parameters: the core's names, defaults and ranges (see config/mrilc.yaml)
PARAMETERS: tuple[Spec, ...] = tuple(
    Spec(name, default, DESCRIPTIONS[name], RANGES[name][:2] if name in RANGES else None, read_only=True,
         check=_check(name))
    for name, default in DEFAULTS.items())


class MrilcMode:
    """The MRILC adapter of the learner node (see the module docstring)."""

    def __init__(self, node: LearnerBase) -> None:
        self.node = node
        declare_all(node, PARAMETERS)
        try:  # the core validates the whole mapping (as offline replays pass it from YAML) into typed settings
            self.model, settings = model_from_params(values(node, PARAMETERS))
        except MrilcError as err:
            raise ValueError(str(err)) from None
        self.joint_names: list[str] = list(settings.joint_names)
        self.patience, self.noise_floor, self.learn = settings.patience, settings.noise_floor, settings.learn
        self.settings = settings
        self.injection = self.model.injection
        self.family = settings.shaper_family
        self.events_topic, self.stands_in = settings.topics["cycle_events"], False
        self.session: MrilcSession | None = node.restore(self._session_from, {"mode": "mrilc"})
        if self.session is None and self.joint_names:
            self.session = self._new_session(len(self.joint_names))
        # both streams taken serialized, every queued message per wake-up (poll 0: in this group, woken by the
        # messages): the plant publishes a block of samples at a time, and rclpy's executor per message and the
        # conversion to a JointState object were most of the learner's CPU in a run (docs/results/testing.md)
        inputs = MutuallyExclusiveCallbackGroup()
        self._decoders = {"joint_states": JointStateDecoder(), "reference": JointStateDecoder()}
        subscribe_draining(node, JointState, settings.topics["joint_states"], self._on_joint_state, 1000, poll=0,
                           callback_group=inputs)
        subscribe_draining(node, JointState, settings.topics["reference"], self._on_reference, 1000, poll=0,
                           callback_group=inputs)
        self.feedforward = ServiceClient(node, SetFeedforward, f"{settings.injection_target.rstrip('/')}"
                                         "/set_feedforward", node.service_timeout, node.diagnostics)

    def describe(self) -> str:
        m = self.model
        mode = "none lightly damped" if m.mode is None else f"{m.mode.omega:.4g} rad/s, zeta {m.mode.zeta:.4g}"
        return f"MRILC: reference model mode {mode}; law {m.law.law}: {m.convergence.describe()}"

    # ------------------------------------------------------------------ state
    def _new_session(self, joints: int, learner: MrilcLearner | None = None) -> MrilcSession:
        if learner is None:
            learner = MrilcLearner(self.model, joints, self.patience, self.noise_floor)
            learner.holding = not self.learn
        return MrilcSession(learner, float(self.node.params.value.stale_after), self.node.max_cycle_duration,
                            self.settings.max_abs_position, self.settings.max_abs_effort)

    def _session_from(self, doc: dict[str, Any]) -> MrilcSession:
        learner, names = learner_from_state(doc, self.model, self.joint_names, self.injection, self.patience,
                                            self.noise_floor)
        self.joint_names = names
        return self._new_session(len(names), learner)

    def state(self) -> dict[str, Any] | None:
        if self.session is None:
            return None
        return {"mode": "mrilc", "joint_names": self.joint_names, "sample_period": self.model.period,
                "injection": self.injection, "learner": self.session.learner.to_dict()}

    def latest(self) -> float:
        return float(self.session.latest) if self.session is not None else float("inf")

    # ------------------------------------------------------------------ outputs
    def ready(self) -> bool:
        return self.feedforward.service_is_ready() and (not self.family or self.node.shaper.service_is_ready())

    async def start(self) -> bool:
        answered = True
        if self.family:
            answered = await self._send_shaper()
        ok, why, answer = await self._install(self.session.learner.profile if self.session else np.zeros((0, 0)))
        if answer is not None and not ok:
            self.node.get_logger().error(f"the injection point refused the profile: {why}")
        return answered and answer is not None

    async def _send_shaper(self) -> bool:
        """The shaper designed on the reference model's mode, to the shaper node; whether it answered."""
        try:
            if self.model.mode is None:
                raise ShaperError("the reference model has no lightly damped mode")
            shaper = design(self.family, [self.model.mode])
        except ShaperError as err:
            self.node.get_logger().error(f"cannot design {self.family} on the reference model: {err}")
            return True
        msg = shaper_to_msg(shaper, self.node.shaper.source, 0, self.node.get_clock().now().to_msg())
        ok, why, answer = await self.node.shaper.send(msg, exact=True)  # the designed impulses exactly
        if answer.response is not None and not ok:
            self.node.get_logger().error(f"the shaper node refused the {self.family} shaper: {why}")
        return answer.response is not None

    async def _install(self, profile: np.ndarray) -> tuple[bool, str, Any]:
        """Install ``profile`` at the injection point: (accepted, why, the response or None)."""
        msg = FeedforwardProfile(source=self.node.shaper.source, injection=self.injection,
                                 joint_names=self.joint_names, sample_period=self.model.period)
        msg.iteration = self.session.learner.iteration if self.session else 1
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.data = np.asarray(profile, dtype=float).ravel().tolist()
        if self.session:
            self.session.profile_ready = False
        answer = await self.feedforward.call(SetFeedforward.Request(profile=msg))
        if answer.response is None:
            return False, answer.error, None
        if self.session:
            self.session.profile_ready = bool(answer.response.success)
        return bool(answer.response.success), str(answer.response.message), answer.response

    # ------------------------------------------------------------------ inputs
    def _decode(self, raw: bytes, stream: str, efforts: bool) -> tuple[float, list[float], list[float] | None] | None:
        """(stamp, positions, efforts or None) of a serialized JointState in the configured joint order; None (and
        a throttled error) for bytes that are not one, a message whose positions do not match its names, or one
        that lacks a configured joint. Efforts (only with ``efforts``) are None unless one per name."""
        decoder = self._decoders[stream]
        try:
            if not little_endian(raw):
                raise ValueError("not little-endian CDR")
            t, names, pos = decoder(raw)
            eff = joint_state_efforts(raw, decoder.positions_end) if efforts else ()
        except (ValueError, struct.error) as err:  # (UnicodeDecodeError is a ValueError)
            self.node.get_logger().error(f"{stream}: a message dropped: {err}", throttle_duration_sec=5.0)
            return None
        if len(pos) != len(names):
            return None
        index = {n: i for i, n in enumerate(names)}
        try:
            order = [index[n] for n in self.joint_names]
        except KeyError:
            self.node.get_logger().error(f"joint states lack joints {sorted(set(self.joint_names) - set(index))}",
                                         throttle_duration_sec=5.0)
            return None
        return t, [pos[i] for i in order], [eff[i] for i in order] if len(eff) == len(names) else None

    def _on_joint_state(self, raw: bytes) -> None:
        if self.session is None:
            return
        got = self._decode(raw, "joint_states", True)
        if got is not None:
            self.node.notice(self.session.on_joint_state(*got))

    def _on_reference(self, raw: bytes) -> None:
        if self.session is None:
            return
        got = self._decode(raw, "reference", False)
        if got is not None:
            self.node.notice(self.session.on_reference(got[0], got[1]))

    async def hold(self, on: bool) -> tuple[bool, str]:
        if self.session is None:
            return False, "no cycle seen yet"
        learner = self.session.learner
        if not on:
            learner.resume()
            return True, "learning resumed"
        ok, why, _ = await self._install(learner.hold())
        return ok, "holding at the best profile" + ("" if ok else f"; refused: {why}")

    async def on_event(self, msg: CycleEvent, stamp: float, stood_in: bool = False) -> CycleReport | None:
        if self.session is None:
            if msg.event == CycleEvent.START:
                await self._first_start(msg)
            return None
        result = self.session.on_event(msg.event, msg.cycle, stamp)
        if result is None:
            return None
        window = (result.start, result.end)
        update = result.update
        if update is None:
            return self.node.skipped(msg, window, result.skipped, result.refusal)
        ok, why, _ = await self._install(update.next_profile)
        self.node.save()
        names = ["iteration", "rms_e", "rms_u1", "rms_u2", "residual", "applied", f"action.{update.action}"]
        values_ = [float(update.iteration), update.rms_e, update.rms_u1, update.rms_u2, update.residual,
                   1.0 if ok else 0.0, 1.0]
        text = (f"cycle {msg.cycle} (iteration {update.iteration}): RMS e {update.rms_e:.4g}, u1 {update.rms_u1:.4g},"
            f" u2 {update.rms_u2:.4g}, residual {update.residual:.4g}; {update.action}"
            + ("" if ok else f"; injection point refused: {why}"))
        # one call site per severity: rclpy refuses a call site whose severity changes between calls
        if ok:
            self.node.get_logger().info(text)
        else:
            self.node.get_logger().error(text)
        return self.node.report(msg, window, names, values_, residual=update.rms_e)

    async def _first_start(self, msg: CycleEvent) -> None:
        """The joints of the first START (when none are configured): a session, and its profile installed;
        learning starts with the next cycle."""
        self.joint_names = list(msg.joint_names)
        self.session = self._new_session(len(self.joint_names))
        self.session.profile_ready = False
        ok, why, _ = await self._install(self.session.learner.profile)
        if not ok:
            self.node.get_logger().error(f"the injection point refused the profile: {why}")
