"""Fixtures for launch-free integration tests: real nodes over real DDS, isolated per test.

Every test gets its own ROS domain (so leftovers of one test never talk to the next), a fresh
rclpy Context for in-process nodes, and a helper that starts installed node executables as
subprocesses on that domain and stops them at teardown.
"""

from __future__ import annotations

import gc
import itertools
import os
import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.task import Future

from shaper_msgs.srv import GetShaper, SetFeedforward, SetShaper
from shaper_nodes.ros.launching import NodeProcess

_counter = itertools.count()
#: domains 1 .. DOMAINS (the root conftest.py's range)
DOMAINS = 200


def new_domain() -> int:
    """A ROS domain no test has had in this process yet (until the 200 wrap): the base, then every stride-th.

    Under pytest-xdist the root conftest.py gives each worker a base and a stride of its own
    (``ROS_DOMAIN_ID``, ``SHAPER_DOMAIN_STRIDE``), so the tests running at once on different workers never
    share a domain; without xdist the stride is 1, the domains of a run follow each other from the base.
    """
    base = int(os.environ.get("ROS_DOMAIN_ID", "30"))
    stride = int(os.environ.get("SHAPER_DOMAIN_STRIDE", "1"))
    return 1 + (base + stride * next(_counter)) % DOMAINS


@pytest.fixture
def domain_id() -> int:
    return new_domain()


@pytest.fixture
def another_domain_id(domain_id) -> int:
    """A second domain of the test's own, for a test that runs two things apart at once or in turn."""
    return new_domain()


@pytest.fixture
def ros_context(domain_id):
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    yield ctx
    gc.collect()  # the test's nodes and executors are freed while their context is valid (and conftest.py)
    ctx.try_shutdown()


@pytest.fixture
def start_node(domain_id, tmp_path):
    procs: list[NodeProcess] = []

    def start(package: str, executable: str, params: dict | None = None, **kwargs) -> NodeProcess:
        """Start a node (kwargs go to NodeProcess: params_file, args, remaps)."""
        log = tmp_path / f"{executable}-{len(procs)}.log"
        proc = NodeProcess(package, executable, params or {}, log_path=log,
                           env={"ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
                           **kwargs)
        procs.append(proc.start())
        return proc

    yield start
    for proc in reversed(procs):
        proc.stop()


class Starter:
    """start_node, remembering the processes so that a run's nodes can be stopped before the next."""

    def __init__(self, start_node):
        self.start_node, self.procs = start_node, []

    def __call__(self, package, executable, params):
        proc = self.start_node(package, executable, params)
        self.procs.append(proc)
        return proc

    def stop_all(self):
        for proc in reversed(self.procs):
            began = time.monotonic()
            code = proc.stop()
            # -9: it did not end within stop()'s 10 s of its SIGINT (seen once under load: say which, and its log)
            assert code == 0, (proc.cmd[0], code, f"{time.monotonic() - began:.1f} s", proc.log_path)
        self.procs = []


@pytest.fixture
def starter(start_node) -> Starter:
    """Like start_node, with ``stop_all()`` to stop the nodes started so far."""
    return Starter(start_node)


class SilentShaper(Node):
    """Plays a shaper node whose replies are lost: it takes ``~/set_shaper`` and ``~/get_shaper``
    requests (and counts them) but never answers, as when a reply is dropped before DDS has matched
    the reply reader, or the node is stuck. Optionally it also plays an injection point that does
    answer (``/sim_plant/set_feedforward``), for the MRILC learner."""

    def __init__(self, context, feedforward: bool = False) -> None:
        super().__init__("shaper", context=context)
        self.requests: list = []
        self.feedforward: list = []
        self._never = Future()  # never done: the replies are never sent
        group = ReentrantCallbackGroup()
        self.create_service(SetShaper, "~/set_shaper", self._swallow, callback_group=group)
        self.create_service(GetShaper, "~/get_shaper", self._swallow, callback_group=group)
        if feedforward:
            self.create_service(SetFeedforward, "/sim_plant/set_feedforward", self._on_feedforward)

    async def _swallow(self, request, response):
        self.requests.append(request)
        await self._never
        return response

    def _on_feedforward(self, request, response):
        self.feedforward.append(request)
        response.success, response.message = True, "installed"
        return response


class Diagnosed:
    """Collects /diagnostics statuses."""

    def __init__(self, node: Node) -> None:
        self.statuses: list = []
        node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.statuses.extend(m.status), 100)

    def find(self, node_name: str, words: str):
        """The first status of ``node_name`` whose message contains ``words`` (None if none yet)."""
        return next((s for s in self.statuses if s.name.startswith(f"{node_name}:") and words in s.message), None)


