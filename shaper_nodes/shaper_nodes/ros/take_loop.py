"""A take loop for a lean node's subscriptions: one wait set, built once, instead of rclpy's executor.

rclpy's ``SingleThreadedExecutor`` builds a wait set again at every wake-up (every entity of its nodes
entered, counted and added), makes a task of each ready callback and checks its callback group before
running it; for a 1 kHz stream served by a lean node of one or two subscriptions that is most of the
hop's CPU (docs/results/benchmarks.md, "The shaper hop below a bare rclpy echo"). :class:`TakeLoop`
serves the same node from a thread of its own with one wait set made once over the node's
subscriptions, their event handlers (incompatible QoS or type) and a guard condition that stops it;
each wake-up adds the same handles again (rcl_wait clears those that are not ready), waits, and takes
every message of every ready subscription in arrival order (``take_message``, raw or not as the
subscription was made), calling its callback with the message, and its info for a two-argument
callback, as rclpy's executors do. The subscriptions' QoS event handlers (rclpy's ``EventHandler``,
two or three per subscription) are added and checked by their event handles in C
(``WaitSet.add_event``, ``WaitSet.is_ready``) rather than through their Python methods at every
wake-up; a ready one is then served through its own API (``is_ready``, ``take_data``, ``execute``).

The wait set is rclpy's own C++ class (``_rclpy.WaitSet`` from
``rclpy.impl.implementation_singleton``), which rclpy exposes in no public API; this module is the
only one of the suite that uses it and ``take_message``, and
``shaper_nodes/test/test_take_loop.py::test_the_rclpy_internals_the_take_loop_uses_are_there``
fails by name when the locked rclpy (7.1.6) changes them. The node must carry nothing else: no
timers, services, clients or guard conditions of its own (a lean :class:`~.side_node.SideNode`);
:meth:`TakeLoop.__init__` refuses a node with any.

Why not rclpy's ``EventsExecutor`` (``rclpy.experimental``, 7.1.6): its ``spin()`` holds the
interpreter lock while it waits (the process's other threads stop; measured: a publisher in the main
thread never returned) and it calls every subscription callback with the message only, so a
two-argument callback (message, info) raises, and its error path then fails with ``SystemError: null
argument to internal routine`` (``nodes_[0]`` on a Python set, fixed upstream by ros2/rclpy#1718).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any

from rclpy.event_handler import EventHandler
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.subscription import Subscription
from rclpy.waitable import NumberOfEntities

#: the rclpy internals used here, checked by the test named in the module docstring
INTERNALS = ("WaitSet", "GuardCondition")
#: where rclpy's ``EventHandler`` keeps its event handle (a name-mangled attribute; checked by the same test)
EVENT_HANDLE = "_EventHandler__event"


class TakeLoop:
    """Serve ``node``'s subscriptions on a thread of its own (module docstring).

    Parameters
    ----------
    node : Node
        A lean node with subscriptions only (their QoS event handlers included); created before
        :meth:`start`, none added after it.
    name : str
        The thread's name.
    on_error : callable or None
        Called with an exception a callback raised (the loop goes on); default: re-raised, which ends
        the loop.
    """

    def __init__(self, node: Node, name: str, on_error: Callable[[Exception], None] | None = None) -> None:
        others = {"timers": list(node.timers), "services": list(node.services), "clients": list(node.clients),
                  "guard conditions": list(node.guards)}
        extra = [k for k, v in others.items() if v]
        if extra:
            raise ValueError(f"TakeLoop serves subscriptions only; node {node.get_name()} has {', '.join(extra)}")
        self.node = node
        self._on_error = on_error
        self._stop = False
        self._wake = _rclpy.GuardCondition(node.context.handle)
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        #: messages taken so far, per subscription's topic name
        self.taken: dict[str, int] = {}

    def start(self) -> TakeLoop:
        """Start the loop's thread (after the node's subscriptions are made)."""
        self.node.context.on_shutdown(self._on_shutdown)  # a shutdown of the context ends the loop too
        self._thread.start()
        return self

    def _on_shutdown(self) -> None:
        self._stop = True
        self._wake_up()

    def _wake_up(self) -> None:
        with contextlib.suppress(Exception):
            self._wake.trigger_guard_condition()

    def _run(self) -> None:
        node = self.node
        subs: list[Subscription] = list(node.subscriptions)
        waitables = list(node.waitables)
        with contextlib.ExitStack() as stack:
            # entered for the loop's life: a destroy waits until the loop is done with the handle
            context: Any = node.context.handle
            stack.enter_context(context)
            handles: list[Any] = [sub.handle for sub in subs]
            for h in handles:
                stack.enter_context(h)
            for w in waitables:
                stack.enter_context(w)
            count = sum((w.get_num_entities() for w in waitables), start=NumberOfEntities(num_subs=len(subs)))
            wait_set = _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions + 1, count.num_timers,
                                      count.num_clients, count.num_services, count.num_events, context)
            two_args = [sub._callback_type is Subscription.CallbackType.WithMessageInfo for sub in subs]
            served = list(zip(subs, handles, [h.pointer for h in handles], two_args, strict=True))
            for sub in subs:
                self.taken.setdefault(sub.topic_name, 0)
            # rclpy's event handlers by their handles (entered above, so no `with` at each wake-up); their
            # events are the wait set's first, indices 0, 1, ... in this order, at every wake-up
            handlers = [w for w in waitables if type(w) is EventHandler]
            events = [getattr(w, EVENT_HANDLE) for w in handlers]
            for i, w in enumerate(handlers):
                w._event_index = i  # type: ignore[assignment]  # rclpy types it as its None start
            others = [w for w in waitables if type(w) is not EventHandler]
            add_subscription, add_event = wait_set.add_subscription, wait_set.add_event
            wake = self._wake
            if not node.context.ok():
                self._stop = True
            while not self._stop:
                wait_set.clear_entities()
                for e in events:
                    add_event(e)
                for h in handles:
                    add_subscription(h)
                wait_set.add_guard_condition(wake)
                for w in others:
                    w.add_to_wait_set(wait_set)
                wait_set.wait(-1)
                if self._stop:
                    break
                ready = wait_set.get_ready_entities("subscription")
                for sub, handle, pointer, two in served:
                    if pointer in ready:
                        self._drain(sub, handle, two)
                _serve_events(wait_set, handlers, others)
            wait_set.destroy_when_not_in_use()

    def _drain(self, sub: Subscription, handle: Any, two_args: bool) -> None:
        """Take every message waiting on ``sub`` and call its callback with each, in order."""
        typ, raw, callback = sub.msg_type, sub.raw, sub.callback
        n = 0
        while not self._stop:
            taken = handle.take_message(typ, raw)
            if taken is None:
                break
            n += 1
            try:
                if two_args:
                    callback(taken[0], taken[1])
                else:
                    callback(taken[0])
            except Exception as err:
                if self._on_error is None:
                    raise
                self._on_error(err)
        self.taken[sub.topic_name] += n

    def stop(self, timeout: float = 5.0) -> None:
        """Wake the loop, let it finish the callback it runs, and wait for its thread (up to ``timeout`` s)."""
        self._stop = True
        self._wake_up()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        if not self._thread.is_alive():
            self._wake.destroy_when_not_in_use()

    def join(self, timeout: float) -> None:
        """Wait up to ``timeout`` s for the loop's thread to end (it ends on :meth:`stop` or the context's shutdown)."""
        self._thread.join(timeout)

    @property
    def running(self) -> bool:
        """The loop's thread is alive."""
        return self._thread.is_alive()


def _serve_events(wait_set: Any, handlers: list[EventHandler], others: list[Any]) -> None:
    """Serve the ready ones of rclpy's event ``handlers`` (the wait set's events 0, 1, ..., checked in C first)
    and of the ``others`` waitables, through their own API."""
    is_ready = wait_set.is_ready
    for i, w in enumerate(handlers):
        if is_ready("event", i) and w.is_ready(wait_set):
            _run_coroutine(w.execute(w.take_data()))
    for w in others:
        if w.is_ready(wait_set):
            _run_coroutine(w.execute(w.take_data()))


def _run_coroutine(coro: Any) -> None:
    """Run an event handler's ``execute`` coroutine (it awaits nothing) to its end."""
    try:
        coro.send(None)
    except StopIteration:
        return
    coro.close()
