"""A goal shaped while the scheduler was paused is not learned from (issue found in session 13's walk; fixed in 14).

Real nodes over DDS, the rig of tests/test_learning_list_kill.py (:class:`Cell`): the scheduler, the shaper node
asking it for each goal's shaper (``action.scheduler``), the iterative LIST per move (no payback rule: the goals go
to the shaper node's proxy) as their own processes; the test's peer plays the robot program (cycle events, goals,
accelerometer) and the controller. The scheduler is paused (SIGSTOP) while one goal is shaped: the shaper node falls
back to its active shaper (family none here: no schedule, no factor) and says so on ``/shaper/shaped_goals``
(shaper_msgs/ShapedGoal, FALLBACK, "no answer from the scheduler: ..."). The learner, which would have measured that
cycle as its move's first trial (its ring as large as the reference's: the move held at the schedule alone after one
cycle it did not run with), skips it with the reason, and the move's next cycle runs the same trial and is learned
from; the cycles before were learned from as usual, each goal's record SCHEDULED.
"""

from __future__ import annotations

import math
import signal
from collections.abc import Callable

import pytest
from test_learning_list_kill import INPUTS, MOVES, RATE, Cell, following, plan, used
from trajectory_msgs.msg import JointTrajectory

from shaper_msgs.msg import CycleEvent, ShapedGoal
from shaper_nodes.ros.qos import SHAPED_GOALS_QOS

pytestmark = pytest.mark.integration

SHAPED = "/shaper/shaped_goals"
#: s, the shaper node's wait for the scheduler (action.server_timeout): the pause outlasts it, well under DDS's lease
SHAPER_TIMEOUT = 6.0


def test_a_goal_shaped_while_the_scheduler_was_paused_is_skipped_with_the_reason(start_node, ros_context, tmp_path):
    cell = Cell(start_node, ros_context, tmp_path / "learner_state.json", "/shaper/follow_joint_trajectory",
                shaper_timeout=SHAPER_TIMEOUT)
    records: list[ShapedGoal] = []  # what the shaper node said of each goal
    cell.peer.node.create_subscription(ShapedGoal, SHAPED, records.append, SHAPED_GOALS_QOS)
    schedule: dict[int, float] = {}

    def ring(move: int) -> Callable[[JointTrajectory], float]:
        """The ring after a goal of the move: smaller with a factor over the schedule (test_learning_list_kill.py)."""
        def amplitude(traj: JointTrajectory) -> float:
            return 0.03 if cell.longer(traj, move) > schedule[move] + 2.0 / RATE + 1e-9 else 0.05
        return amplitude

    def record_of(goal_id: bytes) -> ShapedGoal:
        cell.peer.spin_until(lambda: any(bytes(r.goal_info.goal_id.uuid) == goal_id for r in records),
                             "the shaper node's record of the goal")
        return next(r for r in records if bytes(r.goal_info.goal_id.uuid) == goal_id)

    try:
        cell.peer.spin_until(lambda: cell.peer.learner_up((*INPUTS, SHAPED), set()), "the learner's subscriptions")
        cell.wait_started(0, 1)
        schedule.update({m: float(cell.ask(m, False)[1][-1]) for m in (0, 1)})
        reports = [cell.run(cycle, move, ring(move))[0] for cycle, move in ((0, 0), (1, 1), (2, 0))]
        assert [r["iteration"] for r in reports] == [1.0, 1.0, 2.0], reports
        assert math.isnan(reports[1]["a1_used"]) and not math.isnan(reports[1]["a1_next"]), reports[1]

        # pick -> home's first trial: its goal shaped while the scheduler is paused
        cell.event(CycleEvent.START, 3, cell.start(3), 1)
        cell.scheduler.proc.send_signal(signal.SIGSTOP)
        try:
            handle = cell.peer.send(plan(1), "the goal of cycle 3")
        finally:
            cell.scheduler.proc.send_signal(signal.SIGCONT)
        done = handle.get_result_async()
        cell.peer.spin_until(done.done, "the result of the goal of cycle 3")
        sent = cell.peer.goals[-1]
        assert ring(1)(sent) == 0.05  # no factor, no schedule: the active shaper (none)
        rec = record_of(bytes(handle.goal_id.uuid))
        assert rec.shaped_with == ShapedGoal.FALLBACK, rec
        assert rec.detail.startswith("no answer from the scheduler"), rec.detail
        assert list(rec.joint_names) == ["j1", "j2"] and list(rec.goal_positions) == MOVES[1][1], rec
        assert rec.shaper.family == "none" and rec.shaper.revision >= 1, rec.shaper
        assert cell.finish(3, 1, ring(1)(sent)) == {"skipped": 1.0}
        line = "cycle 3 not learned from: its goal was shaped with the active shaper (parameters, revision 1), not" \
               " for its final pose: no answer from the scheduler"
        cell.peer.spin_until(lambda: any(got.startswith(line) for got in cell.peer.logs), "the learner's line")

        # the cycles after are learned from: pick -> home's trial runs again, with the factor cycle 3 was to run
        got, after = cell.run(4, 1, ring(1))
        assert got["iteration"] == 2.0 and got["held"] == 0.0, got
        assert used(got) == pytest.approx(following(reports[1]), rel=1e-12), got
        assert ring(1)(after) == 0.03
        got, _ = cell.run(5, 0, ring(0))
        assert got["iteration"] == 3.0 and got["held"] == 0.0, got
        cell.peer.spin_until(lambda: len(records) >= 6, "the records of the six goals")
        assert [r.shaped_with for r in records] == [ShapedGoal.SCHEDULED] * 3 + [ShapedGoal.FALLBACK] + \
            [ShapedGoal.SCHEDULED] * 2, records
    finally:
        cell.close()
