"""The arm demo's cases: which exist, which need a calibration or the scheduler, and how each is installed (its
shaper set, or the scheduler, the shaper node again and the learner started); the calibration step (the
``calibrate`` node) and the identifier's recommendation."""

from __future__ import annotations

import json
import pathlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .arm_client import IMU, WAIT, ArmClient

CASES = ("none", "zv", "zvd", "identified", "list", "fixed", "scheduled", "scheduled_list", "scheduled_list_moves",
         "scheduled_mrilc_moves", "payload", "scheduled_speedup", "list_moves")
#: the story ``./run demo`` tells: calibrate, then unshaped, the calibrated fixed shaper, the calibrated schedule
DEFAULT_CASES = ("none", "fixed", "scheduled")
#: cases that need a calibration
CALIBRATED = ("fixed", "scheduled", "scheduled_list", "scheduled_list_moves", "scheduled_mrilc_moves", "payload",
              "scheduled_speedup")
#: cases whose shaper node asks the scheduler for each goal (the shaper node is restarted for them)
SCHEDULED = ("scheduled", "scheduled_list", "scheduled_list_moves", "scheduled_mrilc_moves", "payload",
             "scheduled_speedup")
#: cases that mark every move as its own cycle on /cycle_events (the learner per move)
PER_MOVE = ("scheduled_list_moves", "scheduled_mrilc_moves", "payload", "scheduled_speedup", "list_moves")
#: cases that start a scheduler of their own and the shaper node again on it (they run after the SCHEDULED ones)
OWN_SCHEDULER = ("list_moves",)
#: the scheduler of ``list_moves``: family ``none`` (no calibration: no mode shaped), it only carries each move's
#: learned factor to the shaper node's proxy (``~/set_move_shaper``, ``~/shaper_at``)
NO_SCHEDULE = "/no_schedule"
#: most factors stacked per move in ``list_moves`` (the scheduler's limit: 2**4 = 16 impulses)
LIST_MOVES_FACTORS = 4
#: cases that learn (their cycles: --list-cycles)
LEARNING = ("list", "scheduled_list", *PER_MOVE)
#: s of wall time the calibration may take (a guard against a hang: on a loaded machine, load average 30 and two
#: CPU hogs, its identification alone took over 6 min of a 15 min run)
CALIBRATION_TIMEOUT = 3600.0


def identify(conductor: Any, identifier_cli: Any, cycles: int) -> tuple[Any, str]:
    """The identifier's recommendation from the last ``cycles`` cycles (not applied), and its summary."""
    from shaper_msgs.srv import Identify

    deadline = time.monotonic() + 60.0
    while True:  # the identifier closes a cycle once samples after its END came, or after its max wait
        resp = conductor.call(identifier_cli, Identify.Request(cycles=int(cycles), max_modes=3, apply=False),
                              timeout=120.0)
        if resp.success or "buffered" not in resp.message or time.monotonic() > deadline:
            break
        pause = time.monotonic() + 0.5
        conductor.spin_until(lambda: time.monotonic() > pause, 5.0, "the identifier's buffer")  # noqa: B023
    if not resp.success:
        raise RuntimeError(f"identification failed: {resp.message}")
    from shaper_nodes.ros.conversions import estimate_modes

    modes = ", ".join(f"{hz:.3f} Hz zeta {zeta:.3f}" for hz, zeta in estimate_modes(resp.estimate))
    return resp.recommended, f"{resp.recommended.family} for {modes}"


