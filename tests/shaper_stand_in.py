"""A stand-in for the shaper node's services, for tests where the shaper node itself must not run."""

from __future__ import annotations

from typing import Any


class ShaperStandIn:
    """A ``/shaper/set_shaper`` server that accepts every request (kept in ``requests``), answering ``message``;
    with ``active``, also the shaper node's latched ``/shaper/active_shaper`` publishing the identity (revision 1),
    so a learner's first cycle is its reference."""

    def __init__(self, ctx, name: str = "shaper_stand_in", message: str = "accepted", active: bool = False) -> None:
        from rclpy.node import Node

        from shaper_msgs.msg import Shaper
        from shaper_msgs.srv import SetShaper
        from shaper_nodes.ros.qos import LATCHED

        self.node = Node(name, context=ctx)
        self.requests: list = []

        def accept(req, resp):
            self.requests.append(req)
            resp.success, resp.message = True, message
            return resp

        self.node.create_service(SetShaper, "/shaper/set_shaper", accept)
        self.active: Any = None
        if active:
            self.active = self.node.create_publisher(Shaper, "/shaper/active_shaper", LATCHED)
            self.active.publish(Shaper(family="none", amplitudes=[1.0], times=[0.0], source="learner", revision=1))
