"""The arm demo's ``scheduled_speedup`` case: the calibrated schedule, and the learner's speed-up per move over it.

The learner (``mode: speed_moves``, shaper_nodes/nodes/learner_speed.py) serves its own FollowJointTrajectory
proxy in front of the shaper node's: the demo's client sends each move's goal to ``/learner/follow_joint_trajectory``,
the learner time-scales it by the move's learned factor and sends it on to ``/shaper/follow_joint_trajectory``,
which shapes it for its final pose (the schedule) and sends it to the controller. Every move is its own cycle on
``/cycle_events`` (the per-move cases' marking). A scaled goal ends earlier than planned: the client takes each
move's end where the arm comes to rest after it (:attr:`~.arm_client.ArmClient.ends_at_rest`), and its planned
duration as that less the dwell (the learner keeps the dwell's length), so that the measures' move + settle time is
the faster move's.

The limits: the UR5e's published joint speed, 180 deg/s, for every joint; joint accelerations up to
:data:`ACCELERATION` rad/s^2 (four times the moves' planned 6 rad/s^2: a factor up to 2; the ROS-free reproduction,
``reproductions.arm_learning``'s ``speedup``, computed the torques of factors up to 1.9 and found at most 43 % of the
joints' torque limits); and the torques measured during each move (the arm's ``/joint_states`` efforts: its motor
torques) against the UR5e's published joint torque limits, :data:`EFFORT` (a move past one is a bad cycle).
"""

from __future__ import annotations

import math
from typing import Any

from ..arm.description import JOINT_NAMES, TORQUE_LIMITS

#: rad/s: the UR5e's published joint speed limit, every joint (ur_description's joint_limits.yaml: 3.14159)
VELOCITY = math.pi
#: rad/s^2: the joint acceleration limit the demo gives the learner (module docstring)
ACCELERATION = 24.0
#: N m: the UR5e's published joint torque limits, base to wrist 3 (sim_plant_node.arm.description.TORQUE_LIMITS)
EFFORT = TORQUE_LIMITS
#: the largest factor the learner may reach
MAX_FACTOR = 2.0
#: the learner's raise per good cycle
STEP = 0.1
#: s without an answer before the client sends a goal request again
RESEND = 10.0


def learner_parameters() -> dict[str, Any]:
    """The learner's parameters in the demo (and the integration test's defaults)."""
    return {"mode": "speed_moves", "use_sim_time": True, "topics.imu_reliable": True,
            "speed.controller": "/shaper/follow_joint_trajectory", "speed.scheduler": "/scheduler",
            "speed.velocity": [VELOCITY], "speed.acceleration": [ACCELERATION], "speed.max_effort": list(EFFORT),
            "speed.max_factor": MAX_FACTOR, "speed.step": STEP}


def use_learner_proxy(client: Any, ends_at_rest: bool = True) -> None:
    """Send the client's goals to the learner's proxy, and (``ends_at_rest``) take each move's end where the arm
    rests."""
    from control_msgs.action import FollowJointTrajectory

    from shaper_nodes.ros.action_client import ResilientActionClient

    # a goal request is sent again (same goal id) only after RESEND s without an answer: under a load average of 30
    # the default 2 s resent many goals. A resent id runs once (rclpy's action server refuses the duplicate id and
    # the client goes on with the goal it accepted: tests/test_action_proxy_resend.py); the double run, one goal
    # preempting the other, seen at load 33 with 2 s (commit 3be4e0b) is not reproduced by a resend: cause unknown
    client.action = ResilientActionClient(client.c, FollowJointTrajectory, "/learner/follow_joint_trajectory",
                                          resend_period=RESEND)
    client.ends_at_rest = ends_at_rest


