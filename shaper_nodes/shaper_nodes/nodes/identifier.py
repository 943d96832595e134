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
(OK inside the band). A change of the active shaper starts the count again. The identity
shaper is not watched. With ``watch.scheduler`` (a shaper node shaping each goal through that
scheduler, whose active shaper does not change), each cycle is rated against the shaper its move
ran with, asked of the scheduler at its START (:mod:`.identifier_moves`), and the active shaper is
not followed (the scheduler's changes of it as the arm moves would restart the count at every move).
Rated: the identified mode nearest each design mode, and the strongest (a mode a payload moved far
below every design mode is nearer another one); the worst of them decides. Each move has its own count,
and the status is WARN while any move's watch warns.

Parameters: :data:`PARAMETERS` (config/identifier.yaml).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from shaper_msgs.msg import CycleEvent, ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import Identify
from shaper_nodes.core.cycles import CycleMonitor, CycleResult
from shaper_nodes.core.identification import METHODS, IdentificationError, ModeFit, identify_records, recommend_shaper
from shaper_nodes.core.identification.drift import DriftWatch, ModeCheck, check_mode
from shaper_nodes.core.learning.samples import MAX_ABS_ACCEL, out_of_range, sensor_fault
from shaper_nodes.core.shaping import ShaperError, none_shaper
from shaper_nodes.recordings.cdr_sensors import CdrError, JointStateReader, decode_imu
from shaper_nodes.ros.conversions import estimate_msg, msg_hz, shaper_to_msg, time_to_sec
from shaper_nodes.ros.diagnostics import ERROR, OK, WARN, Diagnostics
from shaper_nodes.ros.lockstep_reader import IMU_RELIABLE_DOC, STREAM_QOS, LockstepReader, subscribe_draining
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import Spec, declare, param, table, topic
from shaper_nodes.ros.qos import IMU_QOS, LATCHED, SERVICE_QOS
from shaper_nodes.ros.shaper_client import ShaperClient

from .identifier_moves import MoveShapers

SOURCE = "identification"
#: a gap between two accelerometer samples longer than this many median periods marks the
#: cycle's data as incomplete
MAX_GAP_PERIODS = 5.0


def _distance(hz: float, mode: ModeFit) -> float:
    """How far ``mode`` is from ``hz``, Hz."""
    return abs(mode.hz - hz)


def _validate_method(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"unknown identification method {method!r}; known: {sorted(METHODS)}")
    return method


class SensorFault(IdentificationError):
    """A cycle whose accelerometer data cannot come from a working sensor (silent, stuck, non-finite)."""


class SaturatedRecord(SensorFault):
    """A cycle with accelerometer samples at or beyond the sensor's range; ``count`` of them."""

    def __init__(self, message: str, count: int) -> None:
        super().__init__(message)
        self.count = count


def check_record(result: CycleResult, min_samples: int, max_abs_accel: float = MAX_ABS_ACCEL
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The residual-vibration record of a finished cycle: (times (N,), accel (N, k)).

    Raises
    ------
    IdentificationError
        Too few samples in the window, or a gap in the samples; :class:`SensorFault` when the cycle's
        samples cannot come from a working sensor (none, non-finite, or every axis one value through
        the cycle: :func:`~shaper_nodes.core.learning.samples.sensor_fault`), and its subclass
        :class:`SaturatedRecord` if any sample of the cycle is at or beyond ``max_abs_accel`` (m/s^2,
        the sensor's range).
    """
    t, a = result.accel_times, result.accel
    fault = sensor_fault(a)  # over the whole cycle, motion included
    if fault is not None:
        raise SensorFault(f"cycle {result.cycle}: sensor fault: {fault}")
    sel = (t >= result.residual.window_start) & (t < result.residual.window_end)
    t, a = t[sel], a[sel]
    if t.size < min_samples:
        raise IdentificationError(
            f"cycle {result.cycle}: {t.size} accelerometer samples in the residual window"
            f" [{result.residual.window_start:.3f}, {result.residual.window_end:.3f}) s, need {min_samples}")
    if not np.all(np.isfinite(a)):
        raise IdentificationError(f"cycle {result.cycle}: non-finite accelerometer samples")
    saturated = out_of_range(result.accel, max_abs_accel)
    if saturated is not None:
        raise SaturatedRecord(f"cycle {result.cycle}: saturated accelerometer: "
                              + saturated.describe("accelerometer", "m/s^2", "sensor.max_abs_accel"), saturated.count)
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        raise IdentificationError(f"cycle {result.cycle}: accelerometer stamps not strictly increasing")
    gap, period = float(dt.max()), float(np.median(dt))
    if gap > MAX_GAP_PERIODS * period:
        raise IdentificationError(
            f"cycle {result.cycle}: a {gap * 1e3:.1f} ms gap in the accelerometer data"
            f" (median period {period * 1e3:.2f} ms): data incomplete or stale")
    return t, a


def _check_band(value: Any) -> None:
    lo, hi = (float(x) for x in value)
    if hi > 0.0 and not 0.0 <= lo < hi:
        raise ValueError(f"parameter band_hz must be [low, high] with 0 <= low < high, got {[lo, hi]}")


_PROBE = ModeFit(2 * math.pi * 10.0, 0.02, 0.5, 0.002, 1.0, "fit")  # to hold one value against the core

@dataclass(frozen=True)
class SensorParams:
    """sensor.*: the accelerometer's range."""

    max_abs_accel: float = param(MAX_ABS_ACCEL, "Accelerometer range, m/s^2: a cycle with a sample at or beyond"
                                 " it is refused as saturated (default 16 g).", (1e-3, 1e6))


@dataclass(frozen=True)
class WatchParams:
    """watch.*: the drift watch."""

    enabled: bool = param(True, "Drift watch: rate every buffered cycle's mode against the active shaper's working"
                          " band and warn on /diagnostics when it leaves it.", read_only=True)
    tolerance: float = param(0.05, "Drift watch: the working band is where the active shaper keeps V under this,"
                             " fraction.", (0.001, 0.5))
    confirm: int = param(2, "Drift watch: cycles in a row outside the band before the warning.", (1, 1000))
    max_uncertainty: float = param(
        0.02, "Drift watch: a mode whose one-sigma frequency uncertainty exceeds this"
        " fraction of its frequency is not rated (a fit to a residual at the noise floor, where the shaper leaves"
        " nothing to identify).", (1e-4, 1.0))
    scheduler: str = param(
        "", "Drift watch: fully qualified name of the scheduler whose ~/shaper_at gives the shaper each cycle's"
        " move ran with (its START's joints, start and goal), for a shaper node that shapes each goal through it"
        " (action.scheduler); each cycle is rated against that shaper. Empty: the active shaper.", read_only=True)


@dataclass(frozen=True)
class TopicParams:
    """topics.*: the inputs."""

    imu: str = topic("/tip_imu", "imu")
    joint_states: str = topic("/joint_states", "joint_states")
    cycle_events: str = topic("/cycle_events", "cycle_events")
    imu_reliable: bool = param(False, IMU_RELIABLE_DOC, read_only=True)


@dataclass(frozen=True)
class IdentifierParams:
    """The identifier node's parameters (see config/identifier.yaml)."""

    shaper: str = param("/shaper", "Fully qualified name of the shaper node to apply shapers to.", read_only=True)
    buffer_cycles: int = param(5, "Finished cycles kept for identification.", (1, 1000), read_only=True)
    method: str = param("fit", "Default identification method: " + ", ".join(f"{k} ({v})" for k, v in METHODS.items()),
                        check=lambda v: _validate_method(v))
    max_modes: int = param(2, "Default largest number of modes to identify.", (1, 8))
    target_vibration: float = param(
        0.05, "Default worst-case percentage vibration the recommended shaper must meet,"
        " fraction.", (0.001, 0.5), check=lambda v: recommend_shaper([_PROBE], v, families=("zv",)))
    uncertainty_sigmas: float = param(
        2.0, "Half-width of the uncertainty band the worst case is taken over, in standard"
        " deviations.", (0.0, 10.0), check=lambda v: recommend_shaper([_PROBE], 0.05, sigmas=v, families=("zv",)))
    band_hz: tuple[float, ...] = param([0.0, 0.0], "Frequency band searched, Hz ([0, 0]: up to Nyquist).",
                                       check=_check_band)
    min_samples: int = param(100, "Fewest accelerometer samples in a cycle's residual window.", (10, 10**7))
    sensor: SensorParams = field(default_factory=SensorParams)
    settle_tolerance: float = param(1e-6, "Band within which the joints count as at rest after a move, rad or m.",
                                    (0.0, 1e3))
    service_timeout: float = param(5.0, "Time to wait for the shaper node's set_shaper service, and then for its"
                                   " answer, s.", (0.1, 600.0))
    watch: WatchParams = field(default_factory=WatchParams)
    topics: TopicParams = field(default_factory=TopicParams)


#: the identifier node's parameters (derived from IdentifierParams)
PARAMETERS: tuple[Spec, ...] = table(IdentifierParams)


class IdentifierNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("identifier", *args, **kwargs)
        self.params = declare(self, IdentifierParams)
        p = self.params.value
        _validate_method(p.method)

        self.monitor = CycleMonitor(float(p.settle_tolerance))
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
        self.watch = DriftWatch(int(p.watch.confirm))
        self._active: ShaperMsg | None = None
        self._warned = False
        self.move_shapers = MoveShapers(self, str(p.watch.scheduler), lambda: float(
            self.params.value.service_timeout), self.diagnostics, int(p.watch.confirm)) \
            if p.watch.enabled and p.watch.scheduler else None
        if bool(p.watch.enabled) and self.move_shapers is None:  # (with watch.scheduler: not the one rated)
            self.create_subscription(ShaperMsg, f"{str(p.shaper).rstrip('/')}/active_shaper",
                                     self._on_active, LATCHED)
        self.get_logger().info(
            f"identifying from {p.topics.imu}, keeping {self.cycles.maxlen} cycles;"
            f" applies to {self.shaper.srv_name}")

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
        if msg.event == CycleEvent.END and not self.monitor.in_cycle:
            self._skip(f"cycle {msg.cycle}: END without its START (it began before this node was listening,"
                       " or events were lost)")
            return
        if msg.event == CycleEvent.START and self.monitor.in_cycle:
            self._skip("the cycle in progress never ended (its END was lost)")
        try:
            result = self.monitor.event(msg.event, msg.cycle, time_to_sec(msg.header.stamp))
        except ValueError as err:  # e.g. joint states of changing size within a cycle
            self._skip(f"cycle {msg.cycle}: {err}")
            return
        if msg.event == CycleEvent.START:
            self._cycle_start = time_to_sec(msg.header.stamp)
            if self.move_shapers is not None:
                self.move_shapers.on_start(msg)
        if result is None:
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
        self._watch_cycle(result.cycle, record)

    # ----------------------------------------------------------------- drift watch
    def _on_active(self, msg: ShaperMsg) -> None:
        if self._active is None or msg.revision != self._active.revision:
            self.watch.reset()
        self._active = msg

    def _watch_cycle(self, cycle: int, record: tuple[np.ndarray, np.ndarray]) -> None:
        """Rate this cycle's mode against the active shaper (see the module docstring)."""
        active, watch = self._active, self.watch
        if self.move_shapers is not None:  # the move's shaper, and its own watch
            active, why, move_watch = self.move_shapers.shaper(cycle)
            if active is None or move_watch is None:
                self.get_logger().info(f"cycle {cycle}: drift watch: not rated ({why})")
                return
            watch = move_watch
        if active is None or len(active.amplitudes) < 2 or active.family == "none":
            return
        p = self.params.value
        lo, hi = (float(x) for x in p.band_hz)
        try:
            modes = identify_records([record], method=str(p.method), max_modes=int(p.max_modes),
                                     band_hz=(lo, hi) if hi > 0.0 else None)
        except IdentificationError as err:
            self._quiet(cycle, watch, f"cycle {cycle}: no mode identified in the residual ({err}): the residual is"
                        " at the noise floor")
            return
        sharp = [m for m in modes if m.omega > 0 and m.omega_std <= float(p.watch.max_uncertainty) * m.omega]
        check = self._worst(active, sharp)
        if check is None:
            found = ", ".join(f"{m.hz:.4g} Hz (+-{100 * m.omega_std / m.omega:.2g} %)" for m in modes if m.omega > 0)
            self._quiet(cycle, watch, f"cycle {cycle}: no mode identified sharply enough to rate ({found or 'none'};"
                        f" watch.max_uncertainty {100 * float(p.watch.max_uncertainty):.3g} %): the residual"
                        " is at the noise floor")
            return
        watch.update(check)
        text = f"cycle {cycle}: {check.describe()}"
        values = [("cycle", str(cycle)), ("mode_hz", f"{check.mode_hz:.6g}"), ("zeta", f"{check.zeta:.4g}"),
                  ("vibration", f"{check.vibration:.4g}"), ("tolerance", f"{check.tolerance:.4g}"),
                  ("band_low_hz", f"{check.band_hz[0]:.6g}" if check.band_hz else "none"),
                  ("band_high_hz", f"{check.band_hz[1]:.6g}" if check.band_hz else "none"),
                  ("outside_in_a_row", str(watch.outside_in_a_row)), ("shaper_revision", str(active.revision))]
        if watch.warning:
            text = (f"the mode has drifted out of the active shaper's working band ({watch.outside_in_a_row}"
                    f" cycles in a row): {text}; retune the shaper (~/identify with apply)")
        self._verdict(text, values)

    def _verdict(self, text: str, values: list[tuple[str, str]]) -> None:
        """The status ``drift``: WARN while the watch warns (with watch.scheduler: while any move's watch does)."""
        drifted = self.move_shapers.drifted() if self.move_shapers is not None else (
            ["the task"] if self.watch.warning else [])
        if drifted and self.move_shapers is not None:
            text = f"{len(drifted)} move(s) drifted out of their shaper's working band ({', '.join(drifted)}); {text}"
            values = [*values, ("drifted_moves", str(len(drifted)))]
        if drifted:
            if not self._warned:
                self.get_logger().warning(text)
            self._warned = True
            self.diagnostics.publish("drift", WARN, text, values)
        else:
            if self._warned:
                self.get_logger().info(f"the mode is back inside the working band: {text}")
            self._warned = False
            self.diagnostics.publish("drift", OK, text, values)

    def _quiet(self, cycle: int, watch: DriftWatch, text: str) -> None:
        """A cycle with nothing to rate: the shaper works (see DriftWatch.quiet)."""
        watch.quiet()
        self._verdict(text, [("cycle", str(cycle)), ("outside_in_a_row", "0")])

    def _worst(self, active: ShaperMsg, modes: list[ModeFit]) -> ModeCheck | None:
        """The checks of the identified mode nearest each design mode and of the strongest mode (the one that
        rings most, which a payload may have moved below every design mode); the one with the largest V."""
        if not modes:
            return None
        tol = float(self.params.value.watch.tolerance)
        design = [hz for hz in map(msg_hz, active.design_modes) if hz > 0]
        chosen = {min(modes, key=functools.partial(_distance, hz)) for hz in design}
        chosen.add(max(modes, key=lambda m: m.amplitude))
        checks = [check_mode(active.amplitudes, active.times, design, m, tol) for m in chosen]
        return max(checks, key=lambda c: c.vibration)

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
            method = _validate_method(req.method.strip() or str(p.method))
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
