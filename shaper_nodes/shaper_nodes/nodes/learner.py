"""The learner node (LIST mode): learn the shaper from each cycle's residual vibration (seed 003).

After each cycle of a repeated task it measures the residual vibration of the tip
accelerometer (M) and its phase against the unshaped vibration (phi), updates the 2-impulse
shaper (A1, T2) by the Learning Input Shaping Technique (:mod:`shaper_nodes.core.list_learning`)
and sends it to the shaper node with source "learner". The work happens after the cycle's
END, in this node, never on the shaper's real-time path.

Interfaces (names are parameters, see config/learner.yaml)
----------------------------------------------------------
topics.imu (sensor_msgs/Imu, sensor QoS), topics.cycle_events, ``<shaper>/active_shaper``
    Inputs. A cycle is learned from only if it ran with the shaper the learner sent (or
    unshaped: the reference) from START to END; missing, stale, gappy, saturated or
    non-finite accelerometer data is reported and skipped, never learned from.
``<shaper>/set_shaper``
    Where the learned shaper goes (family "custom", source "learner").
~/hold (std_srvs/SetBool)
    true: stop exploring and apply the best parameters so far (held until false, or until M at
    them rises above ``list.rollback_factor`` times the best); false: learn again.
~/reports (shaper_msgs/CycleReport)
    One per finished cycle, published after the new shaper was accepted: M (residual_rms and
    metric "M"), phi, the parameters used and next, the action taken; a skipped cycle has the
    metric "skipped" = 1 and the reason in the log.
state_file
    The learner's whole state, saved atomically (write, fsync, rename) after every update and
    reloaded at start; a corrupt file is reported, moved aside to ``<file>.corrupt`` and not
    loaded.

Start-up: with a saved state the learner sends its shaper at once; otherwise it sets the
identity shaper so that the next cycle runs unshaped and becomes the phase reference, and the
initial guess unless one is given (``initial.frequency_hz`` > 0).
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import Imu
from std_srvs.srv import SetBool

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper
from shaper_nodes.core.learning.list import (
    ListConfig,
    ListError,
    ListLearner,
    ListParams,
    ListSession,
    SessionResult,
    list_config,
)
from shaper_nodes.core.shaping import Mode, ShaperError, none_shaper
from shaper_nodes.ros.conversions import shaper_to_msg, time_to_sec
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import describe

from .learner_mrilc import MrilcMode, write_atomic

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
IMU_QOS = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.VOLATILE)
STATE_VERSION = 1
SOURCE = "learner"


def save_state(path: pathlib.Path, learner: ListLearner, structure: str) -> None:
    """Write the learner's state to ``path`` atomically: a crash leaves the old file or the new one."""
    write_atomic(path, {"version": STATE_VERSION, "structure": structure, "saved_at": time.time(),
                        "learner": learner.to_dict()})


def load_state(path: pathlib.Path, structure: str) -> ListLearner:
    """The learner saved in ``path``.

    Raises
    ------
    ListError
        The file is unreadable, not JSON, of another version or structure, or inconsistent.
    """
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ListError(f"cannot read learner state {path}: {err}") from None
    if not isinstance(doc, dict) or doc.get("version") != STATE_VERSION:
        raise ListError(f"learner state {path}: not a version-{STATE_VERSION} state file")
    if doc.get("structure") != structure:
        raise ListError(f"learner state {path}: saved for structure {doc.get('structure')!r}, not {structure!r}")
    return ListLearner.from_dict(doc.get("learner"))


class LearnerNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("learner", *args, **kwargs)
        d = self.declare_parameter
        d("mode", "list", describe("Learning mode: 'list' (Learning Input Shaping Technique, seed 003) or 'mrilc'"
                                   " (Model-Reference Iterative Learning Control, seed 000).", read_only=True))
        d("shaper", "/shaper", describe("Fully qualified name of the shaper node.", read_only=True))
        d("state_file", "", describe("Where the learner's state is saved and reloaded ('' = not saved).",
                                     read_only=True))
        d("initial.frequency_hz", 0.0, describe(
            "Initial guess: mode frequency, Hz (0 = from the first, unshaped, cycle).", 0.0, 1000.0, read_only=True))
        d("initial.damping_ratio", 0.0, describe("Initial guess: damping ratio.", 0.0, 0.95, read_only=True))
        d("stale_after", 0.1, describe(
            "A cycle whose last accelerometer sample is older than this at END is stale, s.", 0.0, 60.0,
            read_only=True))
        d("end_wait", 0.5, describe(
            "At a cycle's END, wait up to this long for accelerometer samples stamped up to END, s.", 0.0, 10.0))
        d("service_timeout", 5.0, describe("Time to wait for the shaper node's services, s.", 0.1, 600.0))
        mode = self.get_parameter("mode").value
        if mode not in ("list", "mrilc"):
            raise ValueError(f"parameter mode must be 'list' or 'mrilc', got {mode!r}")
        if mode == "mrilc":
            self.mrilc = MrilcMode(self)
            return
        self.mrilc = None
        defaults = ListConfig()
        d("list.structure", defaults.structure, describe("Impulse structure: 'zv2' (the paper's 2 impulses) or"
                                                         " 'zvd3' (the learned pair convolved with itself).",
                                                         read_only=True))
        d("list.rule", defaults.rule, describe("Update rule: 'components' (signed M sin/cos phi) or 'paper'.",
                                               read_only=True))
        d("list.highpass_hz", defaults.highpass_hz, describe(
            "High-pass cut-off removing drift before M and phi, Hz (0 = none).", 0.0, 1000.0, read_only=True))
        d("list.window_delay", defaults.window_delay if defaults.window_delay is not None else 0.0, describe(
            "Residual window starts this long after MOTION_END, s (0 = the T2 upper bound).", 0.0, 60.0,
            read_only=True))
        d("list.a1_bounds", list(defaults.a1_bounds), describe("Bounds of A1, [low, high].", read_only=True))
        d("list.t2_bounds", list(defaults.t2_bounds) if defaults.t2_bounds else [0.0, 0.0], describe(
            "Bounds of T2, s ([0, 0] = 0.5 to 2 times the initial T2).", read_only=True))
        d("list.max_step_a1", defaults.max_step_a1, describe("Largest change of A1 per cycle.", 0.0, 1.0,
                                                             read_only=True))
        d("list.max_step_t2", defaults.max_step_t2, describe(
            "Largest change of T2 per cycle, fraction of T2.", 0.0, 10.0, read_only=True))
        d("list.phase_trials", defaults.phase_trials, describe(
            "Most cycles varying one parameter before switching to the other.", 1, 100, integer=True,
            read_only=True))
        d("list.switch_tol", defaults.switch_tol, describe(
            "Relative step below which a parameter counts as converged.", 0.0, 1.0, read_only=True))
        d("list.rollback_factor", defaults.rollback_factor, describe(
            "Roll back to the best parameters when M exceeds this times the best M.", 1.0, 100.0, read_only=True))
        d("list.patience", defaults.patience, describe(
            "Hold at the best parameters after this many trials in a row without a better M (0 = never).",
            0, 1000, integer=True, read_only=True))
        d("list.saturation", defaults.saturation if math.isfinite(defaults.saturation) else 0.0, describe(
            "Accelerometer full scale, m/s^2: a cycle reaching it is rejected (0 = no limit).", 0.0, 1e6,
            read_only=True))
        d("list.min_samples", defaults.min_samples, describe(
            "Fewest accelerometer samples in the residual window.", 2, 10**7, integer=True, read_only=True))
        for key, default in {"imu": "/tip_imu", "cycle_events": "/cycle_events"}.items():
            d(f"topics.{key}", default, describe(f"Topic name ({key}).", read_only=True))

        p = lambda name: self.get_parameter(name).value  # noqa: E731
        self.config = self._config()
        self.structure = self.config.structure
        path = str(p("state_file"))
        self.state_path = pathlib.Path(path).expanduser() if path else None
        learner = self._restore() or ListLearner(self.config, self._initial_params())
        self.session = ListSession(learner, self.structure, float(p("stale_after")))
        self.results: list[SessionResult] = []

        shaper = str(p("shaper")).rstrip("/")
        self._sleep_group = MutuallyExclusiveCallbackGroup()  # (Node has its own _timers)
        inputs = MutuallyExclusiveCallbackGroup()  # taken while an END's update awaits the shaper node
        self.create_subscription(Imu, p("topics.imu"), self._on_imu, IMU_QOS, callback_group=inputs)
        self.create_subscription(ShaperMsg, f"{shaper}/active_shaper", self._on_active, LATCHED,
                                 callback_group=inputs)
        self.create_subscription(CycleEvent, p("topics.cycle_events"), self._on_event, 100)
        self._set_shaper = self.create_client(SetShaper, f"{shaper}/set_shaper",
                                              callback_group=MutuallyExclusiveCallbackGroup())
        self._report_pub = self.create_publisher(CycleReport, "~/reports", 10)
        self.create_service(SetBool, "~/hold", self._on_hold, callback_group=MutuallyExclusiveCallbackGroup())
        # steady clock: with use_sim_time, ROS time stands still while the lockstep plant is idle
        self._startup = self.create_timer(0.2, self._send_initial, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._waiting_logged = False
        self.get_logger().info(
            f"LIST ({self.structure}, rule {self.config.rule}) on {p('topics.imu')};"
            f" {'resuming ' + str(self.state_path) if learner.reference is not None else 'starting'}"
            f" with {self._describe(learner.params if learner.reference is not None else None)}; shaper {shaper}")

    # ----------------------------------------------------------------- configuration
    def _config(self) -> ListConfig:
        values = {name[len("list."):]: self.get_parameter(name).value
                  for name in self._parameters if name.startswith("list.")}
        try:
            return list_config(values)
        except ListError as err:
            raise ValueError(str(err)) from None

    def _initial_params(self) -> ListParams | None:
        hz = float(self.get_parameter("initial.frequency_hz").value)
        if hz <= 0.0:
            return None
        try:
            return ListParams.from_mode(Mode.from_hz(hz, float(self.get_parameter("initial.damping_ratio").value)))
        except ShaperError as err:
            raise ValueError(f"invalid initial mode: {err}") from None

    def _restore(self) -> ListLearner | None:
        if self.state_path is None or not self.state_path.exists():
            return None
        try:
            learner = load_state(self.state_path, self.structure)
        except ListError as err:
            aside = self.state_path.with_name(self.state_path.name + ".corrupt")
            os.replace(self.state_path, aside)
            self.get_logger().error(f"{err}; not loaded, moved to {aside}; starting afresh")
            return None
        self.get_logger().info(f"resumed from {self.state_path}")
        return learner

    @staticmethod
    def _describe(params: ListParams | None) -> str:
        return "no shaping (reference cycle next)" if params is None else f"A1 {params.a1:.5f}, T2 {params.t2:.5f} s"

    # ----------------------------------------------------------------- shaper node
    async def _send_initial(self) -> None:
        """Until the shaper node answers: send the learner's current shaper (or the identity)."""
        if not self._set_shaper.service_is_ready():
            if not self._waiting_logged:
                self.get_logger().info(f"waiting for {self._set_shaper.srv_name}")
                self._waiting_logged = True
            return
        self._startup.cancel()
        learner = self.session.learner
        ok, why = await self._send(learner.params if learner.reference is not None else None)
        if not ok:
            self.get_logger().error(f"the shaper node refused the initial shaper: {why}")

    async def _send(self, params: ListParams | None) -> tuple[bool, str]:
        timeout = float(self.get_parameter("service_timeout").value)
        if not self._set_shaper.wait_for_service(timeout_sec=timeout):
            return False, f"service {self._set_shaper.srv_name} not available within {timeout:g} s"
        if params is None:
            msg = ShaperMsg(family="none", source=SOURCE)
        else:
            msg = shaper_to_msg(params.shaper(self.structure), SOURCE, 0, self.get_clock().now().to_msg())
            msg.family = "custom"  # the learned impulses exactly, not a design
        req = SetShaper.Request(shaper=msg)
        self.session.sent(params)
        resp = await self._call(self._set_shaper, req, timeout)
        if resp is None:
            return False, f"{self._set_shaper.srv_name} did not answer within {timeout:g} s"
        return bool(resp.success), str(resp.message)

    # ----------------------------------------------------------------- inputs
    def _on_imu(self, msg: Imu) -> None:
        a = msg.linear_acceleration
        self.session.on_imu(time_to_sec(msg.header.stamp), (a.x, a.y, a.z))

    def _on_active(self, msg: ShaperMsg) -> None:
        self.session.on_shaper(msg.amplitudes, msg.times, msg.source, msg.revision)

    async def _call(self, client, request, timeout: float):
        """The reply to ``request``, or None when none came within ``timeout`` s of wall time (a
        reply sent before DDS has matched the reply reader is lost; it must not hang the learner)."""
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            await self._sleep(0.002)
        if not future.done():
            client.remove_pending_request(future)
            return None
        return future.result()

    async def _sleep(self, seconds: float) -> None:
        """Wait without blocking the executor (steady clock; other callback groups keep running)."""
        done = Future()
        # its own callback group: the awaiting callback holds the default one
        timer = self.create_timer(seconds, lambda: done.done() or done.set_result(True),
                                  callback_group=self._sleep_group, clock=Clock(clock_type=ClockType.STEADY_TIME))
        await done
        self.destroy_timer(timer)

    async def _on_hold(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        learner = self.session.learner
        if req.data:
            params = learner.hold()
            ok, why = await self._send(params) if params is not None else (True, "")
            resp.success = ok
            resp.message = f"holding at {self._describe(params)}" + ("" if ok else f"; shaper node refused: {why}")
        else:
            learner.resume()
            resp.success, resp.message = True, "learning resumed"
        self._save()
        self.get_logger().info(resp.message)
        return resp

    async def _on_event(self, msg: CycleEvent) -> None:
        stamp = time_to_sec(msg.header.stamp)
        if msg.event == CycleEvent.END:  # the last samples of the cycle may still be on their way
            deadline = time.monotonic() + float(self.get_parameter("end_wait").value)
            while self.session.latest_imu < stamp and time.monotonic() < deadline:
                await self._sleep(0.01)
        result = self.session.on_event(msg.event, msg.cycle, stamp,
                                       msg.start_positions, msg.goal_positions)
        if result is None:
            return
        self.results.append(result)
        report = CycleReport(source=SOURCE, cycle=int(msg.cycle), window_start=result.start,
                             window_end=result.end)
        report.header.stamp = msg.header.stamp
        update = result.update
        if update is None or update.action == "rejected":
            why = result.skipped or update.reason
            self.get_logger().warning(f"cycle {msg.cycle} not learned from: {why}")
            report.metric_names, report.metric_values = ["skipped"], [1.0]
            self._report_pub.publish(report)
            return
        applied, why = True, ""
        if update.next != update.used:
            applied, why = await self._send(update.next)
        self._save()
        report.residual_rms = float(update.m)
        report.shaper_used = self._shaper_msg(update.used)
        report.shaper_next = self._shaper_msg(update.next)
        names = ["M", "phi", "iteration", "a1_used", "t2_used", "a1_next", "t2_next", "applied",
                 f"action.{update.action}", f"parameter.{update.parameter}"]
        used = update.used or ListParams(float("nan"), float("nan"))
        values = [update.m, update.phi, float(update.iteration), used.a1, used.t2, update.next.a1, update.next.t2,
                  1.0 if applied else 0.0, 1.0, 1.0]
        report.metric_names, report.metric_values = names, [float(v) for v in values]
        self._report_pub.publish(report)
        log = self.get_logger().info if applied else self.get_logger().error
        log(f"cycle {msg.cycle}: M {update.m:.4g}, phi {math.degrees(update.phi):.1f} deg, {update.action}"
            f" ({update.parameter}): {self._describe(update.used)} -> {self._describe(update.next)}"
            + ("" if applied else f"; shaper node refused: {why}"))

    def _save(self) -> None:
        """Save the learner's state (if a state file is configured); a failure is logged, not fatal."""
        if self.state_path is None:
            return
        try:
            save_state(self.state_path, self.session.learner, self.structure)
        except OSError as err:
            self.get_logger().error(f"could not save the learner state to {self.state_path}: {err}")

    def _shaper_msg(self, params: ListParams | None) -> ShaperMsg:
        shaper = none_shaper() if params is None else params.shaper(self.structure)
        return shaper_to_msg(shaper, SOURCE, 0)


def main(args: list[str] | None = None) -> int:
    return run_node(LearnerNode, "learner", args)


if __name__ == "__main__":
    raise SystemExit(main())

