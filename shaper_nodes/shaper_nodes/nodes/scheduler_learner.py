"""The scheduler node's interface for the learner (:class:`~.scheduler.SchedulerNode`'s part): ``~/set_shaper``
takes the learner's shaper as a correction of the scheduled one in the pose's operating region and forwards it
unchanged to the shaper node (the identity shaper holds the schedule), ``~/get_shaper`` answers with the shaper
node's active shaper. The policy is the scheduler module's docstring ("Policy with the learner")."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import GetShaper, SetShaper
from shaper_nodes.core.scheduling import FuzzyError, Interpolation
from shaper_nodes.core.shaping import ShaperError, none_shaper
from shaper_nodes.ros.conversions import shaper_from_msg, shaper_to_msg

if TYPE_CHECKING:
    from shaper_nodes.core.scheduling import Scheduler
    from shaper_nodes.ros.shaper_client import ShaperClient


class LearnerInterface:
    """``~/set_shaper`` and ``~/get_shaper`` (module docstring): a mixin of :class:`~.scheduler.SchedulerNode`,
    whose attributes it uses are declared below."""

    if TYPE_CHECKING:
        core: Scheduler
        shaper: ShaperClient
        last_sent: Interpolation | None
        _active: ShaperMsg | None
        _interp: Interpolation | None
        _forwarding: bool
        _held_by_learner: bool
        _sent_at: float

        def _now(self) -> float: ...

        def get_logger(self) -> Any: ...

    async def _on_set_shaper(self, req: SetShaper.Request, resp: SetShaper.Response) -> SetShaper.Response:
        source = req.shaper.source.strip() or "service"
        resp.active = self._active or ShaperMsg()
        if source != "learner":
            resp.success, resp.message = False, (f"the scheduler takes corrections from the learner only; source"
                                                 f" {source!r} sets {self.shaper.srv_name} directly")
            return resp
        before = self.core.corrections.copy()
        interp = self._interp
        try:
            learned = shaper_from_msg(req.shaper)
            identity = learned.family == "none"
            region, corr = (0, (1.0, 1.0)) if identity else self._learn(interp, learned)
        except (ShaperError, FuzzyError) as err:
            resp.success, resp.message = False, f"refused: {err}"
            return resp
        self._forwarding = True
        try:
            answer = await self.shaper.set.call(SetShaper.Request(shaper=req.shaper))
        finally:
            self._forwarding = False
        if answer.response is None or not answer.response.success:
            self.core.corrections = before  # the learner's shaper did not become active: nothing learned
            resp.success, resp.message = False, answer.error if answer.response is None else answer.response.message
            return resp
        resp.success, resp.active = True, answer.response.active
        self._held_by_learner = identity
        self._sent_at = self._now()
        if identity:
            resp.message = f"{answer.response.message}; schedule held until the learner sends a shaper"
        else:
            self.last_sent = interp
            name = self.core.rule_base.rules[region].name or str(region)
            if self.core.factors[region] is not None:  # several modes: an extra factor (core docstring)
                what = f"extra factor T2 = {corr[0]:.4f} s, A1 = {corr[1]:.4f}"
            else:
                what = f"T2 x {corr[0]:.4f}, A1 x {corr[1]:.4f}"
            self.get_logger().info(f"learner correction in region {name}: {what}")
            resp.message = f"{answer.response.message}; kept as the correction of region {name}"
        return resp

    def _learn(self, interp: Interpolation | None, learned: Any) -> tuple[int, tuple[float, float]]:
        if interp is None:
            raise ShaperError("no pose yet (no joint states): the correction has no operating region")
        return self.core.learn(interp, learned)

    async def _on_get_shaper(self, req: GetShaper.Request, resp: GetShaper.Response) -> GetShaper.Response:
        assert self.shaper.get is not None
        answer = await self.shaper.get.call(GetShaper.Request())
        if answer.response is None:
            resp.active = self._active or shaper_to_msg(none_shaper(), "", 0)
            return resp
        return answer.response