def start_scheduled_arm(start_node, rule_base, rate: float, readers: list[str], **shaper) -> None:
    """The arm in lockstep (waiting for ``readers``), the scheduler on ``rule_base`` (ZV, modes interpolated)
    and the shaper node asking it, all on simulated time: the per-move learners' rig. ``shaper`` adds to the
    shaper node's parameters (e.g. ``action.controller``)."""
    from reproductions.scheduler_cases import scheduler_parameters
    from sim_plant_node.arm.description import JOINT_NAMES
    from sim_plant_node.arm.task import HOME

    start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME.tolist(), "rate": rate,
                                               "lockstep.readers": readers})
    start_node("shaper_nodes", "scheduler", {**scheduler_parameters(rule_base), "interpolation": "modes",
                                             "family": "zv", "use_sim_time": True})
    start_node("shaper_nodes", "shaper_node", {"joint_names": list(JOINT_NAMES), "command_rate": rate,
                                               "use_sim_time": True, "action.server_timeout": 30.0,
                                               "action.scheduler": "/scheduler", **shaper})


def restart_learner(start_node, learner, params: dict, conductor, inputs: tuple[str, ...]) -> None:
    """``kill -9`` the learner (a NodeProcess) and start it again with ``params`` (the same state file); returns
    once its subscriptions of ``inputs`` are on ``conductor``'s graph again."""
    before = conductor.subscription_gids(inputs)
    assert learner.proc is not None
    learner.proc.kill()
    learner.proc.wait(timeout=30)
    start_node("shaper_nodes", "learner", params)
    conductor.spin_until(lambda: conductor.new_subscriptions(inputs, before), 120.0,
                         f"the restarted learner's subscriptions of {', '.join(inputs)}")


def run_move_cycle(client, cycle: int, index: int, move, wait: float):
    """One move of a per-move learner's run as its own cycle: the move through ``client`` (an ArmClient) with
    START, MOTION_END (at the planned end) and END on /cycle_events, each naming the move by its start and goal;
    returns the move's result and the metrics (name -> value) of the learner's report of ``cycle``, waited for up
    to ``wait`` s."""
    from shaper_msgs.msg import CycleEvent
    from shaper_nodes.ros.conversions import sec_to_time
    from sim_plant_node.arm.description import JOINT_NAMES

    def event(kind: int, t: float) -> None:
        msg = CycleEvent(event=kind, cycle=cycle, task="per_move", joint_names=list(JOINT_NAMES),
                         start_positions=move.positions[0].tolist(), goal_positions=move.positions[-1].tolist())
        msg.header.stamp = sec_to_time(t)
        client.events.publish(msg)

    def report():
        return next((r for r in reversed(client.reports) if r.cycle == cycle), None)

    r = client.run_move(index, move, lambda t: event(CycleEvent.START, t))
    event(CycleEvent.MOTION_END, r.start + r.planned)
    event(CycleEvent.END, r.end)
    client.c.spin_until(lambda: report() is not None, wait, f"the learner's report of cycle {cycle}")
    got = report()
    return r, dict(zip(got.metric_names, got.metric_values, strict=True))
