"""A node's second node on a thread of its own, for work that must never hold the first one.

rclpy's executors serve whole nodes: every callback of a node waits in one wait set, and a
``MultiThreadedExecutor`` that would let callback groups run side by side costs so much per
callback in Python that a 1 kHz stream no longer keeps up (measured: 350 of 6000 setpoints came
back within their window, against 3947 with ``rclpy.spin``). So a node whose slow requests must
not delay its fast stream (the shaper's whole trajectories against its streamed setpoints) serves
the slow ones from a second node in the same process, named ``<node>_<suffix>`` in the same
namespace, spun by a ``SingleThreadedExecutor`` in a daemon thread. The names it serves are
resolved by the first node, so clients see the same services, topics and actions as before.

A *lean* side node (``lean=True``) carries nothing but what its owner puts on it: no parameter
services, no type description service, no ``/rosout`` publisher, and none of the process's
command-line arguments (the owner resolves the names it uses, remappings included; a
``-r __node:=NAME`` meant for the owner does not rename it too). rclpy's executor builds its wait
set again over every entity of its nodes at each wake-up, so a fast stream served by a lean node
wakes a wait set of one subscription instead of the owner's dozens of entities (the scheduler's
500 Hz ``/joint_states``). With ``take=True`` a lean side node is served by a
:class:`~.take_loop.TakeLoop` instead (one wait set built once, no executor; subscriptions only).

A side node that is not lean takes the process's arguments, ``-p use_sim_time:=true`` too; it keeps no
``/clock`` subscription of its own (:func:`follow_parent_time`): its clock is set with the parent's, so
a process has one ``/clock`` subscription, off its executors (:mod:`.sim_clock`).
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from .take_loop import TakeLoop


def follow_parent_time(parent: Node, node: Node) -> None:
    """``node`` on simulated time (``use_sim_time``) without a ``/clock`` subscription of its own: its clock is
    set by ``parent``'s time source, with the parent's clock (rclpy's ``TimeSource`` internals, those
    :mod:`.sim_clock` uses). Each ``/clock`` subscription wakes its node's executor at every message, several
    thousand a second from the sim plant in lockstep. Nothing changes for a node on the system clock."""
    own: Any = node._time_source
    parent_source: Any = parent._time_source
    if own._clock_sub is None or not parent_source.ros_time_is_active:
        return
    node.destroy_subscription(own._clock_sub)
    own._clock_sub = None
    own._subscribe_to_clock_topic = lambda: None  # use_sim_time turned on again: still the parent's time
    parent_source.attach_clock(node.get_clock())


class SideNode:
    """A second node of ``parent``'s process on its own executor thread (see the module docstring).

    Parameters
    ----------
    parent : Node
        The node it serves; its context and namespace are used.
    suffix : str
        The side node is named ``<parent name>_<suffix>``, whatever ``-r __node:=NAME`` the process was
        started with (that renames ``parent``; the side node keeps its own name after the new one).
    lean : bool
        Nothing but the owner's entities on it (see the module docstring): rclpy's executor builds its
        wait set over every entity of its nodes at each wake-up.
    take : bool
        Served by a :class:`~.take_loop.TakeLoop` (subscriptions only) instead of an executor; implies lean.
    """

    def __init__(self, parent: Node, suffix: str, *, lean: bool = False, take: bool = False) -> None:
        lean = lean or take
        name = f"{parent.get_name()}_{suffix}"
        extra: dict = {}
        if lean:
            extra = {"use_global_arguments": False, "enable_rosout": False,
                     "parameter_overrides": [Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)]}
        # a local __node rule comes before the process's global one (which names the parent)
        self.node = Node(name, namespace=parent.get_namespace(), context=parent.context,
                         cli_args=["--ros-args", "-r", f"__node:={name}"], start_parameter_services=False, **extra)
        follow_parent_time(parent, self.node)
        self._take = take
        self._loop: TakeLoop | None = None
        self._executor = SingleThreadedExecutor(context=parent.context)
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=f"{self.node.get_name()} executor", daemon=True)
        self._closed = False

    def start(self) -> SideNode:
        """Start spinning (after the side node's entities are created)."""
        if self._take:
            self._loop = TakeLoop(self.node, self._thread.name, on_error=self._error).start()
            return self
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

    def _error(self, err: Exception) -> None:
        """A callback's exception in the take loop: logged, the loop goes on (an executor would stop)."""
        self.node.get_logger().error(f"callback raised: {err!r}")

    def close(self, timeout: float = 5.0) -> None:
        """Stop the executor and wait for its thread (entities are the owner's to destroy first); once."""
        if self._closed:
            return
        self._closed = True
        if self._loop is not None:
            self._loop.stop(timeout)
        self._executor.shutdown(timeout_sec=timeout)
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self.node.destroy_node()
