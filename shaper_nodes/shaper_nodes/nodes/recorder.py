"""Recorder node: chosen topics, serialized CDR as received, into a rosbag2 MCAP folder.

For machines without rosbag2 (it is not on PyPI). Subscriptions take the raw bytes and only
queue them; a writer thread writes them, so no disk I/O happens in a callback. Topics are
found by name as they appear on the graph (types from the graph), with a QoS that matches
their publishers (TRANSIENT_LOCAL for latched topics such as the active shaper). The bag is
finished (metadata.yaml written) on shutdown (SIGINT) or by the ~/stop service.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from std_srvs.srv import Trigger

from shaper_nodes.ros.bag_writer import BagWriter, message_class
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import Spec, declare_all

#: the recorder node's parameters
PARAMETERS: tuple[Spec, ...] = (
    Spec("output", "recording", "rosbag2 folder to create (must not exist).", read_only=True),
    Spec("topics", ["/joint_states", "/tip_imu", "/cycle_events"], "Topics to record (fully qualified names).",
         read_only=True),
    Spec("discovery_period", 0.2, "How often to look for requested topics not yet subscribed, s.", read_only=True),
)


class RecorderNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__("recorder", *args, **kwargs)
        declare_all(self, PARAMETERS)
        self.wanted = [t if t.startswith("/") else "/" + t for t in self.get_parameter("topics").value]
        self.bag = BagWriter(self.get_parameter("output").value)
        self._queue: collections.deque[tuple[str, int, bytes]] = collections.deque()
        self._subs: dict[str, Subscription] = {}
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain_loop, name="bag-writer", daemon=True)
        self._thread.start()
        # wall-clock timer: with use_sim_time the ROS clock stands still while the plant is idle
        self.create_timer(float(self.get_parameter("discovery_period").value), self._discover,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_service(Trigger, "~/stop", self._on_stop)
        self._closed = False
        self._discover()
        self.get_logger().info(f"recording {self.wanted} to {self.bag.path}")

    @property
    def subscribed(self) -> list[str]:
        return sorted(self._subs)

    def _qos_for(self, topic: str) -> QoSProfile:
        infos = self.get_publishers_info_by_topic(topic)
        latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
        return QoSProfile(
            depth=1000,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _discover(self) -> None:
        if self._closed:
            return
        graph = dict(self.get_topic_names_and_types())
        for topic in self.wanted:
            if topic in self._subs or topic not in graph or not self.get_publishers_info_by_topic(topic):
                continue
            type_name = graph[topic][0]
            try:
                cls = message_class(type_name)
                with self._lock:
                    self.bag.add_topic(topic, type_name)
            except (ImportError, AttributeError, KeyError) as err:
                self.get_logger().error(f"cannot record {topic} ({type_name}): {err}", throttle_duration_sec=10.0)
                continue
            self._subs[topic] = self.create_subscription(cls, topic, self._queuer(topic), self._qos_for(topic),
                                                         raw=True)
            self.get_logger().info(f"recording {topic} [{type_name}]")

    def _queuer(self, topic: str) -> Callable[[bytes], None]:
        """The subscription callback of ``topic``: queue the raw message with the receive time."""
        def queue(data: bytes) -> None:
            self._queue.append((topic, self.get_clock().now().nanoseconds, data))
        return queue

    def _drain(self) -> None:
        with self._lock:
            while self._queue:
                topic, stamp, data = self._queue.popleft()
                self.bag.write(topic, stamp, data)

    def _drain_loop(self) -> None:
        while not self._stop.is_set():
            self._drain()
            time.sleep(0.02)

    def close(self) -> None:
        """Write what is queued and finish the bag (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for sub in self._subs.values():
            self.destroy_subscription(sub)
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._drain()
        with self._lock:
            self.bag.close()
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.bag.counts.items()))
        self.get_logger().info(f"closed {self.bag.path} ({counts})")

    def _on_stop(self, req, resp):
        self.close()
        resp.success, resp.message = True, str(self.bag.path)
        return resp


def main(args: list[str] | None = None) -> int:
    return run_node(RecorderNode, "recorder", args)


if __name__ == "__main__":
    raise SystemExit(main())
