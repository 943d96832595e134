"""A node's second node on a thread of its own, for work that must never hold the first one.

rclpy's executors serve whole nodes: every callback of a node waits in one wait set, and a
``MultiThreadedExecutor`` that would let callback groups run side by side costs so much per
callback in Python that a 1 kHz stream no longer keeps up (measured: 350 of 6000 setpoints came
back within their window, against 3947 with ``rclpy.spin``). So a node whose slow requests must
not delay its fast stream (the shaper's whole trajectories against its streamed setpoints) serves
the slow ones from a second node in the same process, named ``<node>_<suffix>`` in the same
namespace, spun by a ``SingleThreadedExecutor`` in a daemon thread. The names it serves are
resolved by the first node, so clients see the same services, topics and actions as before.
"""

from __future__ import annotations

import threading

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node


class SideNode:
    """A second node of ``parent``'s process on its own executor thread (see the module docstring).

    Parameters
    ----------
    parent : Node
        The node it serves; its context and namespace are used.
    suffix : str
        The side node is named ``<parent name>_<suffix>``.
    """

    def __init__(self, parent: Node, suffix: str) -> None:
        self.node = Node(f"{parent.get_name()}_{suffix}", namespace=parent.get_namespace(), context=parent.context,
                         start_parameter_services=False)
        self._executor = SingleThreadedExecutor(context=parent.context)
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=f"{self.node.get_name()} executor", daemon=True)

    def start(self) -> SideNode:
        """Start spinning (after the side node's entities are created)."""
        self._thread.start()
        return self

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except (ExternalShutdownException, KeyboardInterrupt):
            pass
        except Exception as err:  # the shutdown of the context can race the wait; log anything else
            if self.node.context.ok():
                self.node.get_logger().error(f"executor stopped: {err!r}")

    def close(self, timeout: float = 5.0) -> None:
        """Stop the executor and wait for its thread (entities are the owner's to destroy first)."""
        self._executor.shutdown(timeout_sec=timeout)
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self.node.destroy_node()
