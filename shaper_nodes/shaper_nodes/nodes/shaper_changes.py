"""The shaper node's active shaper and every change to it (nodes/shaper.py wires it).

:class:`ShaperChanges` holds what the node shapes with (the shaper, its FIR, the discretization method, the
source that set it and the revision) and answers every way of changing or reading it: the design parameters
(an on-set callback that validates, a post-set callback that commits), ``~/set_shaper`` and ``~/get_shaper``,
and :meth:`ShaperChanges.request` for in-process callers. Validate, then commit: a change is designed and
discretised completely and checked against the update policy (:mod:`shaper_nodes.core.shaping.policy`)
before anything changes; a refused change leaves the active shaper as it was. An accepted change is applied
to the streamed inputs' filters between two samples (:meth:`CommandStream.switch`, bumplessly or re-timing
the motion for the sources in ``retime_sources``), published on the latched ``~/active_shaper`` and, when
it replaces another source's shaper, reported in the log and on ``/diagnostics``.

The node creates this object where it made the ``~/active_shaper`` publisher, and registers the services
and the parameter callbacks itself, in the order it always did.
"""

from __future__ import annotations

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper
from shaper_nodes.core.shaping import PolicyError, Shaper, ShaperError, SparseFir, UpdatePolicy, discretize
from shaper_nodes.core.shaping.policy import PARAMETERS_SOURCE
from shaper_nodes.core.shaping.stream import CommandStream
from shaper_nodes.ros.conversions import shaper_from_msg, shaper_to_msg
from shaper_nodes.ros.diagnostics import OK, WARN, Diagnostics
from shaper_nodes.ros.parameters import Live
from shaper_nodes.ros.qos import LATCHED

from .shaper_parameters import DESIGN_PARAMS, ShaperParams, describe, design_from_params, displacement, ineffective

__all__ = ["ShaperChanges"]


