"""The scheduler node: the shaper follows the pose, by Takagi-Sugeno fuzzy interpolation (seed 004).

From /joint_states it takes the premise variables (the positions of the joints named in
``premises``), evaluates the rule base (operating points with their linear models and/or mode
parameters, in the parameter file, see config/scheduler.yaml and core/fuzzy.py), and sends the
shaper designed on the interpolated mode(s) to the shaper node (``<shaper>/set_shaper``, source
"scheduler").

Rate limit: a new shaper is sent only when a mode moved by more than ``relative_change`` since
the last one sent, at most once per ``min_interval`` s, never while the previous request is
unanswered, and never faster than the shaper node retires shapers bumplessly (the active
shaper's duration divided by the number of shapers it keeps alive, core.fir.MAX_STAGES - 1).
Premises outside the rule base's range are clamped to it (never extrapolated) and reported
(a warning and a /diagnostics status). Joint states missing a premise joint or carrying
non-finite positions are refused and reported; without joint states for ``stale_timeout`` s
the scheduler stops updating and says so.

Interfaces
----------
/joint_states (sensor_msgs/JointState)                in
~/mode_estimate (shaper_msgs/ModeEstimate, latched)   the interpolated mode(s), rad/s and -
<shaper>/set_shaper (shaper_msgs/SetShaper)           out, source "scheduler" (or "learner")
~/set_shaper, ~/get_shaper, ~/active_shaper           the shaper node's interface, for the learner
/diagnostics                                          clamping, refused input, stale data

Policy with the learner (core/scheduling.py): point the learner at this node (its parameter
``shaper: /scheduler``). The scheduler decides the mode; the learner's shapers are taken as a
correction of the scheduled ZV, kept per operating region (rule) and applied with every
scheduled shaper from then on. The learner's request itself is forwarded unchanged (source
"learner"), so the cycle it learns from runs with exactly its shaper. The identity shaper (the
learner's unshaped reference cycle) is forwarded too and holds the schedule until the learner
sends a shaper again. Other sources are refused here: they set the shaper node directly.
"""

from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from shaper_msgs.msg import Mode as ModeMsg
from shaper_msgs.msg import ModeEstimate
from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper
from shaper_nodes.core.scheduling import FuzzyError, Interpolation, Scheduler, relative_change, rule_base_from_dict
from shaper_nodes.core.shaping import FAMILIES, MAX_STAGES, ShaperError
from shaper_nodes.ros.conversions import shaper_from_msg, shaper_to_msg
from shaper_nodes.ros.node_main import run_node
from shaper_nodes.ros.parameters import describe as _desc

from .shaper import LATCHED

SOURCE = "scheduler"
RULE_FIELDS = {"membership": Parameter.Type.STRING_ARRAY, "membership_params": Parameter.Type.DOUBLE_ARRAY,
               "a_matrix": Parameter.Type.DOUBLE_ARRAY, "b_matrix": Parameter.Type.DOUBLE_ARRAY,
               "natural_frequency": Parameter.Type.DOUBLE_ARRAY, "damping_ratio": Parameter.Type.DOUBLE_ARRAY}


#: wall time between discovering the shaper's set_shaper service and the first request, s
DISCOVERY_SETTLE = 0.5

