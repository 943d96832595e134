"""LIST per move with no calibration over DDS: the arm demo's ``list_moves`` case on a small plan, all real nodes.

The case's own set-up (:func:`sim_plant_node.clients.arm_cases.apply_case` with ``list_moves``): a scheduler of
family ``none`` (no mode shaped) that only keeps each move's factor, the shaper node again on it (its proxy asks it
for every goal), and the learner's LIST per move with ``list.start: identified``. The client is the demo's
(:class:`~sim_plant_node.clients.arm_demo.ArmClient`: every move its own cycle on ``/cycle_events``), the sim arm in
lockstep. Two moves, home -> pick and back, three cycles: each move's first cycle is its unshaped reference; the
learner starts its factor from the mode identified there (not from a schedule: there is none) and the scheduler
gives that factor to the move's next goal.
"""

from __future__ import annotations

import functools
import json
import math

import pytest
from sensor_msgs.msg import JointState

from shaper_msgs.srv import ShaperAt
from sim_plant_node.arm.description import JOINT_NAMES
from sim_plant_node.arm.task import HOME, PICK, trapezoid_move
from sim_plant_node.clients.arm_cases import NO_SCHEDULE, Session, apply_case
from sim_plant_node.clients.arm_demo import ArmClient, _learned
from sim_plant_node.clients.conductor import Conductor

pytestmark = pytest.mark.integration
RATE = 500.0
MOVES = [trapezoid_move("home->pick", HOME, PICK), trapezoid_move("pick->home", PICK, HOME)]
CYCLES = 3


def metrics(report: object) -> dict[str, float]:
    return dict(zip(report.metric_names, report.metric_values, strict=True))  # type: ignore[attr-defined]


def test_list_per_move_with_no_calibration_starts_each_move_from_its_identified_mode(start_node, ros_context):
    start_node("sim_plant_node", "sim_plant", {"plant.model": "arm", "task.start": HOME.tolist(), "rate": RATE,
                                               "imu.noise_stddev": 0.01, "lockstep.readers": ["/conductor"]})
    shaper_params = {"joint_names": list(JOINT_NAMES), "command_rate": RATE, "use_sim_time": True,
                     "action.server_timeout": 30.0}
    session = Session(start_node, start_node("shaper_nodes", "shaper_node", shaper_params), shaper_params)
    conductor = Conductor(context=ros_context)
    client = ArmClient(conductor)
    reports: list[list[dict[str, float]]] = []
    try:
        client.wait_ready(1)
        installed = apply_case("list_moves", client, None, None, session)
        assert "no calibration" in installed
        first = 0
        for _ in range(CYCLES):
            client.run_cycle_per_move(first, MOVES, lambda: None, functools.partial(_learned, client))
            reports.append([metrics(_learned(client, first + i)) for i in range(len(MOVES))])
            first += len(MOVES)
        # what the scheduler gives each move's goal now: its learned factor over no schedule
        shaper_at = conductor.create_client(ShaperAt, f"{NO_SCHEDULE}/shaper_at")
        given = []
        for mv in MOVES:
            req = ShaperAt.Request(pose=JointState(name=list(JOINT_NAMES), position=mv.positions[-1].tolist()),
                                   start=JointState(name=list(JOINT_NAMES), position=mv.positions[0].tolist()))
            given.append(conductor.call(shaper_at, req, timeout=60.0))
    finally:
        conductor.close()
        print("reports per cycle and move:", json.dumps(reports, default=float))

    for k, cycle in enumerate(reports):
        for m in cycle:
            assert "skipped" not in m, (k, m)
    # cycle 1: the reference (unshaped: no factor used), a factor learned from the mode identified in it
    for m in reports[0]:
        assert math.isnan(m["a1_used"]) and math.isnan(m["t2_used"]), m
        assert 0.5 <= m["a1_next"] < 1.0 and m["t2_next"] > 0.0, m
    # cycle 2: each move's goal ran with that factor (the scheduler gave it to the shaper node's proxy)
    for before, after in zip(reports[0], reports[1], strict=True):
        assert after["a1_used"] == pytest.approx(before["a1_next"], rel=1e-6), (before, after)
        assert after["t2_used"] == pytest.approx(before["t2_next"], rel=1e-6), (before, after)
    # the scheduler's answer for each move: the learned factor alone (two impulses; family none: no mode shaped)
    for resp, last in zip(given, reports[-1], strict=True):
        assert resp.success, resp.message
        assert len(resp.shaper.times) == 2, resp.message
        assert "learned factor" in resp.message, resp.message
        assert resp.shaper.times[1] == pytest.approx(last["t2_next"], rel=1e-6) or last["held"] == 1.0, \
            (resp.message, last)