class ShaperChanges:
    """The active shaper of a shaper node, and its changes; see the module docstring.

    Parameters
    ----------
    node : rclpy.node.Node
        The shaper node: its clock stamps the active shaper, its logger reports the changes, and it
        gets the latched ``~/active_shaper`` publisher (made here).
    params : Live of ShaperParams
        The node's typed parameters (refreshed here when a change of them is committed).
    policy : UpdatePolicy
        Which sources may change the shaper, and how (switch or re-time).
    stream : CommandStream
        The streamed inputs' filters and rules; an accepted change switches its FIR.
    diagnostics : Diagnostics
        Where a change that replaces another source's shaper is reported.
    shaper : Shaper
        The start-up design (from the parameters).
    method : str
        Its discretization method.
    fir : SparseFir
        ``shaper`` discretised at the command rate with ``method`` (the stream's filter at start-up).
    rate : float
        The command rate, Hz.

    Attributes
    ----------
    shaper, fir, method, source, revision
        The active shaper, its FIR and discretization method, the source that set it, its revision
        (1 at start-up, one more for every accepted change).
    displaced : str or None
        What the last change displaced ("replaces the shaper set by <source> (revision N)"), or None.
    """

    def __init__(self, node: Node, params: Live[ShaperParams], policy: UpdatePolicy, stream: CommandStream,
                 diagnostics: Diagnostics, shaper: Shaper, method: str, fir: SparseFir, rate: float) -> None:
        self._node, self._params, self._policy, self._stream = node, params, policy, stream
        self._diagnostics, self._rate = diagnostics, rate
        self.shaper, self.fir, self.method = shaper, fir, method
        self.source = PARAMETERS_SOURCE
        self.revision = 1
        self.displaced: str | None = None
        self._pending_params: tuple[Shaper, str] | None = None
        self._pub = node.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)

    def describe(self) -> str:
        """One line on the active shaper (family, impulses, duration, modes)."""
        return describe(self.shaper)

    # ----------------------------------------------------------------- the design parameters
    def validate_params(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: a change of the design parameters is designed and discretised in full, and checked
        against the policy, before rclpy takes it; nothing changes here."""
        if not any(p.name in DESIGN_PARAMS for p in params):
            return SetParametersResult(successful=True)
        try:
            proposed = self._params.with_changes(params)
            why = ineffective(self._params.value, proposed, {p.name for p in params})
            if why is not None:
                return SetParametersResult(successful=False, reason=why)
            self._policy.allow(PARAMETERS_SOURCE)
            shaper, method = design_from_params(proposed, self._rate)
            self._policy.settled(self._stream.stages())
            discretize(shaper, self._rate, method)  # may refuse; nothing has changed yet
        except (ShaperError, PolicyError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        except Exception as err:  # whatever the values, the node refuses them and keeps running
            return SetParametersResult(successful=False, reason=f"the design failed ({type(err).__name__}: {err})")
        self._pending_params = (shaper, method)
        return SetParametersResult(successful=True)

    def apply_params(self, params: list[Parameter]) -> None:
        """Post-set callback: the stream's bounds follow the parameters; a design validated above is committed."""
        p = self._params.refresh()  # rclpy calls this before the typed parameters' own post-set callback
        self._stream.max_abs = float(p.limits.max_abs_value)
        self._stream.max_samples = int(p.limits.max_trajectory_samples)
        pending, self._pending_params = self._pending_params, None
        if pending is not None:
            self._commit(pending[0], PARAMETERS_SOURCE, pending[1])

    # ----------------------------------------------------------------- requests
    def request(self, shaper: Shaper, source: str) -> tuple[bool, str]:
        """Validate and make ``shaper`` active on behalf of ``source``; returns (accepted, why)."""
        try:
            self._policy.decide(source, shaper, self._rate, self._stream.stages())
            self._commit(shaper, source, self.method)
        except (PolicyError, RuntimeError, ValueError) as err:
            return False, str(err)
        note = f"; {self.displaced}" if self.displaced else ""
        return True, f"active: {self.describe()}, revision {self.revision}{note}"

    def _commit(self, shaper: Shaper, source: str, method: str) -> None:
        fir = discretize(shaper, self._rate, method)  # may raise; nothing changed yet
        self._stream.switch(fir, retime=self._policy.how(source) == "retime")  # between two streamed samples
        before, before_revision = self.source, self.revision
        self.shaper, self.fir, self.source, self.method = shaper, fir, source, method
        self.revision += 1
        self.publish()
        self.displaced = displacement(before, before_revision, source)  # reported: log, /diagnostics, answer
        line = f"shaper changed by {source}: {self.describe()}, revision {self.revision}"
        level = OK if before in (source, PARAMETERS_SOURCE) else WARN  # the start-up design is there to be replaced
        if level == WARN:  # one call site per severity, as rclpy's logger wants
            self._node.get_logger().warning(f"{line}; {self.displaced}")
        else:
            self._node.get_logger().info(line + (f"; {self.displaced}" if self.displaced else ""))
        if self.displaced:
            self._diagnostics.publish("source", level, f"{source} {self.displaced}: {self.describe()}",
                                      [("displaced", before), ("by", source), ("revision", str(self.revision))])

    # ----------------------------------------------------------------- the active shaper, published and served
    def msg(self) -> ShaperMsg:
        """The active shaper as a message, stamped now."""
        return shaper_to_msg(self.shaper, self.source, self.revision, self._node.get_clock().now().to_msg())

    def publish(self) -> None:
        """The active shaper on the latched ``~/active_shaper``."""
        self._pub.publish(self.msg())

    def on_set_shaper(self, req: SetShaper.Request, resp: SetShaper.Response) -> SetShaper.Response:
        """``~/set_shaper``: :meth:`request` for the source the request names; every answer carries the
        active shaper."""
        source = UpdatePolicy.source_of(req.shaper.source)
        try:
            shaper = shaper_from_msg(req.shaper, float(self._params.value.shaper.max_gain))
            resp.success, resp.message = self.request(shaper, source)
        except ShaperError as err:
            resp.success, resp.message = False, f"invalid shaper: {err}"
        except Exception as err:  # whatever a request holds, the node answers and keeps running
            resp.success, resp.message = False, f"invalid shaper: the design failed ({type(err).__name__}: {err})"
        if not resp.success:
            self._node.get_logger().warning(f"set_shaper from {source} refused: {resp.message}")
        resp.active = self.msg()
        return resp

    def on_get_shaper(self, req: GetShaper.Request, resp: GetShaper.Response) -> GetShaper.Response:
        """``~/get_shaper``: the active shaper, the command rate and the FIR's dense taps."""
        resp.active = self.msg()
        resp.command_rate = self._rate
        resp.fir_taps = self.fir.dense().tolist()
        return resp
