"""A huge FollowJointTrajectory goal against the installed shaper node (issue 33, item 3).

Figures, not pass/fail. ``python -m benchmarks.big_goal --points 1000000`` starts ``shaper_node`` (6 joints at
500 Hz, ZV) on the current ROS_DOMAIN_ID, sends one goal of that many points (positions only, 1 ms apart),
``--repeat`` times, and prints the shaper's RSS before (``VmRSS``), its peak (``VmHWM``) and 3 s after each
answer, with the time the answer took. ``--profile`` instead measures, in this process, rclpy's conversion of
such a request against the node's own checks (``WholeShaping.shape`` on the converted message).
"""

from __future__ import annotations

import argparse
import subprocess
import time


def _memory(pid: int) -> dict[str, float]:
    """VmRSS and VmHWM of ``pid``, MiB."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out[key] = int(value.split()[0]) / 1024
    return out


def _goal(points: int, joints: list[str]):
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    pts = [JointTrajectoryPoint(positions=[0.0] * len(joints),
                                time_from_start=Duration(sec=1 + k // 1000, nanosec=(k % 1000) * 1_000_000))
           for k in range(points)]
    return FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=joints, points=pts))


def node_run(points: int, repeat: int, joints: list[str]) -> None:
    import rclpy
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionClient
    from rclpy.node import Node

    from shaper_nodes.ros.launching import ros_args

    proc = subprocess.Popen(["shaper_node", *ros_args({"joint_names": joints, "command_rate": 500.0,
                                                       "shaper.family": "zv"})],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rclpy.init()
    node = Node("big_goal_bench")
    client = ActionClient(node, FollowJointTrajectory, "/shaper/follow_joint_trajectory")
    try:
        while not client.server_is_ready():
            if proc.poll() is not None:
                raise SystemExit("shaper_node ended before its action server came up")
            rclpy.spin_once(node, timeout_sec=0.1)
        time.sleep(3.0)
        print(f"shaper RSS before: {_memory(proc.pid)['VmRSS']:.0f} MiB", flush=True)
        goal = _goal(points, joints)
        for k in range(repeat):
            began = time.monotonic()
            sent = client.send_goal_async(goal)
            converted = time.monotonic()
            while not sent.done():
                rclpy.spin_once(node, timeout_sec=0.1)
            answered = time.monotonic()
            time.sleep(3.0)
            mem = _memory(proc.pid)
            print(f"goal {k + 1}, {points} points: accepted {sent.result().accepted}; client conversion"
                  f" {converted - began:.1f} s, answer {answered - converted:.1f} s after it; shaper RSS peak"
                  f" {mem['VmHWM']:.0f} MiB, 3 s after the answer {mem['VmRSS']:.0f} MiB", flush=True)
    finally:
        proc.terminate()
        proc.wait(30)
        node.destroy_node()
        rclpy.shutdown()


def profile(points: int, joints: list[str]) -> None:
    from control_msgs.action import FollowJointTrajectory
    from rclpy.serialization import deserialize_message, serialize_message

    from shaper_nodes.core.checks import InputError
    from shaper_nodes.core.shaping import design, discretize
    from shaper_nodes.core.shaping.families import Mode
    from shaper_nodes.core.shaping.limits import JointLimits
    from shaper_nodes.ros.whole_trajectory import WholeShaping

    request_type = FollowJointTrajectory.Impl.SendGoalService.Request
    data = serialize_message(request_type(goal=_goal(points, joints)))
    began = time.perf_counter()
    msg = deserialize_message(data, request_type).goal.trajectory
    rclpy_s = time.perf_counter() - began
    fir = discretize(design("zv", [Mode.from_hz(10.0, 0.05)]), 500.0)
    how = WholeShaping(tuple(joints), 500.0, fir, JointLimits.unset(joints), 1e6, 5000)
    began = time.perf_counter()
    try:
        how.shape(msg)
        outcome = "shaped"
    except InputError as err:
        outcome = f"refused: {err}"
    print(f"{points} points: rclpy's conversion {rclpy_s:.2f} s; the node's own checks"
          f" {1e3 * (time.perf_counter() - began):.1f} ms ({outcome})")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="big_goal", description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, default=1_000_000, help="points of the goal (default 10^6)")
    p.add_argument("--repeat", type=int, default=1, help="goals sent one after the other (default 1)")
    p.add_argument("--profile", action="store_true", help="rclpy's conversion against the node's checks")
    args = p.parse_args(argv)
    joints = [f"j{k}" for k in range(6)]
    if args.profile:
        profile(args.points, joints)
    else:
        node_run(args.points, args.repeat, joints)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