def start(session: Any, client: Any, imu: str, wait: float) -> str:
    """Start the speed learner and point the client at it (the learner's accelerometer topic ``imu``, its
    subscriptions of it and of /joint_states waited for up to ``wait`` s); returns what was installed (for the log)."""
    from shaper_nodes.ros.lockstep_reader import AckWatch

    session.start("shaper_nodes", "learner", learner_parameters())
    use_learner_proxy(client)
    client.wait_ready(4)  # the learner's action server, and its subscription of the cycle events
    # its efforts' subscription too: a move's torques unseen would leave it unlearned
    AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [imu, "/joint_states"], wait)
    return (f"calibrated schedule with the speed-up per move on top (each goal time-scaled by its move's factor"
            f" before it is shaped; limits {VELOCITY:.4g} rad/s, {ACCELERATION:g} rad/s^2, measured torques"
            f" {'/'.join(f'{e:g}' for e in EFFORT)} N m, factor up to {MAX_FACTOR:g})")


def status(m: dict[str, float]) -> str:
    """The learner's last report of a move, in words (the per-move table's last column)."""
    effort, speed = m.get("effort_ratio", math.nan), m.get("speed_ratio", math.nan)
    torque = ("" if math.isnan(effort) else f"; torque {100 * effort:.0f} % of its limit") + (
        "" if math.isnan(speed) else f"; speed {100 * speed:.0f} %") + ("; the raise cut by the prediction"
                                                                       if m.get("held") else "")
    return (f"factor {m['speed_factor']:.3f} ({'good' if m['ok'] else 'bad'}: peak {m['peak']:.3g} m/s^2,"
            f" {m['peak_mm']:.4f} mm at {m['frequency_hz']:.3g} Hz{torque}) -> {m['factor_next']:.3f}")


def summary(per_move: list[list[tuple[Any, Any, Any]]], rows: list[dict[str, Any]]) -> list[str]:
    """The case against the schedule: the cycle's summed move + settle time per cycle, and the learned factors."""
    from ..arm.metrics import SETTLE_TOLERANCE

    sched = [r for r in rows if r["case"] == "scheduled"]
    totals = [sum(float(m.move_and_settle_s) for _, m, _ in c) for c in per_move]
    out = ["", "Speed-up per move, summed over the cycle's moves: move + settle s per cycle "
           + ", ".join(f"c{k + 1} {t:.3f}" for k, t in enumerate(totals))]
    if sched:
        base = sum(float(r["move_and_settle_s"]) for r in sched)
        out.append(f"against the schedule's {base:.3f} s at planned speed: last cycle"
                   f" {100 * (1 - totals[-1] / base):.1f} % shorter")
    for what, key in (("joint torque", "effort"), ("joint speed", "speed")):
        largest: dict[str, tuple[float, str]] = {}  # the largest measured ratio to its limit per move, and its joint
        for c in per_move:
            for run, _, report in c:
                m = dict(zip(report.metric_names, report.metric_values, strict=True))
                ratio, joint = m.get(f"{key}_ratio", math.nan), int(m.get(f"{key}_joint", -1))
                if not math.isnan(ratio) and ratio >= largest.get(run.name, (-1.0, ""))[0]:
                    largest[run.name] = (ratio, JOINT_NAMES[joint] if 0 <= joint < len(JOINT_NAMES) else "?")
        if largest:
            out.append(f"largest measured {what} per move over all cycles, of its joint's limit: "
                       + ", ".join(f"{k} {100 * r:.0f} % ({j})" for k, (r, j) in largest.items()))
    factors: dict[str, list[str]] = {}  # per move, the factor of each cycle (* : a bad cycle)
    for c in per_move:
        for run, _, report in c:
            m = dict(zip(report.metric_names, report.metric_values, strict=True))
            factors.setdefault(run.name, []).append(f"{m.get('speed_factor', math.nan):.3f}"
                                                    + ("" if m.get("ok", 1.0) else "*"))
    out.append("factors per move by cycle (*: a bad cycle): " + "; ".join(f"{k} {' '.join(v)}"
                                                                          for k, v in factors.items()))
    worst = max(float(m.peak_mm) for c in per_move for _, m, _ in c)
    out.append("factors in the last cycle: " + ", ".join(f"{k} {v[-1]}" for k, v in factors.items())
               + f"; largest flange peak over all cycles {worst:.4f} mm (tolerance {1e3 * SETTLE_TOLERANCE:g} mm)")
    return out
