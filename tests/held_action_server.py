# Copyright 2026 The ros2 vibration suppression authors
# SPDX-License-Identifier: Apache-2.0
"""A FollowJointTrajectory action server in a process of its own, to be killed, restarted or paused by a test.

``python held_action_server.py ACTION``: serves ACTION (node ``held_controller``); every goal it accepts is held
(executing) until a message on ``/held_controller/release`` (std_msgs/Empty), then succeeds with error_string
``released``. It runs until killed (SIGINT ends it cleanly).
"""

from __future__ import annotations

import sys


def main(action: str) -> None:
    import rclpy
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionServer
    from rclpy.executors import ExternalShutdownException
    from rclpy.task import Future
    from std_msgs.msg import Empty

    rclpy.init()
    node = rclpy.create_node("held_controller")
    held: list[Future] = []

    async def execute(handle):
        hold = Future()
        held.append(hold)
        await hold
        handle.succeed()
        return FollowJointTrajectory.Result(error_string="released")

    def release(_msg) -> None:
        for hold in held:
            if not hold.done():
                hold.set_result(None)

    server = ActionServer(node, FollowJointTrajectory, action, execute_callback=execute)
    node.create_subscription(Empty, "/held_controller/release", release, 10)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        server.destroy()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main(sys.argv[1])