def calibrate(out: pathlib.Path, noise_log: pathlib.Path) -> pathlib.Path:
    """Run the ``calibrate`` node on the simulated arm (its installed config/calibrate.yaml) into
    ``out``; returns ``out``. Raises RuntimeError with the log's end if it fails."""
    from ament_index_python.packages import get_package_share_directory

    from shaper_nodes.ros.launching import NodeProcess

    config = pathlib.Path(get_package_share_directory("shaper_nodes")) / "config" / "calibrate.yaml"
    proc = NodeProcess("shaper_nodes", "calibrate", {}, log_path=noise_log, params_file=config,
                       args=["--execute", "--out", str(out)]).start()
    assert proc.proc is not None
    import subprocess

    try:
        code = proc.proc.wait(timeout=CALIBRATION_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.stop()
        raise RuntimeError(f"the calibration did not finish within {CALIBRATION_TIMEOUT:g} s (its log:"
                           f" {noise_log})") from None
    except BaseException:
        proc.stop()
        raise
    proc.stop()
    if code != 0:
        tail = "\n".join(noise_log.read_text().splitlines()[-5:])
        raise RuntimeError(f"calibration failed (exit {code}):\n{tail}")
    return out


def calibrate_step(out: pathlib.Path, t_wall: float) -> pathlib.Path:
    """Calibrate the workspace into ``out``/calibration (:func:`calibrate`, its log ``out``/arm-calibrate.log) and
    print what it found; ``t_wall`` is the demo's start (time.monotonic(), s). Returns the calibration folder."""
    print("calibrate: the workspace (config/calibrate.yaml) ... ", end="", flush=True)
    calibration = calibrate(out / "calibration", out / "arm-calibrate.log")
    report = json.loads((calibration / "report.json").read_text())
    print(f"{len(report['poses'])} poses, {len(report['flagged_poses'])} flagged; scheduler over"
          f" {', '.join(report['scheduler']['premises'])} ({time.monotonic() - t_wall:.0f} s)", flush=True)
    return calibration


def fallback_request(calibration: pathlib.Path) -> Any:
    """The SetShaper request for the calibration's fallback shaper (shaper.yaml)."""
    import yaml

    from shaper_msgs.msg import Shaper as ShaperMsg
    from shaper_msgs.srv import SetShaper
    from shaper_nodes.ros.conversions import mode_msg

    (body,) = yaml.safe_load((calibration / "shaper.yaml").read_text()).values()
    sh = body["ros__parameters"]["shaper"]
    modes = [mode_msg(float(f), float(z)) for f, z in zip(sh["frequencies_hz"], sh["damping_ratios"], strict=True)]
    return SetShaper.Request(shaper=ShaperMsg(family=str(sh["family"]), design_modes=modes, source="user"))


@dataclass
class Session:
    """What the cases share: the node starter, the shaper node's process, the calibration."""

    start: Callable[..., Any]
    shaper: Any
    shaper_params: dict[str, Any]
    calibration: pathlib.Path | None = None
    scheduled: bool = False
    payload_learner: str = "list"  # the payload case's learner: "list" or "mrilc" (clients/arm_payload.py)


def _schedule(session: Session, client: ArmClient) -> None:
    """Start the calibrated scheduler, and the shaper node again with action.scheduler (once)."""
    if session.scheduled:
        return
    assert session.calibration is not None
    session.shaper.stop()
    session.start("shaper_nodes", "scheduler", {"use_sim_time": True},
                  params_file=session.calibration / "scheduler.yaml")
    session.shaper = session.start("shaper_nodes", "shaper_node", {**session.shaper_params,
                                                                    "action.scheduler": "/scheduler"})
    session.scheduled = True
    client.c.wait_ready(60.0, {})
    client.wait_ready(3)


def apply_case(case: str, client: ArmClient, recommended: tuple[Any, str] | None, home_mode: Any,
                session: Session) -> str:
    """Install the case's shaper (or start its learner); returns what was installed, for the log."""
    from shaper_msgs.srv import SetShaper

    conductor = client.c
    if case in ("none", "zv", "zvd"):
        conductor.set_shaper(case, home_mode.omega, home_mode.zeta)
        return case if case == "none" else f"{case} at {home_mode.hz:.3f} Hz, zeta {home_mode.zeta:.3f}"
    if case == "identified":
        if recommended is None:
            raise RuntimeError("the identified case needs the unshaped case's cycles first")
        shaper = recommended[0]
        shaper.source, shaper.family = "identification", "custom"  # its impulses as identified, as the identifier sends
        resp = conductor.call(conductor.set_shaper_cli, SetShaper.Request(shaper=shaper))
        if not resp.success:
            raise RuntimeError(f"the shaper refused the recommendation: {resp.message}")
        return recommended[1]
    if case == "fixed":
        assert session.calibration is not None
        req = fallback_request(session.calibration)
        resp = conductor.call(conductor.set_shaper_cli, req)
        if not resp.success:
            raise RuntimeError(f"the shaper refused the calibrated fallback: {resp.message}")
        from shaper_nodes.ros.conversions import msg_hz

        return (f"calibrated fallback: {req.shaper.family} on the home pose's modes "
                + ", ".join(f"{msg_hz(m):.3f} Hz" for m in req.shaper.design_modes))
    if case == "list_moves":
        return _list_moves(session, client)
    if case in SCHEDULED:
        _schedule(session, client)
        if case == "scheduled":
            return "calibrated schedule: each goal shaped for the modes at its final pose"
        if case == "scheduled_mrilc_moves" or (case == "payload" and session.payload_learner == "mrilc"):
            return _mrilc_moves(session, client)
        if case == "scheduled_speedup":
            from . import arm_speed

            return arm_speed.start(session, client, IMU, WAIT)
        if case in PER_MOVE:
            from shaper_nodes.ros.lockstep_reader import AckWatch

            # every sample of a move, reliable (the plant rests between goals, and the next goal waits for the
            # learner's report of the move: its queue of 10 s holds a move)
            payback = case == "scheduled_list_moves"  # each factor chosen to pay: the goals through the learner
            session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2",
                                                       "shaper": "/scheduler", "list.per_move": True,
                                                       "topics.imu_reliable": True, "payback.enabled": payback})
            if payback:
                from . import arm_speed

                arm_speed.use_learner_proxy(client, ends_at_rest=False)
                client.wait_ready(4)  # the learner's action server, and its subscription of the cycle events
            else:
                client.wait_listeners(4)  # and the learner
            AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [IMU], WAIT)
            return "calibrated schedule with LIST (zv2) per move on top" + (", chosen to pay" if payback else "")
        session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2",
                                                   "shaper": "/scheduler"})
        client.wait_listeners(4)  # and the learner
        return "calibrated schedule with LIST (zv2) on top"
    conductor.set_shaper("none")
    session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2"})
    client.wait_listeners(4)  # and the learner
    return "LIST (zv2), from unshaped"


