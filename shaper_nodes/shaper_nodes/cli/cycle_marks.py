"""send_goal's ``--cycle``: one goal marked as one cycle on /cycle_events (START, MOTION_END, END).

Goals sent through the learner's proxy are marked by the learner, and the suite's task runners mark
their own; an owner moving the robot with a goal of their own has nothing that tells the learner per
move, the identifier or a recorder where the move starts and ends. ``send_goal --cycle N`` marks its
goal as cycle N of task ``--task``: the events name the joints, the pose the move starts from (the
joint states) and its goal, and are stamped on the clock of the joint states (the robot's, or the
simulator's simulated time: no ``use_sim_time`` needed), as the CycleEvent message says:

- START at the stamp of the latest joint state before the goal is sent (a lockstep simulator at rest
  republishes its last state and does not step between goals, so this is when the goal's motion starts;
  on a robot the controller starts it a few milliseconds later; a simulator's first goal starts at 0,
  which the analysis takes as time 0 among stamped events, not as "no stamp"),
- MOTION_END ``--duration`` s later (the unshaped command reaches the goal),
- END ``--duration + --hold`` s after START (the goal's last point: the hold is the cycle's residual
  window, so ``--cycle`` needs ``--hold`` > 0).

START goes out before the goal (once a subscriber of the events topic has matched, or after
``--timeout`` with a warning that nobody listens); MOTION_END and END once the goal succeeded, and the
command waits (bounded) until every subscriber has acknowledged them. A goal that does not succeed
gets no MOTION_END and END: the learner drops the unfinished cycle at the next START.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: default topic of the marks
EVENTS = "/cycle_events"
#: the marks' queue depth (reliable, volatile: as the learner and the identifier subscribe)
DEPTH = 10


@dataclass(frozen=True)
class CycleSpec:
    """What ``--cycle`` asked for: the cycle index, the task's name, the topic."""

    cycle: int
    task: str
    topic: str = EVENTS


class CycleMarks:
    """Publishes one goal's START, MOTION_END and END (module docstring) from ``node``."""

    def __init__(self, node: Any, spec: CycleSpec, joints: Sequence[str], joint_states: str) -> None:
        from sensor_msgs.msg import JointState

        from shaper_msgs.msg import CycleEvent

        self.node, self.spec, self.joints = node, spec, list(joints)
        self.msg = CycleEvent
        self.pub = node.create_publisher(CycleEvent, spec.topic, DEPTH)
        #: the latest joint state's stamp, s (the clock the marks are stamped on)
        self.latest = 0.0
        node.create_subscription(JointState, joint_states, self._on_state, 10)

    def _on_state(self, msg: Any) -> None:
        self.latest = max(self.latest, msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)

    def wait_listeners(self, spin_until: Any, timeout: float, prog: str) -> None:
        """Wait (bounded) for a subscriber of the topic; without one say that nobody will see the marks."""
        try:
            spin_until(lambda: self.pub.get_subscription_count() > 0, timeout, f"subscriber of {self.spec.topic}")
        except RuntimeError:
            print(f"{prog}: WARNING: no subscriber of {self.spec.topic} within {timeout:g} s: the cycle marks go"
                  " out unheard (start the learner, identifier or recorder first)", file=sys.stderr)

    def publish(self, kind: int, stamp_s: float, start: Sequence[float], goal: Sequence[float]) -> None:
        from shaper_nodes.ros.conversions import sec_to_time

        msg = self.msg(event=kind, cycle=self.spec.cycle, task=self.spec.task, joint_names=self.joints,
                       start_positions=[float(x) for x in start], goal_positions=[float(x) for x in goal])
        msg.header.stamp = sec_to_time(stamp_s)
        self.pub.publish(msg)

    def start(self, stamp_s: float, start: Sequence[float], goal: Sequence[float]) -> None:
        self.publish(self.msg.START, stamp_s, start, goal)

    def finish(self, start_s: float, duration: float, hold: float, start: Sequence[float],
               goal: Sequence[float], timeout: float, prog: str) -> None:
        """MOTION_END and END of the cycle that started at ``start_s``, then wait for their acknowledgement."""
        from rclpy.duration import Duration

        self.publish(self.msg.MOTION_END, start_s + duration, start, goal)
        self.publish(self.msg.END, start_s + duration + hold, start, goal)
        deadline = time.monotonic() + timeout
        while not self.pub.wait_for_all_acked(Duration(seconds=0.1)):
            if time.monotonic() > deadline:
                print(f"{prog}: WARNING: the cycle's MOTION_END and END were not acknowledged by every subscriber"
                      f" of {self.spec.topic} within {timeout:g} s", file=sys.stderr)
                return
