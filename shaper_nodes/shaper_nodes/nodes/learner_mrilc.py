"""The learner node's MRILC mode (seed 000): learn a feedforward profile over cycles.

Started as ``learner`` with ``mode:=mrilc`` (see learner_node.py and config/mrilc.yaml).
The parameters' names, defaults and ranges, and the construction of the model from them, are
in the ROS-free core (core.mrilc_learning.DEFAULTS, RANGES, model_from_params), which offline
replays (the bag analysis) share.

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
state_file: the profile and history, saved atomically after every cycle and reloaded at start.
"""

from __future__ import annotations

import json
import os
import pathlib
import time

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool

from shaper_msgs.msg import CycleEvent, CycleReport, FeedforwardProfile
from shaper_msgs.srv import SetFeedforward, SetShaper
from shaper_nodes.core.learning.mrilc import DEFAULTS, RANGES, MrilcLearner, MrilcSession, model_from_params
from shaper_nodes.core.learning.mrilc import model as M
from shaper_nodes.core.shaping import ShaperError, design
from shaper_nodes.ros.conversions import shaper_to_msg, time_to_sec
from shaper_nodes.ros.parameters import describe

STATE_VERSION = 1
SOURCE = "learner"


def write_atomic(path: pathlib.Path, doc: dict) -> None:
    """JSON to ``path`` atomically (write, fsync, rename, fsync the folder): a crash leaves the
    old file or the new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(doc, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


#: what each parameter means (names, defaults and ranges: core.mrilc_learning.DEFAULTS, RANGES)
DESCRIPTIONS = {
    "mrilc.rate": "Sample rate of the loop and of the profile, Hz.",
    "mrilc.controller.numerator": "Feedback controller C(s) numerator, highest power first (default seed 000 eq. 13).",
    "mrilc.controller.denominator": "Feedback controller C(s) denominator.",
    "mrilc.nominal.omega": "Nominal plant natural frequency, rad/s.",
    "mrilc.nominal.zeta": "Nominal plant damping ratio.",
    "mrilc.check.omegas": "Plant set of the convergence check: natural frequencies, rad/s (every pair with"
                          " check.zetas).",
    "mrilc.check.zetas": "Plant set: damping ratios.",
    "mrilc.check.min_frequency_hz": "Lowest frequency of the check (and of the robust design), Hz: about"
                                    " 1 / (cycle duration).",
    "mrilc.law": "Learning law: 'p' (gamma z), 'pd' (gamma z + lambda (z - 1)), 'robust'.",
    "mrilc.gamma": "P/PD learning gain.",
    "mrilc.lambda": "PD derivative learning gain.",
    "mrilc.robust_gain": "Robust law: fraction of the minimax L applied.",
    "mrilc.q_cutoff_hz": "Q filter cut-off (zero-phase Butterworth), Hz (0 = Q = 1).",
    "mrilc.q_order": "Q filter order.",
    "mrilc.injection": "'effort' (added to the controller output) or 'command' (added to the setpoint after the"
                       " shaper).",
    "mrilc.injection_target": "Node offering ~/set_feedforward at the injection point.",
    "mrilc.shaper_family": "Shaper designed on the reference model's mode and sent to the shaper node ('' = leave"
                           " it).",
    "mrilc.learn": "Learn (true) or only measure and report with the profile held (false).",
    "mrilc.patience": "Divergence guard: iterations of growing RMS(e) before rollback.",
    "mrilc.noise_floor": "RMS(e) below which growth is not divergence (output units).",
    "joint_names": "Joints learned, in profile order ([''] = those of the first START).",
    "topics.joint_states": "Topic name (joint_states).",
    "topics.reference": "Topic name (reference).",
    "topics.cycle_events": "Topic name (cycle_events).",
}


def declare(node) -> None:
    """The MRILC parameters (mrilc.*, joint_names, topics.*), read-only, with the core's defaults."""
    for name, default in DEFAULTS.items():
        low, high, integer = RANGES.get(name, (None, None, False))
        node.declare_parameter(name, default, describe(DESCRIPTIONS[name], low, high, integer=integer,
                                                       read_only=True))