class SchedulerNode(Node):
    """See the module docstring. Extra arguments go to ``Node``."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__("scheduler", *args, **kwargs)
        d = self.declare_parameter
        d("premises", Parameter.Type.STRING_ARRAY, _desc(
            "Joints whose positions (from joint_states, rad or m) are the premise variables, in the order of"
            " each rule's membership functions.", read_only=True))
        d("range", Parameter.Type.DOUBLE_ARRAY, _desc(
            "Valid range per premise [lo1, hi1, lo2, hi2, ...] (rad or m); outside it premises are clamped."
            " Default: from the lowest to the highest membership peak.", read_only=True))
        d("rule_names", Parameter.Type.STRING_ARRAY, _desc(
            "Names of the rules (operating points); each has rules.<name>.membership (one kind per premise:"
            " triangular, trapezoidal, gaussian), .membership_params (their parameters, concatenated), and"
            " .a_matrix (n*n, row-major) with .b_matrix (n*m), and/or .natural_frequency (rad/s) with"
            " .damping_ratio, one per mode.", read_only=True))
        d("interpolation", "model", _desc(
            "'model': interpolate the linear models and take the modes of the result (seed 004);"
            " 'modes': interpolate the mode parameters directly.", read_only=True))
        d("max_damping", 0.3, _desc("Modes with a damping ratio at or above this are not shaped for.", 0.01, 0.95,
                                    read_only=True))
        d("family", "zv", _desc("Shaper family designed on the interpolated modes: "
                                       + ", ".join(k for k in FAMILIES if k not in ("none", "custom")), read_only=True))
        d("shaper", "/shaper", _desc("Fully qualified name of the shaper node.", read_only=True))
        d("joint_states", "/joint_states", _desc("Joint state topic.", read_only=True))
        d("period", 0.05, _desc("How often the rule base is evaluated, s (node clock).", 0.001, 60.0, read_only=True))
        d("min_interval", 0.1, _desc("Least time between two shapers sent, s.", 0.0, 3600.0))
        d("service_timeout", 2.0, _desc(
            "A set_shaper call unanswered this long (wall time) is given up and sent again, s.", 0.01, 600.0))
        d("relative_change", 0.01, _desc(
            "Least change that sends a new shaper: |d omega| / omega or |d zeta| / max(zeta, 0.01), fraction.",
            0.0, 10.0))
        d("stale_timeout", 1.0, _desc("Joint states older than this stop the updates, s.", 0.001, 3600.0))
        d("error_throttle", 1.0, _desc("Least time between two reports of the same problem, s.", 0.0, 3600.0))

        def p(name: str):
            try:
                return self.get_parameter(name).value
            except ParameterUninitializedException:  # optional, no default
                return None

        premises = list(p("premises") or [])
        names = list(p("rule_names") or [])
        rules = {}
        for name in names:
            rules[name] = {}
            for fld, typ in RULE_FIELDS.items():
                self.declare_parameter(f"rules.{name}.{fld}", typ, _desc(f"Rule {name}: {fld}.", read_only=True))
                rules[name][fld] = p(f"rules.{name}.{fld}") or []
        spec = {"premises": premises, "rules": rules, "range": list(p("range") or []),
                "max_damping": float(p("max_damping"))}
        try:
            self.core = Scheduler(rule_base_from_dict(spec), str(p("interpolation")), str(p("family")))
        except (FuzzyError, ShaperError) as err:
            raise ValueError(f"invalid rule base: {err}") from None
        self.premises = self.core.rule_base.premises

        shaper = str(p("shaper")).rstrip("/")
        # the clients' answers must get through while a service callback awaits them
        clients = ReentrantCallbackGroup()
        self._set_cli = self.create_client(SetShaper, f"{shaper}/set_shaper", callback_group=clients)
        self._get_cli = self.create_client(GetShaper, f"{shaper}/get_shaper", callback_group=clients)
        self.create_subscription(ShaperMsg, f"{shaper}/active_shaper", self._on_active, LATCHED)
        self.create_subscription(JointState, str(p("joint_states")), self._on_joint_states, 50)
        self._active_pub = self.create_publisher(ShaperMsg, "~/active_shaper", LATCHED)
        self._mode_pub = self.create_publisher(ModeEstimate, "~/mode_estimate", LATCHED)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_service(SetShaper, "~/set_shaper", self._on_set_shaper)
        self.create_service(GetShaper, "~/get_shaper", self._on_get_shaper)

        self._z: list[float] | None = None        # latest premise values
        self._interp: Interpolation | None = None # the rule base at the latest evaluation
        self._z_stamp = None                      # node clock time they arrived
        self._stamp = None                        # their header stamp
        self.last_sent: Interpolation | None = None
        self._sent_at = -math.inf                 # node clock, s
        self._pending = False
        self._pending_since = 0.0                 # monotonic time of the call in flight
        self._call = 0                            # number of the latest set_shaper call
        self._held_by_learner = False
        self._active: ShaperMsg | None = None
        self._reported: dict[str, float] = {}
        self.sent = 0
        self.refused = 0
        self.create_timer(float(p("period")), self._tick)
        # wall clock (with use_sim_time the node clock stands still while a lockstep plant is idle):
        # notes when the shaper's set_shaper service appeared, see _service_settled
        self._ready_since: float | None = None
        self._watch = self.create_timer(0.05, self._watch_service, clock=Clock(clock_type=ClockType.STEADY_TIME))
        rb = self.core.rule_base
        self.get_logger().info(
            f"{len(rb.rules)} rules over {', '.join(self.premises)} (range "
            + ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in rb.ranges) + f"), interpolating {self.core.method},"
            f" {self.core.family} shapers to {shaper}")

    # ----------------------------------------------------------------- helpers
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _report(self, kind: str, level: int, message: str) -> None:
        now = self._now()
        if now - self._reported.get(kind, -math.inf) < float(self.get_parameter("error_throttle").value):
            return
        self._reported[kind] = now
        if level == DiagnosticStatus.ERROR:  # rclpy wants one severity per call site
            self.get_logger().error(message)
        else:
            self.get_logger().warning(message)
        status = DiagnosticStatus(level=level, name=f"{self.get_name()}: {kind}",
                                  hardware_id=self.get_fully_qualified_name(), message=message,
                                  values=[KeyValue(key="kind", value=kind)])
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    # ----------------------------------------------------------------- inputs
    def _on_joint_states(self, msg: JointState) -> None:
        names = list(msg.name)
        missing = [j for j in self.premises if j not in names]
        if missing or len(msg.position) != len(names):
            self.refused += 1
            why = f"missing joints {missing}" if missing else f"{len(msg.position)} positions for {len(names)} names"
            self._report("input", DiagnosticStatus.ERROR, f"refused joint_states: {why}")
            return
        z = [float(msg.position[names.index(j)]) for j in self.premises]
        if not all(math.isfinite(v) for v in z):
            self.refused += 1
            self._report("input", DiagnosticStatus.ERROR, f"refused joint_states: non-finite premise values {z}")
            return
        self._z, self._z_stamp, self._stamp = z, self._now(), msg.header.stamp

    def _on_active(self, msg: ShaperMsg) -> None:
        self._active = msg
        self._active_pub.publish(msg)

    # ----------------------------------------------------------------- scheduling
    def _tick(self) -> None:
        if self._z is None:
            return
        if self._now() - self._z_stamp > float(self.get_parameter("stale_timeout").value):
            self._report("stale", DiagnosticStatus.WARN, "no joint states for stale_timeout; not updating the shaper")
            return
        try:
            interp = self.core.evaluate(self._z)
        except FuzzyError as err:
            self._report("rule_base", DiagnosticStatus.ERROR, f"rule base: {err}")
            return
        if any(interp.clamped):
            out = [f"{n} = {v:.6g} outside [{lo:g}, {hi:g}]" for n, v, (lo, hi), c in
                   zip(self.premises, interp.z_in, self.core.rule_base.ranges, interp.clamped) if c]
            self._report("clamped", DiagnosticStatus.WARN, "premise " + "; ".join(out) + ": clamped, not extrapolated")
        est = ModeEstimate(source=SOURCE, modes=[ModeMsg(natural_frequency=m.omega, damping_ratio=m.zeta)
                                                 for m in interp.modes])
        est.header.stamp = self._stamp
        self._mode_pub.publish(est)
        self._interp = interp
        if self._pending and time.monotonic() - self._pending_since > float(
                self.get_parameter("service_timeout").value):
            # e.g. a reply lost while DDS was still matching the service's reply reader: ask again
            self._report("timeout", DiagnosticStatus.WARN, f"{self._set_cli.srv_name} did not answer within"
                         " service_timeout; sending again")
            self._pending = False
        if self._pending or self._held_by_learner or not self._service_settled():
            return
        threshold = float(self.get_parameter("relative_change").value)
        if self.last_sent is not None and relative_change(self.last_sent.modes, interp.modes) < threshold:
            return
        if self._now() - self._sent_at < self._min_gap():
            return
        self._send(interp)

    def _watch_service(self) -> None:
        if self._set_cli.service_is_ready():
            if self._ready_since is None:
                self._ready_since = time.monotonic()
        else:
            self._ready_since = None

    def _service_settled(self) -> bool:
        """set_shaper has been discovered for DISCOVERY_SETTLE s: a request sent as soon as the
        service appears may be answered before DDS has matched the reply reader, and the reply is
        lost (then service_timeout sends it again, but late)."""
        return self._ready_since is not None and time.monotonic() - self._ready_since > DISCOVERY_SETTLE

    def _min_gap(self) -> float:
        duration = self._active.times[-1] if self._active is not None and len(self._active.times) else 0.0
        return max(float(self.get_parameter("min_interval").value), duration / (MAX_STAGES - 1))

    def _send(self, interp: Interpolation) -> None:
        try:
            shaper = self.core.shaper(interp)
        except ShaperError as err:
            self._report("design", DiagnosticStatus.ERROR, f"no shaper for the interpolated modes: {err}")
            return
        msg = shaper_to_msg(shaper, SOURCE, 0, self.get_clock().now().to_msg())
        if shaper.family != "custom":  # a family design: the shaper node designs it on the modes
            msg.amplitudes, msg.times = [], []
        req = SetShaper.Request(shaper=msg)
        self._pending, self._pending_since = True, time.monotonic()
        self._call += 1
        self._sent_at = self._now()
        future = self._set_cli.call_async(req)
        future.add_done_callback(lambda f, i=interp, n=self._call: self._on_answer(f, i, n))

    def _on_answer(self, future, interp: Interpolation, call: int) -> None:
        if call != self._call:
            return  # the answer to a call given up after service_timeout (sent again since)
        self._pending = False
        resp = future.result()
        if resp is not None and resp.success:
            self.last_sent = interp
            self.sent += 1
        else:
            why = resp.message if resp is not None else "no answer"
            self._report("refused", DiagnosticStatus.WARN, f"shaper node refused the scheduled shaper: {why}")

    # ----------------------------------------------------------------- the learner's interface
    async def _on_set_shaper(self, req: SetShaper.Request, resp: SetShaper.Response) -> SetShaper.Response:
        source = req.shaper.source.strip() or "service"
        resp.active = self._active or ShaperMsg()
        if source != "learner":
            resp.success, resp.message = False, (f"the scheduler takes corrections from the learner only; source"
                                                 f" {source!r} sets {self._set_cli.srv_name} directly")
            return resp
        before = self.core.corrections.copy()
        interp = self._interp
        try:
            learned = shaper_from_msg(req.shaper)
            identity = learned.family == "none"
            if not identity:
                if interp is None:
                    raise ShaperError("no pose yet (no joint states): the correction has no operating region")
                region, corr = self.core.learn(interp, learned)
        except (ShaperError, FuzzyError) as err:
            resp.success, resp.message = False, f"refused: {err}"
            return resp
        if not self._set_cli.service_is_ready():
            self.core.corrections = before
            resp.success, resp.message = False, f"{self._set_cli.srv_name} not available"
            return resp
        self._pending = True
        try:
            answer = await self._set_cli.call_async(SetShaper.Request(shaper=req.shaper))
        finally:
            self._pending = False
        resp.success, resp.active = answer.success, answer.active
        if answer.success:
            self._held_by_learner = identity
            self._sent_at = self._now()
            if not identity:
                self.last_sent = interp
                name = self.core.rule_base.rules[region].name or str(region)
                self.get_logger().info(f"learner correction in region {name}: T2 x {corr[0]:.4f}, A1 x {corr[1]:.4f}")
                resp.message = f"{answer.message}; kept as the correction of region {name}"
            else:
                resp.message = f"{answer.message}; schedule held until the learner sends a shaper"
        else:
            self.core.corrections = before  # the learner's shaper did not become active: nothing learned
            resp.message = answer.message
        return resp

    async def _on_get_shaper(self, req: GetShaper.Request, resp: GetShaper.Response) -> GetShaper.Response:
        if not self._get_cli.service_is_ready():
            resp.active = self._active or ShaperMsg()
            return resp
        return await self._get_cli.call_async(GetShaper.Request())


def main(args: list[str] | None = None) -> int:
    return run_node(SchedulerNode, "scheduler", args)


if __name__ == "__main__":
    raise SystemExit(main())
