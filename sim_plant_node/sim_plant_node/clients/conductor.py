"""A client node that runs experiments against the sim plant and the shaper over the graph.

It speaks only the public interfaces (SetShaper, rcl_interfaces/SetParameters, Trigger,
the Imu, JointState and CycleEvent topics), so the demo and the integration tests drive the
real nodes exactly as a user would. It measures each cycle's residual vibration itself from
what it receives, with the same core code (``CycleMonitor``) that the plant's reports use.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import functools
import math
import pathlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.srv import SetParameters
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, JointState
from std_srvs.srv import Trigger

from shaper_msgs.msg import CycleEvent
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper
from shaper_nodes.core.cycles import CycleResult, StampedCycleMonitor
from shaper_nodes.recordings.cdr_arrays import CdrError
from shaper_nodes.recordings.cdr_sensors import JointStateReader, decode_imu
from shaper_nodes.ros.conversions import mode_msg, time_to_sec
from shaper_nodes.ros.lockstep_reader import subscribe_draining
from shaper_nodes.ros.qos import NoDefaultQosEvents

from ..models.plants import mck_from_mode
from ..node.parameters import WAITING


def _past(t: float) -> bool:
    return time.monotonic() > t


#: the node processes of the running :func:`node_session` (a wait ends when one of them dies)
_SESSION: list[Any] = []
#: s of wall time between two looks at the session's processes during a wait
LOOK = 1.0


def _dead(procs: list[Any]) -> str | None:
    """One line naming a process of ``procs`` that ended in an error without being stopped, with its log's last
    line (a process that ran to its end, as calibrate does, exits with 0)."""
    for proc in procs:
        if not proc.stopped and not proc.running() and proc.proc.returncode != 0:
            last = ""
            if proc.log_path is not None and proc.log_path.exists():
                lines = proc.log_path.read_text(errors="replace").strip().splitlines()
                last = f": {lines[-1]}" if lines else ""
            return f"{pathlib.Path(proc.cmd[0]).name} exited with code {proc.proc.returncode} ({proc.log_path}){last}"
    return None


def spin_until(executor: Executor, done: Callable[[], bool], timeout: float, what: str) -> None:
    """Spin ``executor`` until ``done()``; ``TimeoutError`` (naming ``what``) after ``timeout`` s, and
    ``RuntimeError`` (naming the process and its log's last line) as soon as a node process of the running
    :func:`node_session` has died: waiting for it is pointless."""
    now = time.monotonic()
    deadline, look = now + timeout, now + LOOK
    while not done():
        now = time.monotonic()
        if now > deadline:
            raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
        if now > look:
            look = now + LOOK
            if _SESSION and (dead := _dead(_SESSION)):
                raise RuntimeError(f"while waiting for {what}: {dead}")
        executor.spin_once(timeout_sec=0.05)


class Conductor(NoDefaultQosEvents, Node):
    """Drive the sim plant and the shaper; collect per-cycle results."""

    def __init__(self, *args, plant: str = "/sim_plant", shaper: str = "/shaper", imu_topic: str = "/tip_imu",
                 settle_tolerance: float = 1e-6, measure: bool = True, **kwargs) -> None:
        # no parameter services (nothing sets the conductor's parameters): six services fewer in the wait set of
        # every spin, about 17 % less CPU per message taken (it takes every accelerometer sample of a run)
        kwargs.setdefault("start_parameter_services", False)
        super().__init__("conductor", *args, **kwargs)
        self.plant, self.shaper = plant, shaper
        self._task_cycles: int | None = None  # task.cycles as this conductor last set it
        # by stamps: samples and events come on separate topics, in an order that depends on the load
        self.monitor = StampedCycleMonitor(settle_tolerance)
        self.results: list[CycleResult] = []
        # best effort as the sensor publishes, but a deep queue: with the default sensor-data depth (5) a busy
        # machine drops samples here and the measured residual depends on the load
        imu_qos = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
        # measure False: no accelerometer or joint state subscription (a driver that does not use the residuals
        # this conductor measures: they were most of its CPU, a message taken per sample); run_cycles needs them.
        # Both are taken serialized, every queued message per wake-up (poll 0: woken by the messages, in the
        # node's default group as before), and only the stamp and the values the monitor uses are read: the same
        # floats as the message objects', without rclpy's executor turn and conversion per sample
        self.measure = measure
        if measure:
            self._js_reader = JointStateReader()
            subscribe_draining(self, Imu, imu_topic, self._on_imu, imu_qos, poll=0)
            subscribe_draining(self, JointState, "/joint_states", self._on_js, 100, poll=0)
        self.create_subscription(CycleEvent, "/cycle_events", self._on_event, 100)
        self.set_shaper_cli = self.create_client(SetShaper, f"{shaper}/set_shaper")
        self.plant_params_cli = self.create_client(SetParameters, f"{plant}/set_parameters")
        self.start_cli = self.create_client(Trigger, f"{plant}/start_task")
        self.executor_ = SingleThreadedExecutor(context=self.context)
        self.executor_.add_node(self)

    # ----------------------------------------------------------------- data
    def _on_imu(self, raw: bytes) -> None:
        try:
            t, accel = decode_imu(raw)
        except CdrError as err:  # (not from a typed publisher) dropped: a lost sample
            self.get_logger().error(f"accelerometer: a message dropped: {err}", throttle_duration_sec=5.0)
            return
        self.monitor.add_accel(t, accel)
        self.results.extend(self.monitor.poll())

    def _on_js(self, raw: bytes) -> None:
        try:
            t, _, positions = self._js_reader(raw)
        except CdrError as err:
            self.get_logger().error(f"joint states: a message dropped: {err}", throttle_duration_sec=5.0)
            return
        self.monitor.add_positions(t, positions)
        self.results.extend(self.monitor.poll())

    def _on_event(self, msg: CycleEvent) -> None:
        self.monitor.event(msg.event, msg.cycle, time_to_sec(msg.header.stamp))
        self.results.extend(self.monitor.poll())

    # ----------------------------------------------------------------- driving
    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        spin_until(self.executor_, done, timeout, what)

    def call(self, client, request, timeout: float = 10.0, attempts: int = 3):
        """Call a service and return its answer. A request sent just after discovery may lose its answer (the
        server has not matched this client's reply reader yet), so an unanswered request is sent again, up to
        ``attempts`` times, ``timeout`` s each; only for requests that may be repeated."""
        self.spin_until(client.service_is_ready, timeout, f"service {client.srv_name}")
        for attempt in range(1, attempts + 1):
            future = client.call_async(request)
            try:
                self.spin_until(future.done, timeout, f"answer of {client.srv_name}")
            except TimeoutError:
                client.remove_pending_request(future)
                if attempt == attempts:
                    raise
                self.get_logger().warning(f"no answer of {client.srv_name} within {timeout:g} s; asking again")
                continue
            return future.result()
        raise AssertionError("unreachable")

    def wait_ready(self, timeout: float = 30.0, subscribers: dict[str, int] | None = None) -> None:
        """Wait for the services and for the given topics to have at least N subscribers."""
        for cli in (self.set_shaper_cli, self.plant_params_cli, self.start_cli):
            self.spin_until(cli.service_is_ready, timeout, f"service {cli.srv_name}")
        for topic, n in (subscribers or {}).items():
            self.spin_until(functools.partial(self._has_subscribers, topic, n), timeout, f"{n} subscribers on {topic}")

    def _has_subscribers(self, topic: str, n: int) -> bool:
        return self.count_subscribers(topic) >= n

    def subscription_gids(self, topics: tuple[str, ...]) -> set[bytes]:
        """The endpoint GIDs of every subscription of ``topics`` on the graph now."""
        return {bytes(i.endpoint_gid) for topic in topics for i in self.get_subscriptions_info_by_topic(topic)}

    def new_subscriptions(self, topics: tuple[str, ...], before: set[bytes]) -> bool:
        """Whether each of ``topics`` has a subscription not among ``before`` (endpoint GIDs, from
        :meth:`subscription_gids`): a restarted node's inputs are on the graph again."""
        return all(any(bytes(i.endpoint_gid) not in before for i in self.get_subscriptions_info_by_topic(topic))
                   for topic in topics)

    def set_shaper(self, family: str, omega: float = 1.0, zeta: float = 0.0, source: str = "user",
                   **extra) -> SetShaper.Response:
        req = SetShaper.Request()
        req.shaper = ShaperMsg(family=family, source=source, **extra)
        if family not in ("none", "custom"):
            req.shaper.design_modes = [mode_msg(float(omega) / (2.0 * math.pi), float(zeta))]  # omega in rad/s
        resp = self.call(self.set_shaper_cli, req)
        if not resp.success:
            raise RuntimeError(f"shaper refused {family}: {resp.message}")
        return resp

    def set_plant(self, **values) -> None:
        """Set sim plant parameters (names with '.' given as '__', e.g. task__cycles=3)."""
        req = SetParameters.Request()
        req.parameters = [Parameter(k.replace("__", "."), value=v).to_parameter_msg() for k, v in values.items()]
        resp = self.call(self.plant_params_cli, req)
        bad = [r.reason for r in resp.results if not r.successful]
        if bad:
            raise RuntimeError(f"sim plant refused parameters: {bad}")
        if "task__cycles" in values:
            self._task_cycles = int(values["task__cycles"])

    def set_plant_mode(self, omega: float, zeta: float, mass: float = 1.0) -> None:
        """Make every joint of the sim plant an m-c-k system with this mode (rad/s, -)."""
        m, c, k = mck_from_mode(omega, zeta, mass)
        self.set_plant(plant__mass=[m], plant__damping=[c], plant__stiffness=[k])

    def run_cycles(self, cycles: int, timeout: float = 600.0,
                   progress: Callable[[int], None] | None = None) -> list[CycleResult]:
        """Start a run of ``cycles`` cycles on the plant and return their results (``task.cycles`` is set
        when it differs from what this conductor set last: a learner's loop of one-cycle runs sets it once)."""
        if not self.measure:
            raise RuntimeError("run_cycles measures the cycles: this conductor was made with measure=False")
        first = len(self.results)
        self.start_run(cycles, timeout)
        seen = first

        def done() -> bool:
            nonlocal seen
            self.results.extend(self.monitor.poll())  # a cycle whose last samples were lost completes too
            if progress and len(self.results) > seen:
                seen = len(self.results)
                progress(seen - first)
            return len(self.results) >= first + cycles

        self.spin_until(done, timeout, f"{cycles} cycles")
        return self.results[first:]

    def start_run(self, cycles: int, timeout: float = 60.0) -> str:
        """Start a run of ``cycles`` cycles on the plant without waiting for it (``task.cycles`` is set when it
        differs from what this conductor set last). Returns the plant's message."""
        if self._task_cycles != int(cycles):
            self.set_plant(task__cycles=int(cycles))
        return self.start_task(timeout)

    def start_task(self, timeout: float = 60.0) -> str:
        """Start a run on the plant; while the plant waits for its ``task.subscribers`` to match, ask
        again (every 50 ms of spinning, up to ``timeout`` s). Returns the plant's message."""
        end = time.monotonic() + timeout
        while True:
            resp = self.call(self.start_cli, Trigger.Request(), attempts=1)  # not repeatable
            if resp.success:
                return str(resp.message)
            if not resp.message.startswith(WAITING) or time.monotonic() > end:
                raise RuntimeError(f"sim plant did not start: {resp.message}")
            self.spin_until(functools.partial(_past, time.monotonic() + 0.05), 5.0, "the next start request")

    def close(self) -> None:
        self.executor_.shutdown()
        self.destroy_node()


def rms(results: list[CycleResult]) -> float:
    """Mean over cycles of the residual RMS, m/s^2."""
    return float(np.mean([r.residual.rms for r in results]))


def spin_context(domain_id: int | None = None) -> rclpy.context.Context:
    """A fresh rclpy context (optionally on a given ROS domain)."""
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    return ctx


#: ``start(package, executable, params, **kwargs)``: start a node process (what :func:`node_session` yields;
#: kwargs go to NodeProcess: params_file, args, remaps, log_path)
StartNode = Callable[..., Any]


@contextlib.contextmanager
def node_session(logs: pathlib.Path, prefix: str) -> Iterator[tuple[StartNode, rclpy.context.Context]]:
    """Yield ``(start, ctx)``: ``start(package, executable, params)`` starts a node process (log in
    ``logs/<prefix>-<executable>.log``), ``ctx`` a fresh rclpy context; at exit the context is
    shut down and every process started is stopped, all at once.

    Every way the session's process can end stops the nodes: an exception or Ctrl-C leaves the block;
    SIGTERM (in the main thread) is turned into the same ``KeyboardInterrupt`` for the session's time; and
    ``kill -9`` leaves the nodes their parent-death signal (ros/launching.py), a SIGTERM each.
    """
    from shaper_nodes.ros.launching import ChildProcess, NodeProcess

    _SESSION.clear()
    procs: list[ChildProcess] = _SESSION  # the session's waits look at its processes (spin_until)
    previous: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(sig) is not signal.SIG_IGN:  # a background job of a shell ignores SIGINT
                previous[sig] = signal.signal(sig, _interrupt)

    def start(package: str, executable: str, params: dict[str, Any], **kwargs: Any) -> NodeProcess:
        proc = NodeProcess(package, executable, params, log_path=logs / f"{prefix}-{executable}.log", **kwargs)
        procs.append(proc.start())
        return proc

    ctx = spin_context()
    try:
        yield start, ctx
    finally:
        ctx.try_shutdown()
        # all at once (each waits for its own process's shutdown: one after the other took seconds a process)
        with concurrent.futures.ThreadPoolExecutor(max(len(procs), 1)) as pool:
            list(pool.map(lambda proc: proc.stop(), reversed(procs)))
        for num, handler in previous.items():
            signal.signal(num, handler)
        _SESSION.clear()


#: the stop signals a session received (its caller reports an interruption, whatever the exception it ended in:
#: an interrupt raised inside rclpy's wait can surface as another error from the clean-up after it)
RECEIVED: list[int] = []


def interrupted() -> str:
    """The name of the first stop signal a session received ('' if none)."""
    return signal.Signals(RECEIVED[0]).name if RECEIVED else ""


def _interrupt(signum: int, frame: object) -> None:
    """SIGINT or SIGTERM: recorded, then Ctrl-C's ``KeyboardInterrupt``: the session's block is left through its
    ``finally``, which stops the nodes."""
    RECEIVED.append(signum)
    raise KeyboardInterrupt
