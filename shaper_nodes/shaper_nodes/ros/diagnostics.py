"""A node's problems and summaries on ``/diagnostics`` and in its log, throttled per kind.

Every refusal of the suite's nodes (bad input, a refused or unanswered service call, a stale
sensor) goes through :class:`Diagnostics`: an ERROR or WARN line in the node's log and a
``diagnostic_msgs/DiagnosticStatus`` named ``<node>: <name>`` with the message and key values,
at most once per ``throttle`` seconds of wall time for each kind (a flood of bad messages does
not flood the log). Counts are kept for every report, throttled or not. Periodic summaries
(:meth:`Diagnostics.publish`) are never throttled.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from std_msgs.msg import Header

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


class Diagnostics:
    """Throttled reports of one node (see the module docstring).

    Parameters
    ----------
    node : Node
        The node that reports; it gets a ``/diagnostics`` publisher.
    throttle : callable returning float, or float
        Least time between two reports of the same kind, s (a callable is read at every report,
        so a dynamic parameter takes effect at once).
    """

    def __init__(self, node: Node, throttle: Callable[[], float] | float = 1.0) -> None:
        self.node = node
        self._throttle = throttle if callable(throttle) else (lambda: float(throttle))
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._last: dict[str, float] = {}
        self.counts: Counter[str] = Counter()

    def report(self, kind: str, level: int, message: str, *, name: str | None = None,
               values: Iterable[tuple[str, str]] = ()) -> bool:
        """Count a problem of ``kind``; log and publish it unless one of its kind was reported less
        than ``throttle`` s ago. Returns whether it was published."""
        self.counts[kind] += 1
        now = time.monotonic()
        if now - self._last.get(kind, -float("inf")) < self._throttle():
            return False
        self._last[kind] = now
        log = self.node.get_logger()
        if level >= ERROR:  # one call site per severity, as rclpy's logger wants
            log.error(message)
        elif level == WARN:
            log.warning(message)
        else:
            log.info(message)
        self.publish(name or kind, level, message, [("kind", kind), *values])
        return True

    def publish(self, name: str, level: int, message: str, values: Iterable[tuple[str, str]] = ()) -> None:
        """One status ``<node>: <name>`` on /diagnostics, now (not throttled, not logged)."""
        status = DiagnosticStatus(level=level, name=f"{self.node.get_name()}: {name}",
                                  hardware_id=self.node.get_fully_qualified_name(), message=message,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in values])
        header = Header(stamp=self.node.get_clock().now().to_msg())
        self._pub.publish(DiagnosticArray(header=header, status=[status]))
