"""The sim plant node's per-move report of the arm's residual split (``~/residual_parts``).

For the arm (``plant.model: arm``) the node hands every period's setpoint to a
:class:`~sim_plant_node.arm.residual_watch.ResidualWatch`; at each move's residual window's end it publishes one
``shaper_msgs/CycleReport`` on ``~/residual_parts`` (reliable, 100 deep):

- ``source`` "sim_plant", ``cycle`` the number of moves reported before this one (from 0; not a CycleEvent index:
  the plant knows moves by its setpoints, not by a task's cycle events);
- ``window_start``, ``window_end``: the residual window, s of the node's time (simulated in lockstep): from the
  commanded motion's end (the first period whose setpoint is the held one) for RESIDUAL_WINDOW (1 s);
- ``residual_rms``, ``residual_peak``: the arm's own residual over that window, from the IMU's noise-free specific
  force (mean removed), m/s^2;
- ``metric_names`` / ``metric_values``: ``servo_rms`` (the position loop's heavily damped part), ``vibration_rms``
  (the arm's lightly damped modes), ``linear_rms`` (the two together as the linearised arm has them; against
  ``residual_rms`` it says how linear the window is), each RMS with the mean removed, m/s^2; ``split_s``, the wall
  time the split took, s (the linearisation included for a new goal pose).

It is the simulator's truth, from the arm's state: a real robot has no such report.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from shaper_msgs.msg import CycleReport
from shaper_nodes.ros.conversions import sec_to_time

if TYPE_CHECKING:  # the arm's modules load Pinocchio: only when the plant is the arm (test_lazy_imports)
    from ..arm.plant import ArmPlant
    from ..arm.residual_watch import Split

__all__ = ["METRICS", "REPORT_QOS", "TOPIC", "ResidualReports", "residual_reports"]

TOPIC = "~/residual_parts"
#: the reports' metrics, in this order
METRICS = ("servo_rms", "vibration_rms", "linear_rms", "split_s")
REPORT_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


class ResidualReports:
    """The watch and its publisher; ``flush`` runs before a report goes out (the samples before it first)."""

    def __init__(self, node: Node, plant: ArmPlant, now: Callable[[], float], flush: Callable[[], None]) -> None:
        from ..arm.residual_watch import ResidualWatch

        self.watch = ResidualWatch(plant)
        self._pub = node.create_publisher(CycleReport, TOPIC, REPORT_QOS)
        self._now, self._flush = now, flush
        self.reported = 0

    def before(self, t_start: float, command: np.ndarray) -> None:
        self.watch.before(t_start, command)

    def after(self) -> None:
        split = self.watch.after()
        if split is not None:
            self._flush()
            self._pub.publish(message(split, self.reported, self._now()))
            self.reported += 1


def message(split: Split, count: int, now: float) -> CycleReport:
    """``split`` as the report of the module docstring (``count``: moves reported before it; ``now`` its stamp, s)."""
    p = split.parts
    msg = CycleReport(source="sim_plant", cycle=count, window_start=split.window_start, window_end=split.window_end,
                      residual_rms=split.own_rms, residual_peak=split.own_peak, metric_names=list(METRICS),
                      metric_values=[p.servo_rms, p.vibration_rms, p.linear_rms, split.seconds])
    msg.header.stamp = sec_to_time(now)
    return msg


def residual_reports(node: Node, plant: Any, now: Callable[[], float],
                     flush: Callable[[], None]) -> ResidualReports | None:
    """The reports for ``plant`` if it is the arm (the only model whose state gives the split), else None."""
    arm = sys.modules.get("sim_plant_node.arm.plant")  # loaded if the plant is the arm; not loaded for another model
    return ResidualReports(node, plant, now, flush) if arm is not None and isinstance(plant, arm.ArmPlant) else None
