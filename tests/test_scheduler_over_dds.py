"""The scheduler node over DDS: seed 004's comparison through the graph, and the learner policy.

The reproduction runs sim plant, shaper and scheduler as separate processes in lockstep. The
policy test runs the scheduler in-process with the real shaper node as a subprocess, a probe
that publishes joint states, and a peer that speaks the learner's side of the interface
(``/scheduler/set_shaper`` with source "learner", ``/scheduler/active_shaper``) and asks
``/scheduler/shaper_at`` for the shaper at other poses.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time

import numpy as np
import pytest
from conftest import call_answered
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from reproductions.scheduler_cases import CASES, run_case
from reproductions.scheduler_rules import rule_base_spec, scheduler_parameters
from shaper_msgs.msg import ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper, ShaperAt
from shaper_nodes.core.scheduling import Scheduler, rule_base_from_dict
from shaper_nodes.core.scheduling.fuzzy import modes_of
from shaper_nodes.core.shaping.families import Mode, design
from shaper_nodes.nodes.scheduler import SchedulerNode
from shaper_nodes.ros.qos import LATCHED
from sim_plant_node.models.two_mass import m1_of, two_mass_matrices

pytestmark = pytest.mark.integration
PAUSE = 1.0  # s of SIGSTOP of the scheduler
PAUSED_STEPS = 3  # of the five: the pause at the end of the first


def test_fuzzy_scheduled_zv_beats_fixed_and_switched_at_every_step(start_node, ros_context):
    runs = {}
    for name in ("a", "b", "c"):  # each case with its own processes, stopped before the next
        procs = []
        start = lambda *a, procs=procs: procs.append(start_node(*a)) or procs[-1]  # noqa: E731
        runs[name] = run_case(CASES[name], start, ros_context, commands=False)  # (v_shaped: only the docs' plot)
        for proc in reversed(procs):
            assert proc.stop() == 0
    a, b, c = (runs[n].residual for n in ("a", "b", "c"))
    assert a.size == b.size == c.size == 5
    assert np.all(c < a) and np.all(c < b), (a, b, c)
    assert a.sum() >= 5 * c.sum(), (a.sum(), c.sum())
    for name in ("b", "c"):  # the first step already ran with a scheduled shaper
        first_step = runs[name].step_times[0]
        before = [src for t, src, _ in runs[name].sources if t <= first_step]
        assert before and before[-1] == "scheduler", runs[name].sources[:3]
        assert runs[name].mode_t.size > 0


def test_a_paused_scheduler_retunes_the_shaper_at_the_same_steps(start_node, ros_context):
    """The scheduler is a lockstep reader of the plant (its parameter ``lockstep``, the plant's ``lockstep.readers``):
    case (c) with the scheduler's process paused (SIGSTOP) for 1 s of wall time as the first step ends gives the
    unpaused run's residuals and mode estimates, to the last digit (before session 13's H5, a paused scheduler
    retuned the shaper seconds of simulated time late: 55.8 mm at step 2 against 1.6). The first three of the
    five steps: the one the pause ends, the one whose retune it would delay, and one after."""
    runs = []
    for pause in (False, True):
        procs: dict[str, object] = {}

        def start(package, executable, params, procs=procs):
            procs[executable] = start_node(package, executable, params)
            return procs[executable]

        def progress(line: str, pause=pause, procs=procs) -> None:
            if pause and line.startswith("step 1 "):
                pid = procs["scheduler"].proc.pid
                os.kill(pid, signal.SIGSTOP)  # the fault injected (no assertion on timing)
                threading.Timer(PAUSE, os.kill, (pid, signal.SIGCONT)).start()

        runs.append(run_case(CASES["c"], start, ros_context, progress=progress, commands=False, steps=PAUSED_STEPS))
        for proc in reversed(procs.values()):
            assert proc.stop() == 0
    quiet, paused = runs
    assert quiet.residual.size == PAUSED_STEPS and np.all(np.isfinite(quiet.residual)), quiet.residual
    assert paused.residual.tolist() == quiet.residual.tolist()  # the same motion: every retune at the same step
    # the scheduler's mode estimates are stamped with the poses they were evaluated at: the same at every pose both
    # runs' recorders took (its topic is latched, depth 1: a recorder may miss some, and the active shaper's stamps
    # are the shaper's clock when the request came, not the step it took effect at)
    modes = [dict(zip(run.mode_t.tolist(), run.mode_omega.tolist(), strict=True)) for run in runs]
    common = sorted(set(modes[0]) & set(modes[1]))
    assert len(common) > 100 and all(modes[0][t] == modes[1][t] for t in common), len(common)


class Peer(Node):
    """Publishes joint states and speaks the learner's side of the scheduler's interface."""

    def __init__(self, context) -> None:
        super().__init__("peer", context=context)
        self.js = self.create_publisher(JointState, "/joint_states", 10)
        self.cli = self.create_client(SetShaper, "/scheduler/set_shaper")
        self.at = self.create_client(ShaperAt, "/scheduler/shaper_at")
        self.active: list[ShaperMsg] = []
        self.real: list[ShaperMsg] = []
        self.modes: list[ModeEstimate] = []
        self.create_subscription(ShaperMsg, "/scheduler/active_shaper", self.active.append, LATCHED)
        self.create_subscription(ShaperMsg, "/shaper/active_shaper", self.real.append, LATCHED)
        self.create_subscription(ModeEstimate, "/scheduler/mode_estimate", self.modes.append, LATCHED)

    def pose(self, x: float, names=("joint_1",)) -> None:
        self.js.publish(JointState(name=list(names), position=[x] * len(names)))


def spin_until(ex, done, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        ex.spin_once(timeout_sec=0.02)


def shaper_at(peer, ex, names, positions) -> ShaperAt.Response:
    return call_answered(ex, peer.at, ShaperAt.Request(pose=JointState(name=list(names), position=list(positions))),
                         "shaper_at")


def true_mode(x: float) -> Mode:
    return modes_of(two_mass_matrices(float(m1_of(x)))[0])[0]


@pytest.fixture
def graph(start_node, ros_context):
    start_node("shaper_nodes", "shaper_node", {"joint_names": ["joint_1"], "command_rate": 100.0,
                                               "retime_sources": ["scheduler"]})
    params = scheduler_parameters(rule_base_spec(np.linspace(0.0, 0.7, 8)))
    params.update({"min_interval": 0.0, "period": 0.02, "stale_timeout": 3600.0, "error_throttle": 0.0})
    sched = SchedulerNode(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    peer = Peer(ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(sched)
    ex.add_node(peer)
    spin_until(ex, lambda: (peer.cli.service_is_ready() and sched.shaper.service_is_ready()
                            and peer.at.service_is_ready()), 30.0, "services")
    yield sched, peer, ex
    ex.shutdown()
    peer.destroy_node()
    sched.destroy_node()


def settle_at(sched, peer, ex, x: float) -> ShaperMsg:
    """Publish pose x until the shaper node's active shaper is the scheduler's for x."""
    sent = sched.sent

    def done():
        peer.pose(x)
        return sched.sent > sent and peer.real and peer.real[-1].revision >= 2 and sched._interp is not None \
            and abs(sched._interp.z[0] - min(max(x, 0.0), 0.7)) < 1e-12 and not sched._pending
    spin_until(ex, done, 30.0, f"the scheduled shaper at x0 = {x}")
    spin_until(ex, lambda: peer.active and peer.active[-1].revision == peer.real[-1].revision, 10.0, "mirror")
    return peer.real[-1]


def test_scheduled_mode_follows_the_pose_and_out_of_range_is_clamped(graph):
    sched, peer, ex = graph
    for x in (0.05, 0.3, 0.65):
        active = settle_at(sched, peer, ex, x)
        assert active.source == "scheduler" and active.family == "zv"
        hz = active.design_modes[0].frequency_hz
        assert hz == pytest.approx(true_mode(x).hz, rel=0.07)  # interpolation error, docs/design/scheduler.md
        est = peer.modes[-1].modes[0]
        assert est.frequency_hz == pytest.approx(hz, rel=0.011)  # sent when it moved by 1 %
    active = settle_at(sched, peer, ex, 1.5)  # beyond the rule base: clamped at 0.7, not extrapolated
    assert sched._interp.clamped == (True,)
    assert active.design_modes[0].frequency_hz == pytest.approx(true_mode(0.7).hz, rel=1e-9)
    # bad joint states are refused, the node keeps going
    refused = sched.refused
    peer.pose(0.2, names=("elbow",))
    peer.js.publish(JointState(name=["joint_1"], position=[math.nan]))
    # the feed is taken serialized: bytes that are not a JointState (cut short) are refused, not a crash
    peer.js.publish(serialize_message(JointState(name=["joint_1"], position=[0.2]))[:20])
    spin_until(ex, lambda: sched.refused >= refused + 3, 10.0, "the refusals")
    settle_at(sched, peer, ex, 0.2)


def test_the_learner_correction_is_kept_per_region_and_reapplied(graph):
    sched, peer, ex = graph
    settle_at(sched, peer, ex, 0.1)
    scheduled = design("zv", [Mode(sched._interp.modes[0].omega, sched._interp.modes[0].zeta)])
    # the learner found T2 8 % longer and A1 a little lower than the scheduled ZV at x0 = 0.1
    a1, t2 = 0.97 * scheduled.amplitudes[0], 1.08 * scheduled.times[1]
    req = SetShaper.Request(shaper=ShaperMsg(family="custom", amplitudes=[a1, 1 - a1], times=[0.0, t2],
                                             source="learner"))
    future = peer.cli.call_async(req)
    spin_until(ex, future.done, 30.0, "the learner's request")
    resp = future.result()
    assert resp.success, resp.message
    assert "correction of region x1" in resp.message
    spin_until(ex, lambda: peer.real and peer.real[-1].source == "learner", 10.0, "the learner's shaper")
    np.testing.assert_allclose(peer.real[-1].times, [0.0, t2], rtol=1e-12)  # forwarded as the learner sent it
    # away to another region: the scheduled mode there, uncorrected (no correction learned there)
    far = settle_at(sched, peer, ex, 0.6)
    assert far.family == "zv"
    # back: the correction of region x1 is applied to the scheduled shaper again
    back = settle_at(sched, peer, ex, 0.1)
    assert back.source == "scheduler" and back.family == "custom"
    np.testing.assert_allclose(back.times, [0.0, t2], rtol=1e-9)
    np.testing.assert_allclose(back.amplitudes, [a1, 1 - a1], rtol=1e-9)
    at = shaper_at(peer, ex, ["joint_1"], [0.1])  # ~/shaper_at gives the corrected shaper there too
    assert at.success and at.shaper.family == "custom" and "(region x1)" in at.message
    np.testing.assert_allclose(at.shaper.times, [0.0, t2], rtol=1e-9)
    # other sources are not taken here (they set the shaper node directly)
    future = peer.cli.call_async(SetShaper.Request(shaper=ShaperMsg(family="zv", source="user")))
    spin_until(ex, future.done, 10.0, "the refusal")
    assert not future.result().success and "learner only" in future.result().message


def test_the_real_learner_speaks_to_the_scheduler(graph, start_node):
    """The learner node pointed at the scheduler (shaper: /scheduler): without a saved state it
    starts with the identity shaper (its unshaped reference cycle); the scheduler forwards it to
    the shaper node, mirrors it on ~/active_shaper, and holds the schedule meanwhile."""
    sched, peer, ex = graph
    settle_at(sched, peer, ex, 0.3)
    start_node("shaper_nodes", "learner", {"shaper": "/scheduler"})
    spin_until(ex, lambda: peer.real and peer.real[-1].source == "learner", 60.0, "the learner's first shaper")
    assert peer.real[-1].family == "none"
    spin_until(ex, lambda: peer.active and peer.active[-1].revision == peer.real[-1].revision, 10.0, "mirror")
    sent = sched.sent
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:  # the pose moves, but the learner's reference cycle holds
        peer.pose(0.6)
        ex.spin_once(timeout_sec=0.02)
    assert sched.sent == sent and peer.real[-1].source == "learner"


def test_shaper_at_gives_the_schedules_shaper_at_any_pose_and_sends_nothing(graph):
    sched, peer, ex = graph
    settle_at(sched, peer, ex, 0.1)
    sent, revision, here = sched.sent, peer.real[-1].revision, peer.modes[-1].modes[0].frequency_hz
    core = Scheduler(rule_base_from_dict(rule_base_spec(np.linspace(0.0, 0.7, 8))), "model", "zv")
    for x, where in ((0.05, 0.05), (0.45, 0.45), (1.5, 0.7)):  # 1.5 is clamped to the range's end, 0.7
        resp = shaper_at(peer, ex, ["elbow", "joint_1"], [9.0, x])  # other joints are ignored
        assert resp.success, resp.message
        interp, expected = core.at([where])
        assert resp.shaper.family == expected.family == "zv" and resp.shaper.source == "scheduler"
        np.testing.assert_allclose(resp.shaper.times, expected.times, rtol=1e-12)
        np.testing.assert_allclose(resp.shaper.amplitudes, expected.amplitudes, rtol=1e-12)
        assert [(m.frequency_hz, m.damping_ratio) for m in resp.shaper.design_modes] == \
            [(pytest.approx(m.hz, rel=1e-12), m.zeta) for m in interp.modes]
        assert [(m.frequency_hz, m.damping_ratio) for m in resp.estimate.modes] == \
            [(pytest.approx(m.hz, rel=1e-12), m.zeta) for m in interp.modes]
        assert resp.estimate.source == "scheduler" and f"joint_1 = {x:.6g}" in resp.message
        assert ("joint_1 = 1.5 outside [0, 0.7]: clamped, not extrapolated" in resp.message) == (x == 1.5)
    for names, positions, words in ((["elbow"], [0.2], "missing premise joints ['joint_1']"),
                                    (["joint_1"], [math.nan], "non-finite premise values: joint_1 = nan"),
                                    (["joint_1", "elbow"], [0.2], "1 positions for 2 names"),
                                    (["joint_1", "joint_1"], [0.2, 0.3], "named more than once: ['joint_1']")):
        resp = shaper_at(peer, ex, names, positions)
        assert not resp.success and words in resp.message, resp.message
        assert not resp.shaper.times and not resp.estimate.modes
    # nothing went to the shaper node, and the schedule is still at the pose of the joint states
    spin_until(ex, lambda: not sched._pending, 10.0, "no request in flight")
    assert sched.sent == sent and peer.real[-1].revision == revision
    assert peer.modes[-1].modes[0].frequency_hz == here


def test_joint_states_published_with_an_incompatible_qos_are_reported(ros_context):
    """The 500 Hz feed has no middleware event handlers (their waitables cost every wait): a publisher of the joint
    states that never matches (here best effort, the scheduler's subscription reliable) is found on the graph and
    reported on /diagnostics with the topic; a matching publisher's poses then reach the schedule."""
    from conftest import Diagnosed
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rule = {"membership": ["triangular"], "frequency_hz": [10.0], "damping_ratio": [0.05]}
    overrides = [Parameter(k, value=v) for k, v in {"premises": ["joint_1"], "rule_names": ["low", "high"],
                                                    "interpolation": "modes", "period": 0.02,
                                                    "stale_timeout": 3600.0, "error_throttle": 0.0}.items()]
    for name, peak, hz in (("low", 0.0, 10.0), ("high", 1.0, 20.0)):
        overrides += [Parameter(f"rules.{name}.{k}", value=v) for k, v in rule.items()]
        overrides += [Parameter(f"rules.{name}.membership_params", value=[peak - 1.0, peak, peak + 1.0]),
                      Parameter(f"rules.{name}.frequency_hz", value=[hz])]
    node = SchedulerNode(context=ros_context, parameter_overrides=overrides)
    probe = Node("probe", context=ros_context)
    diag = Diagnosed(probe)
    modes: list[ModeEstimate] = []
    probe.create_subscription(ModeEstimate, "/scheduler/mode_estimate", modes.append, 10)
    probe.create_publisher(JointState, "/joint_states", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (node, probe):
        ex.add_node(n)

    try:
        spin_until(ex, lambda: diag.find("scheduler", "none matched"), 60.0, "the report of the unmatched publisher")
        status = diag.find("scheduler", "none matched")
        assert "/joint_states" in status.message and "incompatible QoS" in status.message
        assert not modes  # nothing came through the unmatched publisher
        reliable = probe.create_publisher(JointState, "/joint_states", 10)

        def pose() -> bool:
            reliable.publish(JointState(name=["joint_1"], position=[0.5]))
            return True

        spin_until(ex, lambda: pose() and modes, 60.0, "a mode estimate from the matching publisher's pose")
        assert modes[-1].modes[0].frequency_hz == pytest.approx(15.0)  # between the rules' 10 and 20 Hz
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()


def test_a_dead_joint_state_feed_is_stale_a_live_one_on_fast_simulated_time_is_not(ros_context):
    """stale_timeout counts on the node's clock and on the steady clock: on simulated time running 100 times
    faster than the wall clock (a lockstep plant), joint states that keep coming but arrive seconds of simulated
    time apart (a feed thread a few milliseconds late) are not stale; a feed that stops is, once stale_timeout
    passed on both clocks."""
    from conftest import Diagnosed
    from rosgraph_msgs.msg import Clock as ClockMsg
    from std_msgs.msg import Header

    from shaper_nodes.ros.conversions import sec_to_time

    rule = {"membership": ["triangular"], "frequency_hz": [10.0], "damping_ratio": [0.05]}
    overrides = [Parameter(k, value=v) for k, v in {"premises": ["joint_1"], "rule_names": ["low", "high"],
                                                    "interpolation": "modes", "period": 0.02, "use_sim_time": True,
                                                    "stale_timeout": 2.0, "error_throttle": 1.0}.items()]
    for name, peak in (("low", 0.0), ("high", 1.0)):
        overrides += [Parameter(f"rules.{name}.{k}", value=v) for k, v in rule.items()]
        overrides += [Parameter(f"rules.{name}.membership_params", value=[peak - 1.0, peak, peak + 1.0])]
    node = SchedulerNode(context=ros_context, parameter_overrides=overrides)
    probe = Node("probe", context=ros_context)
    diag = Diagnosed(probe)
    modes: list[ModeEstimate] = []
    probe.create_subscription(ModeEstimate, "/scheduler/mode_estimate", modes.append, 100)
    clock = probe.create_publisher(ClockMsg, "/clock", 10)
    js = probe.create_publisher(JointState, "/joint_states", 10)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (node, probe):
        ex.add_node(n)

    def advance(t: float) -> None:  # simulated time jumps 5 s: the scheduler's clock and its period timer follow
        clock.publish(ClockMsg(clock=sec_to_time(t)))
        spin_until(ex, lambda: node._now() >= t, 60.0, f"the scheduler's clock at {t:g} s")

    evaluated: list[tuple[float, bool]] = []  # (node clock s, not stale) of every evaluation of the rule base
    evaluate = node._evaluate

    def counted():
        had_pose = node._pose is not None
        interp = evaluate()
        if had_pose:
            evaluated.append((node._now(), interp is not None))
        return interp

    node._evaluate = counted
    try:
        spin_until(ex, lambda: clock.get_subscription_count() > 0 and js.get_subscription_count() > 0,
                   60.0, "the subscribers")
        t = 1.0
        advance(t)
        for step in range(10):  # live: a joint state at every jump, evaluated after the next jump
            stamp = sec_to_time(t)
            before = node._pose
            js.publish(JointState(header=Header(stamp=stamp), name=["joint_1"], position=[0.5]))
            spin_until(ex, lambda before=before: node._pose is not before, 60.0, f"joint state {step}")
            t += 5.0
            advance(t)
            spin_until(ex, lambda t=t: any(at >= t for at, _ in evaluated),
                       60.0, f"an evaluation after the jump to {t:g} s")
            assert all(fresh for _, fresh in evaluated), f"stale at step {step}: {evaluated}"
        assert node.diagnostics.counts["stale"] == 0 and modes
        # dead: no more joint states, simulated time goes on: stale once 2 s passed on both clocks
        deadline = time.monotonic() + 60.0
        while not node.diagnostics.counts["stale"]:
            assert time.monotonic() < deadline, "no stale report within 60 s of a dead feed"
            t += 5.0
            advance(t)
            spin_until(ex, lambda t=t: any(at >= t for at, _ in evaluated),
                       60.0, f"an evaluation after the jump to {t:g} s")
        assert not evaluated[-1][1]
        spin_until(ex, lambda: diag.find("scheduler", "no joint states"), 60.0, "the stale report on /diagnostics")
        assert "stale_timeout (2 s of the node's clock and of the steady clock)" in \
            diag.find("scheduler", "no joint states").message
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()