def _mrilc_moves(session: Session, client: ArmClient) -> str:
    """MRILC per move: the shaper node again, its proxy sending the shaped goals to the learner's proxy, and the
    learner (``mode: mrilc_moves``) in front of the controller, the sim arm's operator and the moves' planning
    limits."""
    from shaper_nodes.ros.lockstep_reader import AckWatch

    from ..arm.task import MAX_ACCELERATION, MAX_VELOCITY

    session.shaper.stop()
    session.start("shaper_nodes", "learner", {"mode": "mrilc_moves", "use_sim_time": True,
                                               "topics.imu_reliable": True,
                                               "mrilc_moves.operator": "sim_plant_node.arm.lifted:arm_operator",
                                               "mrilc_moves.modes": "sim_plant_node.arm.lifted:arm_modes",
                                               "mrilc_moves.velocity": [MAX_VELOCITY],
                                               "mrilc_moves.acceleration": [MAX_ACCELERATION]})
    session.shaper = session.start("shaper_nodes", "shaper_node", {
        **session.shaper_params, "action.scheduler": "/scheduler",
        "action.controller": "/learner/follow_joint_trajectory"})
    client.c.wait_ready(60.0, {})
    client.wait_ready(4)  # and the learner
    AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [IMU], WAIT)
    return ("calibrated schedule with MRILC per move on top (each move's joint profile correction added by the"
            " learner's proxy)")


def _list_moves(session: Session, client: ArmClient) -> str:
    """LIST per move with no calibration (issue 31's "LIST per move alone"): a scheduler of family ``none`` (no mode
    shaped; its one rule's mode is never used) at :data:`NO_SCHEDULE`, only to keep each move's factor and give it
    to the shaper node's proxy for that move's goals; the shaper node again on it; the learner's LIST per move with
    each factor chosen to pay (``payback.enabled``, up to :data:`LIST_MOVES_FACTORS` stacked; the goals through the
    learner's proxy): each move's first cycle is its unshaped reference; the next factor goes on the lowest mode
    still ringing, predicted not to lengthen the move + settle time measured on the accelerometer, and is kept only
    when its cycle pays against its reference (a lower residual, a move + settle time no longer by more than one
    2 ms sample); a new reference with the kept factors looks for the next (nodes/learner_payback.py)."""
    import math

    from shaper_nodes.ros.lockstep_reader import AckWatch

    from ..arm.description import JOINT_NAMES

    listeners = client.events.get_subscription_count()  # of the cycle events before the learner (the demo: 3)
    session.shaper.stop()
    reach = 2.0 * math.pi
    session.start("shaper_nodes", "scheduler", {
        "use_sim_time": True, "family": "none", "interpolation": "modes", "premises": [JOINT_NAMES[1]],
        "range": [-reach, reach], "rule_names": ["any"], "rules.any.membership": ["triangular"],
        "rules.any.membership_params": [-reach - 1.0, 0.0, reach + 1.0], "rules.any.frequency_hz": [1.0],
        "rules.any.damping_ratio": [0.05]}, remaps={"__node": NO_SCHEDULE.lstrip("/")})
    session.shaper = session.start("shaper_nodes", "shaper_node", {**session.shaper_params,
                                                                    "action.scheduler": NO_SCHEDULE})
    session.scheduled = False  # (the shaper node follows this scheduler now)
    client.c.wait_ready(60.0, {})
    client.wait_ready(listeners)
    session.start("shaper_nodes", "learner", {"mode": "list", "use_sim_time": True, "list.structure": "zv2",
                                               "shaper": NO_SCHEDULE, "list.per_move": True,
                                               "list.start": "identified", "topics.imu_reliable": True,
                                               "payback.enabled": True, "payback.max_factors": LIST_MOVES_FACTORS,
                                               # the demo's drift watch rates each move against the calibrated
                                               # /scheduler's shaper (watch.scheduler), which no goal runs with here:
                                               # its WARN is no drift of this case (a first run relearned every move at
                                               # cycle 2 on home->pick's 29 Hz loop transient, out of the calibrated
                                               # shaper's band); with no calibration there is nothing to watch against
                                               "list.drift_status": ""})
    from . import arm_speed

    arm_speed.use_learner_proxy(client, ends_at_rest=False)
    client.wait_ready(listeners + 1)  # the learner's action server, and its subscription of the cycle events
    AckWatch(client.c, "/learner").wait_subscribed(client.c.spin_until, [IMU], WAIT)
    return (f"LIST (zv2) per move with no calibration: up to {LIST_MOVES_FACTORS} factors stacked per move, a full"
            " pair on each ringing mode lowest first, then on the lowest still ringing, each kept only if it pays"
            " (residual and measured move + settle)")
