"""Simulated plant node: flexible joints with a tip accelerometer, running a repeated task.

Stands in for a robot and its ros2_control forward position controller in tests and the demo.
Its parameters (names, defaults, ranges, units) are the class :class:`~.parameters.SimPlantParams`, read
typed as ``self.params.value`` (its table: :data:`~.parameters.PARAMETERS`).

Each step the task runner publishes the raw setpoint (``topics.command_out``, to the shaper),
the plant takes the shaped setpoint (``topics.command_in``, std_msgs/Float64MultiArray as
forward_command_controller does), integrates one period, and publishes ``/joint_states``
(joint = base position and velocity, which for every model is the applied setpoint and its
slope), ``~/tip_state`` (tip position and velocity), the tip accelerometer (sensor_msgs/Imu,
m/s^2, configurable noise and bias), cycle events and a per-cycle report.

The model (``plant.model``: :mod:`sim_plant_node.models`, :mod:`sim_plant_node.arm`) is built by name
(:mod:`.models`) and driven through one interface, :class:`~sim_plant_node.models.base.Plant`, whatever
the model. The arm stands behind an emulation of joint_trajectory_controller
(:mod:`sim_plant_node.controller`); in lockstep it steps while the controller executes a trajectory, and
at rest publishes its last joint state again every 0.1 s of wall time. ``~/set_feedforward`` installs a
profile at the next START (:mod:`.feedforward`). The arm reports each move's residual split (servo and vibration
parts, m/s^2) on ``~/residual_parts`` (:mod:`.residual_report`): the simulator's truth, from the arm's state.

Modes (parameter ``mode``)
--------------------------
lockstep
    Simulated time: publishes /clock and steps only when the shaped setpoint for the previous raw
    setpoint has arrived (none within ``lockstep_timeout`` s of wall time: it holds the last setpoint,
    warns, and goes on), so runs go as fast as the nodes answer and give the same result on a loaded
    machine; idle (no task) it does not step. ``~/start_task`` refuses with 'waiting for subscribers'
    until the loop through the shaper is matched on DDS. With ``lockstep.block`` N > 1 the raw setpoints
    of N steps go out as one block. Asks, blocks and late answers follow :mod:`shaper_nodes.core.lockstep`.
    With ``lockstep.readers`` it never steps more than ``lockstep.lead`` beyond the slowest of those readers'
    acknowledgements (:class:`.lockstep.Readers`: taken from their queues when a step needs them, waited on only
    while a reader holds the plant), and its per-step streams are reliable and 10000 deep. The per-step writes of
    up to 10 periods go out together, in order, and all of them before anything else (:class:`.sensors.WriteBatch`).
realtime
    Wall-clock rate; the latest shaped setpoint received is applied each period.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from rclpy.clock import Clock as RclpyClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from shaper_msgs.msg import CycleEvent, CycleReport
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetFeedforward
from shaper_nodes.core.checks import InputError, finite_array
from shaper_nodes.core.cycles import CycleMonitor
from shaper_nodes.recordings.cdr import clock_cdr, stamp_parts
from shaper_nodes.ros.conversions import sec_to_time
from shaper_nodes.ros.lockstep_reader import STREAM_QOS
from shaper_nodes.ros.node_main import run_node, with_config
from shaper_nodes.ros.parameters import declare
from shaper_nodes.ros.qos import LATCHED, SERVICE_QOS, NoDefaultQosEvents

from ..controller.server import ControllerServer
from ..models.plants import CycleTask
from ..models.two_mass import StaircaseTask
from .controller_runs import ControllerRuns
from .feedforward import Feedforward
from .live_parameters import LiveParameters
from .lockstep import Exchange, Readers
from .models import PlantValues, build_plant, make_task
from .parameters import MODELS, PARAMETERS, WAITING, SimPlantParams
from .residual_report import residual_reports
from .sensors import Sensors, StateBytes, WriteBatch, writer
from .writer_profile import use_writer_profile

__all__ = ["IDLE_STATE_PERIOD", "LOCKSTEP_IMU_QOS", "MODELS", "PARAMETERS", "WAITING", "SimPlantNode", "main"]

#: the lockstep IMU writer: reliable, 10 s of samples at 1 kHz kept for a reader that lags (the plant stepping in
#: blocks may run seconds ahead of a loaded reader's intake)
LOCKSTEP_IMU_QOS = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
#: s of wall time between joint states of the lockstep arm at rest (joint_states.idle_period's default)
IDLE_STATE_PERIOD = 0.1


class SimPlantNode(ControllerRuns, LiveParameters, NoDefaultQosEvents, Node):
    """See the module docstring. Extra arguments go to ``Node``. No default QoS event handlers (a stand-in for a
    robot: ``NoDefaultQosEvents``)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("sim_plant", *args, **kwargs)
        self.params = declare(self, SimPlantParams)
        p = self.params.value

        self.joint_names = list(p.joint_names)
        self.n = len(self.joint_names)
        self.rate = float(p.rate)
        self.mode = str(p.mode)
        if self.mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode must be 'lockstep' or 'realtime', got {self.mode!r}")
        self.plant = build_plant(PlantValues(p, self.rate, self.n), self.n)
        own = self.plant.joint_names  # a model with joints of its own (the arm): the default names become them
        if own is not None and self.joint_names == ["joint_1"]:
            self.joint_names = list(own)
        if own is not None and len(self.joint_names) != len(own):
            raise ValueError(f"plant.model {p.plant.model} has {len(own)} joints;"
                             f" joint_names has {len(self.joint_names)}")
        self.n = len(self.joint_names)
        axes = [int(a) for a in p.imu.axes][:3]
        self._axes = [a if 0 <= a < self.n else -1 for a in axes] + [-1] * (3 - len(axes))
        self._monitor = CycleMonitor(float(p.settle_tolerance), remove_mean=self.plant.gravity_in_imu)
        self._active_shaper = ShaperMsg()

        t = p.topics
        deep = STREAM_QOS if self.mode == "lockstep" else 10  # every sample counts in lockstep (lockstep.lead)
        self._cmd_pub = self.create_publisher(Float64MultiArray, t.command_out, 10)
        self._js_pub = self.create_publisher(JointState, t.joint_states, deep)
        self._tip_pub = self.create_publisher(JointState, t.tip_state, deep)
        self._loop_pub = self.create_publisher(JointState, "~/loop_state", 10)  # loop models only
        # in lockstep every sample counts (simulated time runs faster than a reader may take them): a reliable
        # writer keeps 10000 for a reliable reader, and still matches best-effort readers as a sensor driver does
        imu_pub = self.create_publisher(Imu, t.imu, LOCKSTEP_IMU_QOS if self.mode == "lockstep"
                                        else qos_profile_sensor_data)
        # lockstep: the per-step writes of a few periods go out together (.sensors.WriteBatch)
        self._batch = WriteBatch()
        batch = self._batch if self.mode == "lockstep" else None
        keep = self._batch.deferred if batch is not None else (lambda write: write)
        self.sensors = Sensors(self.joint_names, p.imu, p.joint_states, imu_pub, self._monitor, batch)
        # the tip state and the reference as serialized bytes written in place (no message objects per step)
        self._tip_bytes, self._ref_bytes = StateBytes(self.joint_names), StateBytes(self.joint_names)
        self._event_pub = self.create_publisher(CycleEvent, t.cycle_events, 10)
        self._report_pub = self.create_publisher(CycleReport, t.cycle_reports, 10)
        # /clock is published as serialized bytes, its numbers rewritten in place (shaper_nodes.recordings.cdr)
        self._clock_pub = self.create_publisher(Clock, "/clock", 10) if self.mode == "lockstep" else None
        self._ref_pub = self.create_publisher(JointState, t.reference, deep)
        # the per-step streams' writes and the optional ones' subscriber counts, without rclpy's per-call wrapper
        self._js_write, self._tip_write, self._ref_write = (keep(writer(pub)) for pub in (self._js_pub, self._tip_pub,
                                                                                       self._ref_pub))
        self._loop_write = keep(self._loop_pub.publish)
        self._tip_count = self._tip_pub.handle.get_subscription_count
        self._ref_count = self._ref_pub.handle.get_subscription_count
        self._clock_write = None if self._clock_pub is None else keep(writer(self._clock_pub))
        self.create_service(SetFeedforward, "~/set_feedforward", self._on_set_feedforward, qos_profile=SERVICE_QOS)
        self._ff = Feedforward()
        # the arm: each move's residual split on ~/residual_parts (.residual_report)
        self._parts = residual_reports(self, self.plant, self._now, self._batch.flush)
        self._cmd_sub = self.create_subscription(Float64MultiArray, t.command_in, self._on_command, 10)
        self.create_subscription(ShaperMsg, t.active_shaper, self._on_shaper, LATCHED)
        self.create_service(Trigger, "~/start_task", self._on_start, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, "~/stop_task", self._on_stop, qos_profile=SERVICE_QOS)
        self.add_on_set_parameters_callback(self._validate_params)

        self.step_index = 0
        self.sim_time = 0.0
        self._cycle_start_step: int | None = None  # step_index at the current cycle's START
        self.task: CycleTask | StaircaseTask | None = None
        self._preroll_left = 0
        self._latest_shaped: np.ndarray | None = None
        self.exchange = Exchange(self._cmd_pub, self.n, int(p.lockstep.block), self.get_logger())
        self.readers = Readers(self, p.lockstep.readers if self.mode == "lockstep" else (), float(p.lockstep.lead),
                               float(p.lockstep.reader_timeout), self._now, on_ack=self._reader_acked)
        self._held = False  # lockstep, a task running: the next ask waits for the readers
        # lockstep, the controller's trajectory held by a reader: its timer is off until an acknowledgement lets it
        # step (or the watchdog's next look, for lockstep.reader_timeout)
        self._free_held = False
        self._free_timer: Any = None
        # lockstep, the controller idle: its timer is off until a trajectory comes (a 2 ms timer woke the executor 500
        # times a wall second for nothing: a tenth of a core per idle arm)
        self._free_idle = False
        self.refused = 0
        self.plant.reset(self._values(p).vector("task.start", p.task.start))
        self._applied = self.plant.setpoint_at_rest
        self._raw = self._applied.copy()
        self.jtc: ControllerServer | None = None
        self._start_controller(t.jtc_action, t.jtc_topic)
        idle = float(p.joint_states.idle_period)
        idle = (IDLE_STATE_PERIOD if self.plant.trajectory_controller else 0.0) if idle < 0 else idle
        if self.mode == "lockstep" and idle > 0:
            # a robot's joint_state_broadcaster publishes at rest too: the last state again (time stands still)
            self._last_js: JointState | bytes = self.sensors.joint_state_message(self.plant, sec_to_time(self._now()))
            self.create_timer(idle, self._idle_joint_states, clock=RclpyClock(clock_type=ClockType.STEADY_TIME))
        if self.mode == "lockstep":
            self.create_timer(0.05, self._watchdog)  # (also looks again at readers that hold a task's next ask)
            self._publish_clock()
            self._batch.flush()
        else:
            self.create_timer(1.0 / self.rate, self._realtime_tick)
        if p.task.autostart:
            self._start_task()
        self.get_logger().info(
            f"{self.n} joints, plant {p.plant.model}, modes " + ", ".join(
                f"{w / (2 * math.pi):.4g} Hz zeta {z:.3g}" for w, z in zip(self.plant.natural_frequency,
                                                                          self.plant.damping_ratio, strict=True))
            + f", {self.mode} at {self.rate:g} Hz")

    @property
    def _waiting_since(self) -> float | None:
        """Lockstep: the wall time the pending ask went out (None: none pending)."""
        return self.exchange.waiting_since

    # ----------------------------------------------------------------- configuration
    def _cycle_time(self) -> float | None:
        """Time since the current cycle's START at the present step, s (None before any)."""
        if self._cycle_start_step is None:
            return None
        return (self.step_index - self._cycle_start_step) / self.rate

    # ----------------------------------------------------------------- task
    def _start_task(self, matched: bool = False) -> tuple[bool, str]:
        """Start a run; with ``matched`` (the ~/start_task service), in lockstep only once the loop through the
        shaper is matched on DDS (:meth:`.lockstep.Exchange.unmatched`)."""
        if self.task is not None:
            return False, "a task is already running"
        if self.jtc is not None and self.jtc.running:
            return False, "joint_trajectory_controller is executing a trajectory"
        p = self.params.value
        need = int(p.task.subscribers)
        have = self._event_pub.get_subscription_count()  # matched, not only discovered
        if have < need:
            return False, f"{WAITING}: the cycle events have {have} matched subscriptions, task.subscribers is {need}"
        unmatched = self.exchange.unmatched(self._cmd_sub) if matched and self.mode == "lockstep" else ""
        if unmatched:
            return False, f"{WAITING}: {unmatched}"
        try:
            task = self.task = make_task(self._values(p), self.rate)
        except ValueError as err:
            return False, str(err)
        self._preroll_left = int(round(float(p.task.preroll) * self.rate))
        self._cycle_start_step = None  # the preroll belongs to no cycle
        self._preroll_total = self._preroll_left
        if self.mode == "lockstep" and self.exchange.waiting_since is None:
            self._publish_next()
        return True, (f"{task.cycles} cycles of {task.samples_per_cycle / self.rate:.3f} s"
                      f" (move {task.move_duration:.3f} s) after {self._preroll_left / self.rate:.3f} s preroll")

    def _on_start(self, req, resp):
        resp.success, resp.message = self._start_task(matched=True)
        return resp

    def _on_stop(self, req, resp):
        resp.success, resp.message = self.task is not None, "stopped" if self.task else "no task running"
        self.task = None
        return resp

    def _next_raw(self) -> tuple[list, bool]:
        """The raw setpoint of the next step (into ``_raw``), its cycle events, and whether the preroll ends
        with it (:meth:`_begin_step` carries them out when the step is integrated)."""
        if self.task is None:
            return [], False
        if self._preroll_left > 0:
            self._raw = self.task.start.copy()
            self._preroll_left -= 1
            return [], self._preroll_left == 0
        self._raw, events = self.task.step()
        return events, False

    def _begin_step(self, events: list, preroll_end: bool) -> None:
        """What comes before a step is integrated: at the end of the preroll the plant rests exactly at the
        applied setpoint (whatever came before the run), and the step's cycle events go out."""
        if preroll_end:
            self.plant.reset(self._applied)
        t = self._now()
        for ev in events:
            self._emit_event(ev, t)

    # ----------------------------------------------------------------- stepping
    def _publish_clock(self) -> None:
        if self._clock_write is not None:
            self._clock_write(clock_cdr(*stamp_parts(self.sim_time)))

    def _now(self) -> float:
        if self.mode == "lockstep":
            return self.sim_time
        return self.get_clock().now().nanoseconds * 1e-9

    def _publish_next(self) -> None:
        """Ask the shaper for the shaped setpoints of the next steps, up to ``lockstep.block`` of them (up to
        the task's end). Their events go out as each step is integrated (:meth:`_step_asked`)."""
        steps: list[tuple[list, bool]] = []
        raws: list[np.ndarray] = []
        self._held = not self.readers.may_step(self.sim_time + self.exchange.block / self.rate)
        while not self._held and len(raws) < self.exchange.block and self.task is not None and (
                self._preroll_left > 0 or not self.task.done):
            steps.append(self._next_raw())
            raws.append(self._raw)
        if raws:
            self.exchange.ask(steps, raws)

    def _step_asked(self, shaped: np.ndarray | None) -> None:
        """Integrate the steps asked for, each with its shaped setpoint (a row of ``shaped``; None: each holds
        the last applied setpoint), publishing /clock after each; then ask for the next ones."""
        for i, (events, preroll_end) in enumerate(self.exchange.take()):
            self._begin_step(events, preroll_end)
            self._integrate(self._applied if shaped is None else shaped[i])
            self._publish_clock()
            self._batch.period()
        self._batch.flush()  # (the steps' writes before the next ask)
        if self.task is not None:
            self._publish_next()

    def _emit_event(self, ev, t: float) -> None:
        self._batch.flush()  # the steps before the event go out before it
        msg = CycleEvent(event=ev.kind, cycle=ev.cycle, task=str(self.params.value.task.name),
                         joint_names=self.joint_names, start_positions=ev.start.tolist(),
                         goal_positions=ev.goal.tolist())
        msg.header.stamp = sec_to_time(t)
        self._event_pub.publish(msg)
        if ev.kind == CycleEvent.START:
            self._cycle_start_step = self.step_index  # the next period is the cycle's first
            self._ff.start()
        result = self._monitor.event(ev.kind, ev.cycle, t)
        if result is not None:
            self._report(result)
        if ev.kind == CycleEvent.END and self.task is not None and self.task.done:
            self.get_logger().info(f"task run finished after {self.task.cycles} cycles")
            self.task = None

    def _report(self, result) -> None:
        r = result.residual
        msg = CycleReport(source="sim_plant", cycle=result.cycle, window_start=r.window_start, window_end=r.window_end,
                          residual_rms=r.rms, residual_peak=r.peak, shaper_used=self._active_shaper,
                          shaper_next=self._active_shaper)
        msg.header.stamp = sec_to_time(self._now())
        self._report_pub.publish(msg)

    def _integrate(self, command: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """One period: apply ``command`` (and, from the trajectory controller, its ``velocity``), publish the state."""
        if self.jtc is not None and velocity is None and not self.jtc.running:
            self.jtc.controller.hold(command)  # the forward command's setpoint is held when it stops
        t_start = self._now()
        self._applied = command
        if self._ref_count() > 0:  # (a learner's input; serialized in place)
            self._ref_write(self._ref_bytes(t_start, command))  # stamped at the period's start
        ff = self._ff.sample(None if self._cycle_start_step is None else self.step_index - self._cycle_start_step)
        if ff is not None and ff[0] == "command":
            command = command + ff[1]
        self.plant.set_effort(ff[1] if ff is not None and ff[0] == "effort" else None)
        if self._parts is not None:
            self._parts.before(t_start, command)
        self.plant.step(command, cycle_time=self._cycle_time(), velocity=velocity)
        self.step_index += 1
        self.sim_time = self.step_index / self.rate
        t = self._now()
        js = self._last_js = self.sensors.joint_state(self.plant, t)  # (also the idle republisher's)
        self._js_write(js)
        if self._tip_count() > 0:
            self._tip_write(self._tip_bytes(t, *self.plant.tip_state()))
        signals = self.plant.loop_state()
        if signals is not None:  # per joint and signal (e.g. output, measured, control, reference)
            loop = JointState(name=[f"{j}/{s}" for s in self.plant.loop_signals for j in self.joint_names],
                              position=signals.tolist())
            loop.header.stamp = sec_to_time(t)
            self._loop_write(loop)
        for stamp, force, rate in self.plant.imu(t_start, t, self._axes):
            self.sensors.publish_imu(stamp, force, rate)
        self._monitor.add_positions(t, self._applied)
        if self._parts is not None:  # (a report goes out after this period's samples)
            self._parts.after()

    # ------------------------------------------------- the trajectory controller (arm; the rest in .controller_runs)
    def _reader_acked(self) -> None:
        """A reader's acknowledgement while the plant is held: a trajectory or a task it held steps on at once if
        none holds it any more."""
        if self._free_held and not self.readers.gate.holding(self.sim_time + 1.0 / self.rate):
            self._free_held = False
            self._free_timer.reset()
            self._free_run()
        self._resume()

    # ----------------------------------------------------------------- the shaped setpoints
    def _on_command(self, msg: Float64MultiArray) -> None:
        if self.mode == "lockstep" and self.exchange.late(msg):  # the answer to an earlier ask: ignored
            return
        try:  # in lockstep, the answer to the steps asked for (lockstep.block)
            rows = self.exchange.rows() if self.mode == "lockstep" else 1
            command = finite_array("shaped command", msg.data, size=self.n * rows)
        except InputError as err:
            self.refused += 1
            self.get_logger().error(f"refused setpoint: {err}; holding the last one", throttle_duration_sec=1.0)
            command = None
        if self.mode == "realtime":
            if self.jtc is not None and self.task is None:  # the arm, no task: the forward controller holds it
                if command is not None and not self.jtc.running:
                    self.jtc.controller.hold(command)
                return
            if command is not None:
                self._latest_shaped = command
            return
        if self.exchange.waiting_since is None:
            return  # not waiting (idle, or a late answer after a timeout): ignore
        self._step_asked(None if command is None else command.reshape(-1, self.n))

    def _resume(self) -> None:
        """Lockstep, a task running: ask for the next steps once the readers that held them caught up."""
        if self._held and self.task is not None and self.exchange.waiting_since is None:
            self._publish_next()

    def _watchdog(self) -> None:
        if not self.readers.waited:  # at rest too: a reader's announcement counts it before the next motion (logged)
            self.readers.take()
        self._resume()
        if self._free_held:  # (a reader that holds the trajectory is looked at again: gone, or past its timeout)
            self._free_held = False
            self._free_timer.reset()
        if self.exchange.overdue(lambda: float(self.params.value.lockstep_timeout)):
            self._step_asked(None)

    def _realtime_tick(self) -> None:
        if self.jtc is not None and self.task is None:
            self._jtc_step()
            return
        self._begin_step(*self._next_raw())
        self._cmd_pub.publish(Float64MultiArray(data=self._raw.tolist()))
        command = self._latest_shaped if self._latest_shaped is not None else self._applied
        self._integrate(command)

    def _on_shaper(self, msg: ShaperMsg) -> None:
        self._active_shaper = msg

    def _on_set_feedforward(self, req, resp):
        resp.success, resp.message = self._ff.request(req.profile, self.plant.injections, self.joint_names, self.rate,
                                                      self._cycle_start_step is None or self.task is None)
        if not resp.success:
            self.get_logger().error(f"refused feedforward profile: {resp.message}")
        return resp


def main(args: list[str] | None = None) -> int:
    use_writer_profile()  # (before rclpy.init: Fast DDS reads it at its first participant)
    return run_node(SimPlantNode, "sim_plant", args, examples=(
        with_config("sim_plant_node", "sim_plant", "sim_plant.yaml"),
        "ros2 run sim_plant_node sim_plant --ros-args -p plant.model:=arm -p mode:=realtime",))


if __name__ == "__main__":
    raise SystemExit(main())