class MrilcMode:
    """Wires the MRILC session into the learner node (which it is given)."""

    def __init__(self, node) -> None:
        self.node = node
        declare(node)
        p = lambda name: node.get_parameter(name).value  # noqa: E731
        try:
            self.model, settings = model_from_params({name: p(name) for name in DEFAULTS})
        except M.MrilcError as err:
            raise ValueError(str(err)) from None
        law = self.model.law
        node.get_logger().info(f"MRILC: reference model mode {self.model.mode.omega:.4g} rad/s, zeta"
                               f" {self.model.mode.zeta:.4g}; law {law.law}: {self.model.convergence.describe()}")
        self.joint_names: list[str] = list(settings.joint_names)
        self.patience, self.noise_floor = settings.patience, settings.noise_floor
        path = str(p("state_file"))
        self.state_path = pathlib.Path(path).expanduser() if path else None
        self.session: MrilcSession | None = None
        self._restore()
        self.injection = str(p("mrilc.injection"))

        node._sleep_group = MutuallyExclusiveCallbackGroup()
        inputs = MutuallyExclusiveCallbackGroup()
        node.create_subscription(JointState, p("topics.joint_states"), self._on_joint_state, 1000,
                                 callback_group=inputs)
        node.create_subscription(JointState, p("topics.reference"), self._on_reference, 1000, callback_group=inputs)
        node.create_subscription(CycleEvent, p("topics.cycle_events"), self._on_event, 100)
        target = str(p("mrilc.injection_target")).rstrip("/")
        self._set_ff = node.create_client(SetFeedforward, f"{target}/set_feedforward",
                                          callback_group=MutuallyExclusiveCallbackGroup())
        shaper = str(p("shaper")).rstrip("/")
        self._set_shaper = node.create_client(SetShaper, f"{shaper}/set_shaper",
                                              callback_group=MutuallyExclusiveCallbackGroup())
        self._report_pub = node.create_publisher(CycleReport, "~/reports", 10)
        node.create_service(SetBool, "~/hold", self._on_hold, callback_group=MutuallyExclusiveCallbackGroup())
        self._family = str(p("mrilc.shaper_family"))
        self._startup = node.create_timer(0.2, self._send_initial, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.ready = False

    # ------------------------------------------------------------------ state
    def _new_session(self, joints: int, doc: dict | None = None) -> MrilcSession:
        if doc is None:
            learner = MrilcLearner(self.model, joints, self.patience, self.noise_floor)
            learner.holding = not bool(self.node.get_parameter("mrilc.learn").value)
        else:
            learner = MrilcLearner.from_dict(self.model, doc, self.patience, self.noise_floor)
        stale = float(self.node.get_parameter("stale_after").value)
        return MrilcSession(learner, stale)

    def _restore(self) -> None:
        if self.state_path is None or not self.state_path.exists():
            if self.joint_names:
                self.session = self._new_session(len(self.joint_names))
            return
        try:
            doc = json.loads(self.state_path.read_text(encoding="utf-8"))
            if not isinstance(doc, dict) or doc.get("version") != STATE_VERSION or doc.get("mode") != "mrilc":
                raise M.MrilcError("not a version-1 MRILC state file")
            if abs(float(doc["sample_period"]) - self.model.period) > 1e-12:
                raise M.MrilcError(f"saved for a sample period of {doc['sample_period']} s, not {self.model.period} s")
            names = list(doc["joint_names"])
            if self.joint_names and names != self.joint_names:
                raise M.MrilcError(f"saved for joints {names}, not {self.joint_names}")
            self.joint_names = names
            self.session = self._new_session(len(names), doc["learner"])
        except (OSError, ValueError, KeyError, TypeError) as err:
            aside = self.state_path.with_name(self.state_path.name + ".corrupt")
            os.replace(self.state_path, aside)
            self.node.get_logger().error(f"cannot load MRILC state {self.state_path}: {err}; moved to {aside};"
                                         " starting afresh")
            self.session = self._new_session(len(self.joint_names)) if self.joint_names else None
            return
        self.node.get_logger().info(f"resumed from {self.state_path} at iteration {self.session.learner.iteration}")

    def save(self) -> None:
        if self.state_path is None or self.session is None:
            return
        doc = {"version": STATE_VERSION, "mode": "mrilc", "saved_at": time.time(), "joint_names": self.joint_names,
               "sample_period": self.model.period, "injection": self.injection,
               "learner": self.session.learner.to_dict()}
        try:
            write_atomic(self.state_path, doc)
        except OSError as err:
            self.node.get_logger().error(f"could not save the learner state to {self.state_path}: {err}")

    # ------------------------------------------------------------------ outputs
    async def _send_initial(self) -> None:
        if not (self._set_ff.service_is_ready() and (not self._family or self._set_shaper.service_is_ready())):
            return
        self._startup.cancel()
        if self._family:
            try:
                shaper = design(self._family, [self.model.mode])
            except ShaperError as err:
                self.node.get_logger().error(f"cannot design {self._family} on the reference model: {err}")
                shaper = None
            if shaper is not None:
                msg = shaper_to_msg(shaper, SOURCE, 0, self.node.get_clock().now().to_msg())
                msg.family = "custom"  # the designed impulses exactly
                resp = await self.node._call(self._set_shaper, SetShaper.Request(shaper=msg),
                                             float(self.node.get_parameter("service_timeout").value))
                if resp is None or not resp.success:
                    why = "no answer" if resp is None else resp.message
                    self.node.get_logger().error(f"the shaper node refused the {self._family} shaper: {why}")
        ok, why = await self._install(self.session.learner.profile if self.session else np.zeros((0, 0)))
        if not ok:
            self.node.get_logger().error(f"the injection point refused the profile: {why}")
        self.ready = True

    async def _install(self, profile: np.ndarray) -> tuple[bool, str]:
        timeout = float(self.node.get_parameter("service_timeout").value)
        if not self._set_ff.wait_for_service(timeout_sec=timeout):
            return False, f"service {self._set_ff.srv_name} not available within {timeout:g} s"
        msg = FeedforwardProfile(source=SOURCE, injection=self.injection, joint_names=self.joint_names,
                                 sample_period=self.model.period)
        msg.iteration = self.session.learner.iteration if self.session else 1
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.data = np.asarray(profile, dtype=float).ravel().tolist()
        if self.session:
            self.session.profile_ready = False
        resp = await self.node._call(self._set_ff, SetFeedforward.Request(profile=msg), timeout)
        if resp is None:
            return False, f"{self._set_ff.srv_name} did not answer within {timeout:g} s"
        if self.session:
            self.session.profile_ready = bool(resp.success)
        return bool(resp.success), str(resp.message)

    # ------------------------------------------------------------------ inputs
    def _select(self, msg: JointState, field: str):
        values = getattr(msg, field)
        if len(values) != len(msg.name):
            return None
        index = {n: i for i, n in enumerate(msg.name)}
        try:
            return [values[index[n]] for n in self.joint_names]
        except KeyError:
            self.node.get_logger().error(f"joint states lack joints {sorted(set(self.joint_names) - set(index))}",
                                         throttle_duration_sec=5.0)
            return None

    def _on_joint_state(self, msg: JointState) -> None:
        if self.session is None:
            return
        pos = self._select(msg, "position")
        if pos is not None:
            self.session.on_joint_state(time_to_sec(msg.header.stamp), pos, self._select(msg, "effort"))

    def _on_reference(self, msg: JointState) -> None:
        if self.session is None:
            return
        pos = self._select(msg, "position")
        if pos is not None:
            self.session.on_reference(time_to_sec(msg.header.stamp), pos)

    async def _on_hold(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        if self.session is None:
            resp.success, resp.message = False, "no cycle seen yet"
            return resp
        learner = self.session.learner
        if req.data:
            ok, why = await self._install(learner.hold())
            resp.success, resp.message = ok, "holding at the best profile" + ("" if ok else f"; refused: {why}")
        else:
            learner.resume()
            resp.success, resp.message = True, "learning resumed"
        self.save()
        self.node.get_logger().info(resp.message)
        return resp

    async def _on_event(self, msg: CycleEvent) -> None:
        stamp = time_to_sec(msg.header.stamp)
        if self.session is None:
            if msg.event != CycleEvent.START:
                return
            self.joint_names = list(msg.joint_names)
            self.session = self._new_session(len(self.joint_names))
            self.session.profile_ready = False  # learn from the next cycle, once a profile is installed
            ok, why = await self._install(self.session.learner.profile)
            if not ok:
                self.node.get_logger().error(f"the injection point refused the profile: {why}")
            return
        if msg.event == CycleEvent.END:
            deadline = time.monotonic() + float(self.node.get_parameter("end_wait").value)
            while self.session.latest < stamp and time.monotonic() < deadline:
                await self.node._sleep(0.01)
        result = self.session.on_event(msg.event, msg.cycle, stamp)
        if result is None:
            return
        report = CycleReport(source=SOURCE, cycle=int(msg.cycle), window_start=result.start, window_end=result.end)
        report.header.stamp = msg.header.stamp
        update = result.update
        if update is None:
            self.node.get_logger().warning(f"cycle {msg.cycle} not learned from: {result.skipped}")
            report.metric_names, report.metric_values = ["skipped"], [1.0]
            self._report_pub.publish(report)
            return
        ok, why = await self._install(update.next_profile)
        self.save()
        report.residual_rms = float(update.rms_e)
        report.metric_names = ["iteration", "rms_e", "rms_u1", "rms_u2", "residual", "applied",
                               f"action.{update.action}"]
        report.metric_values = [float(update.iteration), update.rms_e, update.rms_u1, update.rms_u2, update.residual,
                                1.0 if ok else 0.0, 1.0]
        self._report_pub.publish(report)
        log = self.node.get_logger().info if ok else self.node.get_logger().error
        log(f"cycle {msg.cycle} (iteration {update.iteration}): RMS e {update.rms_e:.4g}, u1 {update.rms_u1:.4g},"
            f" u2 {update.rms_u2:.4g}, residual {update.residual:.4g}; {update.action}" + ("" if ok else f"; injection point refused: {why}"))
