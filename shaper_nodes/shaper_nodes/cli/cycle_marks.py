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

START goes out before the goal (once every subscriber of the events topic the graph names has matched, or
after ``--timeout`` with a warning that nobody, or not everybody, listens), and the goal once every subscriber
has acknowledged START (bounded by ``--timeout``); MOTION_END and END once the goal succeeded, and the
command waits (bounded) until every subscriber has acknowledged them. A goal that does not succeed
gets no MOTION_END and END: the learner drops the unfinished cycle at the next START. Every mark carries
the START's stamp (``start_stamp``): a listener whose side of the match came after START still learns
when the cycle began, from MOTION_END or END (ros/cycle_events.py; the waits above make that rare, they
cannot rule it out: session 13's walk).
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
#: wall s every subscriber the graph names must have matched the marks' publisher before START goes out (the
#: readers' side of the match comes after the writer's: CycleMarks.matched_all)
SETTLE = 0.5


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
        self._matched_since: float | None = None  # wall time every subscriber was matched since (matched_all)
        node.create_subscription(JointState, joint_states, self._on_state, 10)

    def _on_state(self, msg: Any) -> None:
        self.latest = max(self.latest, msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)

    def matched_all(self) -> bool:
        """Whether every subscriber of the topic the graph names (one at least) has matched the marks' publisher,
        and has for :data:`SETTLE` s of wall time.

        The publisher is new (one per command) and volatile, as the subscribers are: a subscriber that has not
        matched it yet when START goes out never gets START, and the writer's side matches a reader before the
        reader's side matches the writer (a volatile reader that matches late starts after the samples sent
        before). Sent at the first match, one of the three listeners (learner, identifier, recorder) missed START
        in 6 of 23 goals of the owner's walk on the sim arm (session 13: "END without its START", the cycle not
        learned from)."""
        matched = self.pub.get_subscription_count()
        now = time.monotonic()
        if not (matched > 0 and matched >= self.node.count_subscribers(self.spec.topic)):
            self._matched_since = None
            return False
        if self._matched_since is None:
            self._matched_since = now
        return now - self._matched_since >= SETTLE

    def wait_listeners(self, spin_until: Any, timeout: float, prog: str) -> None:
        """Wait (bounded) for every subscriber of the topic to match; without one say that nobody will see the
        marks, with some unmatched that they may miss START."""
        try:
            spin_until(self.matched_all, timeout, f"subscriber of {self.spec.topic}")
        except RuntimeError:
            if self.pub.get_subscription_count() == 0:
                print(f"{prog}: WARNING: no subscriber of {self.spec.topic} within {timeout:g} s: the cycle marks go"
                      " out unheard (start the learner, identifier or recorder first)", file=sys.stderr)
            else:
                print(f"{prog}: WARNING: {self.pub.get_subscription_count()} of the"
                      f" {self.node.count_subscribers(self.spec.topic)} subscribers of {self.spec.topic} matched"
                      f" within {timeout:g} s: the others may miss the cycle's START", file=sys.stderr)

    def publish(self, kind: int, stamp_s: float, start: Sequence[float], goal: Sequence[float],
                start_s: float | None = None) -> None:
        """One event stamped ``stamp_s`` s, carrying its cycle's START stamp ``start_s`` (default ``stamp_s``: the
        START itself), so a listener that missed START has it (ros/cycle_events.py)."""
        from shaper_nodes.ros.conversions import sec_to_time
        from shaper_nodes.ros.cycle_events import set_start_stamp

        msg = self.msg(event=kind, cycle=self.spec.cycle, task=self.spec.task, joint_names=self.joints,
                       start_positions=[float(x) for x in start], goal_positions=[float(x) for x in goal])
        msg.header.stamp = sec_to_time(stamp_s)
        set_start_stamp(msg, stamp_s if start_s is None else start_s)
        self.pub.publish(msg)

    def start(self, stamp_s: float, start: Sequence[float], goal: Sequence[float], timeout: float = 0.0,
              prog: str = "") -> None:
        """START, then wait (bounded by ``timeout`` s) until every subscriber has acknowledged it: the goal
        goes out only once the listeners know the cycle began."""
        self.publish(self.msg.START, stamp_s, start, goal)
        self._acked(timeout, prog, "START")

    def _acked(self, timeout: float, prog: str, what: str) -> None:
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout
        while not self.pub.wait_for_all_acked(Duration(seconds=0.1)):
            if time.monotonic() > deadline:
                print(f"{prog}: WARNING: the cycle's {what} not acknowledged by every subscriber"
                      f" of {self.spec.topic} within {timeout:g} s", file=sys.stderr)
                return

    def finish(self, start_s: float, duration: float, hold: float, start: Sequence[float],
               goal: Sequence[float], timeout: float, prog: str) -> None:
        """MOTION_END and END of the cycle that started at ``start_s``, then wait for their acknowledgement."""
        self.publish(self.msg.MOTION_END, start_s + duration, start, goal, start_s)
        self.publish(self.msg.END, start_s + duration + hold, start, goal, start_s)
        self._acked(timeout, prog, "MOTION_END and END were")
