"""What the reproductions share: their command-line preamble and the learner-driven cycle loop.

:func:`docs_option` and :func:`logs_folder` are the common start of every ``main``;
:class:`LearnerDriver` is the conductor of the learner reproductions (LIST and MRILC): it follows
the learner's reports and the shaper it sets, and runs one cycle at a time, waiting for the
learner's report of each before the next, as a robot cell whose next cycle starts once the
update is in.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time
from typing import TYPE_CHECKING, Any

# the block size rule lives with the rest of the lockstep exchange (re-exported for the reproductions)
from shaper_nodes.core.lockstep import lockstep_block as lockstep_block

if TYPE_CHECKING:  # (rclpy is imported when a driver is made, not to print --help)
    from sim_plant_node.clients.conductor import Conductor, CycleResult


def docs_option(parser: argparse.ArgumentParser, what: str) -> None:
    """The ``--docs`` option: the folder the results (``what``) are written to, default docs/results."""
    parser.add_argument("--docs", type=pathlib.Path, default=pathlib.Path("docs/results"),
                        help=f"where {what} go (default docs/results)")


def logs_folder(name: str) -> pathlib.Path:
    """Keep discovery on this machine (unless set otherwise) and make ``out/<name>``, where the
    node processes' logs go."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    logs = pathlib.Path("out") / name
    logs.mkdir(parents=True, exist_ok=True)
    return logs


#: s of wall time the sim plant waits for the shaper's answer before it holds (``lockstep_timeout``): generous,
#: so that a loaded machine slows a run down instead of changing it
LOCKSTEP_TIMEOUT = 60.0
#: the learner's settings for a lockstep run: at a cycle's END it waits up to ``end_wait`` for the samples
#: stamped up to it (a plant stepping in blocks may run ahead of a loaded learner's intake; the wait ends as
#: soon as they are in)
LOCKSTEP_LEARNER = {"end_wait": 10.0}


def save_figure(fig: Any, docs: pathlib.Path, name: str) -> str:
    """Save ``fig`` (laid out tight) as ``docs/img/name`` at the arm pages' resolution, close it; returns ``name``."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    (docs / "img").mkdir(parents=True, exist_ok=True)
    fig.savefig(docs / "img" / name, dpi=90)
    plt.close(fig)
    return name


def metric(report: Any, name: str) -> float:
    """The value of metric ``name`` of a shaper_msgs/CycleReport (nan if it has none)."""
    try:
        return float(report.metric_values[list(report.metric_names).index(name)])
    except ValueError:
        return float("nan")


def action(report: Any) -> str:
    """What the learner did after the cycle of ``report`` (its ``action.<what>`` metric), else 'skipped'."""
    return next((n.split(".", 1)[1] for n in report.metric_names if n.startswith("action.")), "skipped")


def settle(conductor: Conductor, seconds: float = 1.0) -> None:
    """Spin for ``seconds``: once the driver has discovered every node, the plant's publishers get a
    moment to match the learner's subscriptions too (else the learner may miss the first START)."""
    until = time.monotonic() + seconds
    conductor.spin_until(lambda: time.monotonic() > until, seconds + 4.0, "discovery to settle")


class LearnerDriver:
    """A :class:`Conductor` on ``ctx`` that also collects the learner's reports and the active shaper.

    With ``measure`` False the conductor takes neither the accelerometer nor the joint states (it measures no
    residual of its own; :meth:`report_of_cycle` runs its cycles), for a reproduction that reads only the learner's
    reports: per cycle that is two messages fewer per sample to take in the driver's process, which on two
    cores shared with the plant, the shaper and the learner was a quarter of the run's CPU.
    """

    def __init__(self, ctx: Any, measure: bool = True) -> None:
        from shaper_msgs.msg import CycleReport
        from shaper_msgs.msg import Shaper as ShaperMsg
        from shaper_nodes.ros.qos import LATCHED
        from sim_plant_node.clients.conductor import Conductor

        self.conductor = Conductor(context=ctx, measure=measure)
        self.reports: list[Any] = []
        self.active: list[Any] = []
        self.conductor.create_subscription(CycleReport, "/learner/reports", self.reports.append, 100)
        self.conductor.create_subscription(ShaperMsg, "/shaper/active_shaper", self.active.append, LATCHED)

    def wait_ready(self, subscribers: dict[str, int], what: str) -> None:
        """Wait for the services and ``subscribers`` (topic: at least that many), then for the shaper
        the learner sets (``what`` names it in the error on a time-out), then let discovery settle.
        The plant is told to start a run only once its cycle events have as many matched
        subscriptions (``task.subscribers``), so that the learner cannot miss the first START."""
        self.conductor.wait_ready(60.0, subscribers)
        if subscribers.get("/cycle_events"):
            self.conductor.set_plant(task__subscribers=int(subscribers["/cycle_events"]))
        self.conductor.spin_until(lambda: bool(self.active) and self.active[-1].source == "learner", 60.0, what)
        settle(self.conductor)

    def cycle(self, k: int) -> tuple[CycleResult, Any]:
        """Run one cycle, the run's ``k``-th (from 0), and wait for the learner's report of it;
        returns the driver's own result of the cycle and the report."""
        result = self.conductor.run_cycles(1, timeout=300.0)[0]
        self.conductor.spin_until(lambda: len(self.reports) > k, 120.0, f"the learner's report of cycle {k}")
        return result, self.reports[k]

    def report_of_cycle(self, k: int) -> Any:
        """Run one cycle, the run's ``k``-th (from 0), and return the learner's report of it; the driver's own
        result of the cycle is measured only when the driver measures (then as :meth:`cycle`). Without, the
        cycle is over when its report is in: the learner reports a cycle after its END, and the plant ends its
        run at that END (a start while a run goes on is refused, and raises)."""
        if self.conductor.measure:
            return self.cycle(k)[1]
        self.conductor.start_run(1)
        self.conductor.spin_until(lambda: len(self.reports) > k, 300.0, f"the learner's report of cycle {k}")
        return self.reports[k]

    def close(self) -> None:
        self.conductor.close()
