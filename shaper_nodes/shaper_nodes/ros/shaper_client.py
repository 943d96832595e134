"""Calls to another node's services that never hang, and the one client of ``set_shaper``.

A service reply can be lost (a reply sent before DDS has matched the reply reader is dropped)
and a server can stop answering; a node that awaits such a reply without a bound hangs in that
callback for good. :class:`ServiceClient` bounds both waits, for the service to appear and for
its reply, in wall time (with ``use_sim_time`` the node clock may stand still), without blocking
the executor: :func:`wait_for` awaits a future until it is done or a steady-clock timer fires,
whichever comes first (the timer in a callback group of the client's own, so that it runs while
the caller's coroutine holds its group), and the executor serves the node meanwhile.

A call that times out is given up (its pending request removed) and returned as an
:class:`Answer` without a response and with the reason, which is also reported on the log and
``/diagnostics`` (kind ``timeout``) when the client has a :class:`~.diagnostics.Diagnostics`.
Callers retry where that is right (the learners' start-up, the scheduler) and report where it is
not (the identifier's ``apply``).

:class:`ShaperClient` is the client of a shaper node's ``~/set_shaper`` (and ``~/get_shaper``)
that the identifier, both learners and the scheduler use: it fills in the source and the family
``custom`` for exact impulses, and says what the shaper node answered. Callers that cannot await
(a timer callback that must not hold its callback group) use :meth:`ServiceClient.start`, which
returns a :class:`PendingCall` to poll.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper

from .diagnostics import WARN, Diagnostics

#: how often a call waiting for its service looks again, s (wall time)
DISCOVERY_POLL = 0.02
#: the shortest wait for a reply, s (a call whose time is all but spent still gets a chance)
MIN_WAIT = 0.001


async def wait_for(node: Node, future: Future, timeout: float, group: CallbackGroup | None = None) -> bool:
    """Await ``future`` for at most ``timeout`` s of wall time; whether it is done.

    A coroutine: the executor goes on serving the node meanwhile. ``group`` is the callback group
    of the timer that bounds the wait (it must not be one the awaiting callback holds).
    """
    if future.done():
        return True
    wake = Future()

    def fire(*_: object) -> None:
        if not wake.done():
            wake.set_result(None)

    timer = node.create_timer(timeout, fire, callback_group=group, clock=Clock(clock_type=ClockType.STEADY_TIME))
    future.add_done_callback(fire)
    try:
        await wake
    finally:
        node.destroy_timer(timer)
    return future.done()


@dataclass(frozen=True)
class Answer:
    """What became of one call: the response, or None and why."""

    response: Any | None
    error: str = ""
    timed_out: bool = False

    @property
    def ok(self) -> bool:
        """A response came (whatever it says)."""
        return self.response is not None


class PendingCall:
    """A call in flight, polled by :meth:`result` (for callers that cannot await)."""

    def __init__(self, client: ServiceClient, future: Future | None, deadline: float, error: str = "") -> None:
        self._client, self._future, self._deadline, self._error = client, future, deadline, error
        self._answer: Answer | None = None if future is not None else Answer(None, error)

    def result(self) -> Answer | None:
        """The answer once there is one (the response, or a timeout); None while waiting."""
        if self._answer is None and self._future is not None:
            if self._future.done():
                self._answer = Answer(self._future.result())
            elif time.monotonic() >= self._deadline:
                self._answer = self._client._gave_up(self._future)
        return self._answer

    def on_done(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` (from the thread that completes the call: keep it short, e.g. a guard condition's
        trigger) once the response is in; at once for a call answered without one. A timeout is not a response:
        :meth:`result` tells it when polled."""
        if self._future is None:
            callback()
        else:
            self._future.add_done_callback(lambda _future: callback())


