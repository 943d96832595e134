"""The identifier node: vibration modes from the last cycles' residual vibration, and a shaper.

It listens to the accelerometer, the joint states and the cycle events, keeps the last
``buffer_cycles`` finished cycles (the free decay after each move, measured as
:class:`~shaper_nodes.core.cycles.CycleMonitor` does everywhere in the suite), and on request
identifies the modes (:mod:`shaper_nodes.core.identification`), recommends a shaper by the rule
of :mod:`~shaper_nodes.core.identification.recommend` (the shortest that leaves no vibration at the
modes with its worst case over their uncertainty under a target, unless another within the target
is at least 20 % shorter; the rule and its figures end the service's message), and can send it to
the shaper node. The numerics run here, never on the shaper node's real-time path.

Interfaces (names are parameters, see config/identifier.yaml)
-------------------------------------------------------------
topics.imu (sensor_msgs/Imu, sensor QoS), topics.joint_states, topics.cycle_events
    Inputs. A cycle without accelerometer samples, with a gap in them or with non-finite
    samples is reported and not buffered (stale or missing sensor data is never identified from);
    so is a cycle with a sample at or beyond the sensor's range (``sensor.max_abs_accel``):
    saturated, counted (:attr:`IdentifierNode.saturated`) and reported on ``/diagnostics`` too.
~/identify (shaper_msgs/srv/Identify)
    Identify from the last N buffered cycles, recommend, and optionally apply the recommendation
    through ``<shaper>/set_shaper`` with source "identification" (a shaper node that does not
    answer within ``service_timeout`` is reported, and the recommendation is returned unapplied).
~/mode_estimate (shaper_msgs/ModeEstimate, latched)
    The last identified modes with their one-sigma uncertainties.
/diagnostics
    A set_shaper call the shaper node did not answer; a saturated cycle; the drift watch.

Drift watch (``watch.*``)
-------------------------
With ``watch.enabled``, every buffered cycle is identified on its own and its mode rated
against the shaper node's active shaper (``<shaper>/active_shaper``, latched): V of the shaper
at the mode, and the working band around the design mode where V stays under
``watch.tolerance`` (:mod:`shaper_nodes.core.identification.drift`). When ``watch.confirm``
cycles in a row find the mode outside the band, a WARN ``identifier: drift`` on /diagnostics
names the numbers (logged once, until the mode comes back); every check publishes the status
(OK inside the band), with the numbers as KeyValues too (``cycle``, ``mode_hz`` the rated mode, ``zeta``, ...,
and ``modes_hz``: every sharp mode of the cycle, strongest first, which the MRILC learner's payload from the
drift reads). A change of the active shaper starts the count again. The identity
shaper is not watched. With ``watch.scheduler`` (a shaper node shaping each goal through that
scheduler, whose active shaper does not change), each cycle is rated against the shaper its move
ran with, asked of the scheduler at its START (:mod:`.identifier_moves`), and the active shaper is
not followed (the scheduler's changes of it as the arm moves would restart the count at every move).
Rated: the identified mode nearest each design mode, and the strongest (a mode a payload moved far
below every design mode is nearer another one); the worst of them decides. Each move has its own count,
and the status is WARN while any move's watch warns. Drift is a change: each watch keeps a baseline, the
modes of its first ``watch.baseline_cycles`` watched cycles (a move's for the node's life; the active
shaper's from its latest change), and a mode outside the band that is the same as a baseline mode outside
the band (``watch.baseline_margin``; the rule in :mod:`shaper_nodes.core.identification.drift`) is set
aside: it does not count, and the status says so ("present since ...: not drift"). The position loop's
damped pole, outside every band from the first cycle on, is such a mode. So is a mode more than
``watch.max_shift`` above the shaper's highest design mode (farther than a payload moves a mode).

Parameters: :data:`PARAMETERS` (config/identifier.yaml).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from shaper_msgs.msg import CycleEvent, ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import Identify
from shaper_nodes.core.cycle_records import MAX_GAP_PERIODS, SaturatedRecord, SensorFault, check_record
from shaper_nodes.core.cycles import STAND_IN_SPAN, CycleMonitor, CycleResult
from shaper_nodes.core.identification import IdentificationError, identify_records, recommend_shaper
from shaper_nodes.core.identification.drift import Baseline, DriftWatch
from shaper_nodes.core.shaping import ShaperError, none_shaper
from shaper_nodes.recordings.cdr_sensors import CdrError, JointStateReader, decode_imu
from shaper_nodes.ros.conversions import estimate_msg, shaper_to_msg, time_to_sec
from shaper_nodes.ros.cycle_events import EventStream
from shaper_nodes.ros.diagnostics import ERROR, WARN, Diagnostics
from shaper_nodes.ros.lockstep_reader import STREAM_QOS, LockstepReader, subscribe_draining
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import declare
from shaper_nodes.ros.qos import IMU_QOS, LATCHED, SERVICE_QOS
from shaper_nodes.ros.shaper_client import ShaperClient

from .identifier_moves import MoveShapers
from .identifier_parameters import PARAMETERS, IdentifierParams, validate_method
from .identifier_watch import DriftRating

# the names the tests and the docs import from here (check_record and its faults live in the core)
__all__ = ["MAX_GAP_PERIODS", "PARAMETERS", "IdentifierNode", "IdentifierParams", "SaturatedRecord", "SensorFault",
           "check_record", "main"]

SOURCE = "identification"

class IdentifierNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("identifier", *args, **kwargs)
        self.params = declare(self, IdentifierParams)
        p = self.params.value
        validate_method(p.method)

        # the residual logged is the vibration's: the window's mean (gravity, an offset) removed (the fit has its own)
        self.monitor = CycleMonitor(float(p.settle_tolerance), remove_mean=True, keep_before=STAND_IN_SPAN)
        self.events = EventStream()
        self.cycles: deque[tuple[CycleResult, tuple[np.ndarray, np.ndarray]]] = deque(
            maxlen=int(p.buffer_cycles))
        self.skipped: list[str] = []
        self.saturated = 0  # accelerometer samples counted as saturated (in cycles refused for it)
        # a lockstep sim plant that names this node in lockstep.readers waits for it; gaps in the stamps are losses
        self._imu_topic, self._js_topic = p.topics.imu, p.topics.joint_states
        self.lockstep = LockstepReader(self, {self._imu_topic: None, self._js_topic: None})
        self._cycle_start = -math.inf
        # the per-step streams taken raw (serialized bytes, no message objects), read by checked decoders
        self._js_read = JointStateReader()
        # (every queued sample per wake-up: a plant running ahead costs one executor turn per batch)
        subscribe_draining(self, Imu, p.topics.imu, self._on_imu, STREAM_QOS if p.topics.imu_reliable else IMU_QOS)
        subscribe_draining(self, JointState, p.topics.joint_states, self._on_joints, STREAM_QOS)
        self.create_subscription(CycleEvent, p.topics.cycle_events, self._on_event, 100)
        self._estimate_pub = self.create_publisher(ModeEstimate, "~/mode_estimate", LATCHED)
        self.diagnostics = Diagnostics(self)
        self.shaper = ShaperClient(self, str(p.shaper), SOURCE, lambda: float(self.params.value.service_timeout),
                                   self.diagnostics)
        self.create_service(Identify, "~/identify", self._on_identify, qos_profile=SERVICE_QOS)
        self.move_shapers = MoveShapers(self, str(p.watch.scheduler), lambda: float(
            self.params.value.service_timeout), self.diagnostics, self.new_watch) \
            if p.watch.enabled and p.watch.scheduler else None
        self.drift = DriftRating(self, self.move_shapers)  # nodes/identifier_watch.py
        if bool(p.watch.enabled) and self.move_shapers is None:  # (with watch.scheduler: not the one rated)
            self.create_subscription(ShaperMsg, f"{str(p.shaper).rstrip('/')}/active_shaper",
                                     self.drift.on_active, LATCHED)
        self.get_logger().info(
            f"identifying from {p.topics.imu}, keeping {self.cycles.maxlen} cycles;"
            f" applies to {self.shaper.srv_name}")

    def new_watch(self) -> DriftWatch:
        """A drift watch with the node's ``watch.confirm`` and baseline (``watch.baseline_*``)."""
        w = self.params.value.watch
        return DriftWatch(int(w.confirm), baseline=Baseline(int(w.baseline_cycles), float(w.baseline_margin)),
                          max_shift=float(w.max_shift))

    @property
    def _active(self) -> ShaperMsg | None:
        """The active shaper the drift watch rates against (None before it came, and with watch.scheduler)."""
        return self.drift.active

    # ----------------------------------------------------------------- data
    def _on_imu(self, raw: bytes) -> None:
        try:
            t, accel = decode_imu(raw)
        except CdrError as err:
            return self._refused(self._imu_topic, err)
        self.monitor.add_accel(t, accel)
        self.lockstep.took(self._imu_topic, t)

    def _on_joints(self, raw: bytes) -> None:
        try:
            t, _, positions = self._js_read(raw)
        except CdrError as err:
            return self._refused(self._js_topic, err)
        if positions:
            self.monitor.add_positions(t, positions)
        self.lockstep.took(self._js_topic, t)

    def _refused(self, topic: str, err: CdrError) -> None:
        """A message that does not decode: logged and dropped (its gap then counts as lost)."""
        self.get_logger().error(f"{topic}: a message dropped: {err}", throttle_duration_sec=1.0)

    def _on_event(self, msg: CycleEvent) -> None:
        for event in self.events.handle(msg):  # a START missed: stood in for by the later event's start stamp
            if event.stood_in:
                self.get_logger().warning(f"cycle {msg.cycle}: its START was missed; stood in for by a later"
                                          f" event's start stamp, {event.stamp:.3f} s")
            self._on_cycle_event(event.msg, event.stood_in)

    def _on_cycle_event(self, msg: CycleEvent, stood_in: bool) -> None:
        if msg.event == CycleEvent.END and not self.monitor.in_cycle:
            self._skip(f"cycle {msg.cycle}: END without its START (it began before this node was listening,"
                       " or events were lost)")
            return
        if msg.event == CycleEvent.START and self.monitor.in_cycle:
            self._skip("the cycle in progress never ended (its END was lost)")
        try:
            result = self.monitor.event(msg.event, msg.cycle, time_to_sec(msg.header.stamp), stood_in)
        except ValueError as err:  # e.g. joint states of changing size within a cycle
            self._skip(f"cycle {msg.cycle}: {err}")
            return
        if msg.event == CycleEvent.START:
            self._cycle_start = time_to_sec(msg.header.stamp)
            if self.move_shapers is not None:
                self.move_shapers.on_start(msg)
        if result is None:
            return
        if result.unseen:
            self._skip(f"cycle {result.cycle}: {result.unseen}")
            return
        lost = self.lockstep.describe_lost(self._cycle_start, result.residual.window_end)
        if lost:
            self.get_logger().warning(f"cycle {result.cycle}: {lost} (gaps in the stamps)")
        try:
            record = check_record(result, int(self.params.value.min_samples),
                                  float(self.params.value.sensor.max_abs_accel))
        except SaturatedRecord as err:
            self.saturated += err.count
            self._sensor_fault(result.cycle, str(err), "saturated")
            return
        except SensorFault as err:
            self._sensor_fault(result.cycle, str(err), "sensor")
            return
        except IdentificationError as err:
            self._skip(str(err))
            return
        self.cycles.append((result, record))
        self.get_logger().info(
            f"cycle {result.cycle}: residual RMS {result.residual.rms:.4g} m/s^2 over"
            f" {result.residual.window_end - result.residual.window_start:.3g} s buffered ({len(self.cycles)})")
        self.drift.rate(result.cycle, record)

    # ----------------------------------------------------------------- refused cycles
    def _sensor_fault(self, cycle: int, why: str, kind: str) -> None:
        """A cycle the sensor failed: skipped, an ERROR ``identifier: sensor``, and the drift watch says it
        cannot rate (never OK on a dead sensor; the run of cycles outside the band is left as it was)."""
        self.skipped.append(why)
        text = f"{why}; cycle not used for identification"
        if not self.diagnostics.report(kind, ERROR, text, name="sensor"):
            self.get_logger().error(text)
        if self.params.value.watch.enabled:
            self.diagnostics.publish("drift", ERROR, f"cycle {cycle}: cannot rate the mode: {why}",
                                     [("cycle", str(cycle)), ("sensor_fault", kind)])

    def _skip(self, why: str, kind: str = "") -> None:
        self.skipped.append(why)
        text = f"{why}; cycle not used for identification"
        if not (kind and self.diagnostics.report(kind, WARN, text)):  # logged there unless throttled
            self.get_logger().warning(text)

    # ----------------------------------------------------------------- service
    async def _on_identify(self, req: Identify.Request, resp: Identify.Response) -> Identify.Response:
        p = self.params.value
        try:
            method = validate_method(req.method.strip() or str(p.method))
            max_modes = int(req.max_modes) or int(p.max_modes)
            target = float(req.target_vibration) or float(p.target_vibration)
            if not (math.isfinite(target) and 0.0 < target < 1.0):
                raise ValueError(f"target_vibration must be in (0, 1), got {req.target_vibration!r}")
            if not self.cycles:
                raise IdentificationError("no finished cycle with valid accelerometer data buffered yet")
            n = int(req.cycles) or len(self.cycles)
            used = list(self.cycles)[-n:]
            lo, hi = (float(x) for x in p.band_hz)
            if hi > 0.0 and not 0.0 <= lo < hi:
                raise ValueError(f"parameter band_hz must be [low, high] with 0 <= low < high, got {[lo, hi]}")
            band = (lo, hi) if hi > 0.0 else None
            modes = identify_records([rec for _, rec in used], method=method, max_modes=max_modes, band_hz=band)
            rec = recommend_shaper(modes, target, sigmas=float(p.uncertainty_sigmas))
        except (IdentificationError, ShaperError, ValueError) as err:
            resp.success, resp.message = False, f"identification failed: {err}"
            self.get_logger().error(resp.message)
            return resp

        now = self.get_clock().now().to_msg()
        by_freq = sorted(modes, key=lambda m: m.omega)
        est = estimate_msg("identification", by_freq,
                           [m.omega_std for m in by_freq], [m.zeta_std for m in by_freq], now)
        self._estimate_pub.publish(est)
        resp.estimate = est
        for c in rec.candidates:
            resp.candidate_families.append(c.family)
            resp.candidate_durations.append(c.duration)
            resp.candidate_worst_vibration.append(c.worst_vibration)
            resp.candidate_nominal_vibration.append(c.nominal_vibration)
        found = ", ".join(f"{m.hz:.4g} Hz (+-{m.omega_std / (2 * math.pi):.2g}) zeta {m.zeta:.3g}"
                          f" (+-{m.zeta_std:.2g})" for m in by_freq)
        cycles_used = ", ".join(str(r.cycle) for r, _ in used)
        if rec.best is None:
            resp.recommended = shaper_to_msg(none_shaper(), SOURCE, 0, now)
            resp.success = True
            resp.message = (f"modes {found} from cycles {cycles_used}; no candidate keeps the worst-case"
                            f" vibration under {target:.3g}; nothing applied")
            self.get_logger().warning(resp.message)
            return resp
        best = rec.best
        resp.recommended = shaper_to_msg(best.shaper, SOURCE, 0, now)
        resp.success = True
        resp.message = (f"modes {found} from cycles {cycles_used} ({method}); recommended {best.family}"
                        f" ({best.duration * 1e3:.1f} ms, worst-case V {100 * best.worst_vibration:.2g} %); {rec.rule}")
        if req.apply:
            resp.applied, why = await self._apply(resp.recommended)
            resp.message += f"; {'applied' if resp.applied else 'not applied: ' + why}"
        self.get_logger().info(resp.message)
        return resp

    async def _apply(self, shaper_msg: ShaperMsg) -> tuple[bool, str]:
        # the exact impulses identified on, not a re-design
        ok, why, _ = await self.shaper.send(shaper_msg, exact=True)
        return ok, why


def main(args: list[str] | None = None) -> int:
    return run_node(IdentifierNode, "identifier", args, examples=(
        with_config("shaper_nodes", "identifier", "identifier.yaml"),))


if __name__ == "__main__":
    raise SystemExit(main())