class ServiceClient:
    """A client of one service whose waits are bounded (see the module docstring).

    Parameters
    ----------
    node : Node
        The node that calls.
    srv_type : type
        The service type.
    name : str
        The service's name.
    timeout : callable returning float, or float
        Longest wait for the service and, again, for the reply, s of wall time (a callable is
        read at each call, so a dynamic parameter takes effect at once).
    diagnostics : Diagnostics, optional
        Where timeouts are reported (kind ``timeout``).
    """

    def __init__(self, node: Node, srv_type: Any, name: str, timeout: Callable[[], float] | float,
                 diagnostics: Diagnostics | None = None) -> None:
        self.node = node
        self._timeout = timeout if callable(timeout) else (lambda: float(timeout))
        self._diagnostics = diagnostics
        # its own callback group: the caller's coroutine holds its group while it awaits the reply
        self._client = node.create_client(srv_type, name, callback_group=MutuallyExclusiveCallbackGroup())
        self._timer_group = MutuallyExclusiveCallbackGroup()
        self.timeouts = 0

    @property
    def srv_name(self) -> str:
        return str(self._client.srv_name)

    def service_is_ready(self) -> bool:
        return bool(self._client.service_is_ready())

    def destroy(self) -> None:
        self.node.destroy_client(self._client)

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of wall time without blocking the executor."""
        await wait_for(self.node, Future(), seconds, self._timer_group)

    async def call(self, request: Any, timeout: float | None = None, *, total: bool = False) -> Answer:
        """Call the service: the response, or no response and why (not there, or no reply).

        The wait for the service and the wait for the reply are each bounded by ``timeout`` (the
        client's timeout if None); with ``total`` both together are (the reply gets what the
        discovery left).
        """
        limit = self._timeout() if timeout is None else float(timeout)
        deadline = time.monotonic() + limit
        while not self.service_is_ready():
            if time.monotonic() >= deadline:
                return Answer(None, f"service {self.srv_name} not available within {limit:g} s")
            await self.sleep(DISCOVERY_POLL)
        future = self._client.call_async(request)
        wait = max(deadline - time.monotonic(), MIN_WAIT) if total else limit
        if not await wait_for(self.node, future, wait, self._timer_group):
            return self._gave_up(future, limit)
        return Answer(future.result())

    def start(self, request: Any, timeout: float | None = None) -> PendingCall:
        """Send ``request`` now, without waiting; poll the returned call. A service not there is
        answered at once (no response, the reason)."""
        limit = self._timeout() if timeout is None else float(timeout)
        if not self.service_is_ready():
            return PendingCall(self, None, 0.0, f"service {self.srv_name} not available")
        return PendingCall(self, self._client.call_async(request), time.monotonic() + limit)

    def _gave_up(self, future: Future, limit: float | None = None) -> Answer:
        self._client.remove_pending_request(future)
        self.timeouts += 1
        limit = self._timeout() if limit is None else limit
        why = f"{self.srv_name} did not answer within {limit:g} s"
        if self._diagnostics is not None:
            self._diagnostics.report("timeout", WARN, f"{why}; given up", values=[("service", self.srv_name)])
        return Answer(None, why, timed_out=True)


class ShaperClient:
    """The shaper node's ``set_shaper`` and ``get_shaper``, called with bounded waits.

    Parameters
    ----------
    node : Node
        The node that calls.
    shaper : str
        Fully qualified name of the shaper node (or of a node offering its interface, such as the
        scheduler).
    source : str
        The source this node's requests name (the shaper node's update policy decides by it).
    timeout, diagnostics
        As for :class:`ServiceClient`.
    """

    def __init__(self, node: Node, shaper: str, source: str, timeout: Callable[[], float] | float,
                 diagnostics: Diagnostics | None = None, *, get: bool = False) -> None:
        base = shaper.rstrip("/")
        self.source = source
        self.set = ServiceClient(node, SetShaper, f"{base}/set_shaper", timeout, diagnostics)
        self.get = ServiceClient(node, GetShaper, f"{base}/get_shaper", timeout, diagnostics) if get else None

    @property
    def srv_name(self) -> str:
        return self.set.srv_name

    def service_is_ready(self) -> bool:
        return self.set.service_is_ready()

    def request(self, msg: ShaperMsg, *, exact: bool = False) -> SetShaper.Request:
        """A set_shaper request for ``msg`` with this client's source (``exact``: family
        ``custom``, the impulses as they are, not a re-design)."""
        msg.source = self.source
        if exact:
            msg.family = "custom"
        return SetShaper.Request(shaper=msg)

    async def send(self, msg: ShaperMsg, *, exact: bool = False) -> tuple[bool, str, Answer]:
        """Ask the shaper node to make ``msg`` active: (accepted, why, the answer)."""
        answer = await self.set.call(self.request(msg, exact=exact))
        if answer.response is None:
            return False, answer.error, answer
        return bool(answer.response.success), str(answer.response.message), answer
