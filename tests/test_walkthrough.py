"""The integrator's path of docs/guide/calibration.md, run as written.

The guide marks one bash block (``<!-- walkthrough: ... -->`` before it): start the simulated arm,
print the calibration plan, calibrate, start the scheduler and the shaper node from the files the
calibration wrote, send a goal with ``send_goal``. This test takes the commands from that block and
runs each one as it stands, through ``bash -c`` in the repository's root, changing nothing but the
ROS domain (the environment) and the output folder (``cal`` becomes a folder of the test's own); a
command ending in ``&`` runs in the background, as in the terminal. After each command it waits for
what that step must give (a state, never a fixed time), with generous bounds:

- the sim plant: joint states of the arm's six joints, at the home pose;
- the plan: printed, exit 0, nothing written;
- the calibration: exit 0 and its files (report, scheduler.yaml, shaper.yaml naming the joints and the
  scheduler);
- the scheduler: its ``~/shaper_at`` service; the shaper node: its FollowJointTrajectory server;
- the goal: ``send_goal`` prints ``succeeded`` and exits 0, the shaper node's log says the goal was shaped
  for its final pose (the scheduler answered), and the arm's joint states reach the goal.
"""

from __future__ import annotations

import os
import pathlib
import re
import signal
import subprocess
import time

import numpy as np
import pytest
import rclpy
import yaml
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState

from shaper_msgs.srv import ShaperAt

ROOT = pathlib.Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "guide" / "calibration.md"
MARK = "<!-- walkthrough:"
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
#: the steps of the walkthrough, in order, as recognised from each command
STEPS = ["sim_plant", "plan", "calibrate", "scheduler", "shaper_node", "send_goal"]
#: the output folder as the guide names it (a word of its own, or before a /)
OUT = re.compile(r"(?<![\w./-])cal(?=/|\s|$)")


def walkthrough_commands(text: str) -> list[str]:
    """The commands of the bash block after the walkthrough mark, continuation lines joined, comments and
    blank lines left out."""
    start = text.index(MARK)
    block = re.search(r"```bash\n(.*?)```", text[start:], re.S)
    assert block is not None, "no bash block after the walkthrough mark"
    joined = block.group(1).replace("\\\n", " ")
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.strip().startswith("#")]


def step_of(command: str) -> str:
    """Which step a command is (by its executable and arguments)."""
    words = command.split()
    assert words[:2] == ["./run", "exec"], f"not a ./run exec command: {command}"
    exe = words[2]
    if exe == "calibrate":
        return "calibrate" if "--execute" in words else "plan"
    return exe


def test_the_guide_gives_the_whole_path_in_its_walkthrough_block():
    commands = walkthrough_commands(GUIDE.read_text())
    assert [step_of(c) for c in commands] == STEPS
    background = [step_of(c) for c in commands if c.endswith("&")]
    assert background == ["sim_plant", "scheduler", "shaper_node"]  # the nodes stay up; the rest end
    scheduler, shaper = commands[3], commands[4]
    assert "cal/scheduler.yaml" in scheduler and "cal/shaper.yaml" in shaper  # the files calibration wrote
    assert not re.search(r"-p (joint_names|action\.|topics\.)", shaper)  # nothing added to them


class Walk:
    """Runs the guide's commands and remembers the background ones, to stop them at the end."""

    def __init__(self, tmp_path: pathlib.Path, domain_id: int) -> None:
        self.tmp = tmp_path
        self.env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        self.background: list[tuple[subprocess.Popen, pathlib.Path]] = []

    def start(self, command: str, index: int) -> tuple[subprocess.Popen, pathlib.Path]:
        log = self.tmp / f"step{index}-{step_of(command)}.log"
        with open(log, "wb") as f:
            proc = subprocess.Popen(["bash", "-c", command.rstrip("&").strip()], cwd=ROOT, env=self.env,
                                    stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
        return proc, log

    def run(self, command: str, index: int, timeout: float) -> tuple[int, str]:
        proc, log = self.start(command, index)
        try:
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.stop(proc)
            pytest.fail(f"{command!r} did not end within {timeout:g} s:\n{tail(log)}")
        return code, log.read_text()

    def stop(self, proc: subprocess.Popen) -> None:
        """Ctrl-C to the command's process group, as in a terminal; SIGKILL if it does not end in 15 s."""
        if proc.poll() is not None:
            return
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    def close(self) -> None:
        for proc, _ in reversed(self.background):
            self.stop(proc)


def tail(log: pathlib.Path, lines: int = 25) -> str:
    return "\n".join(log.read_text(errors="replace").splitlines()[-lines:])


class Probe:
    """A node that watches what the steps must give: joint states, the scheduler's service, the action."""

    def __init__(self, context) -> None:
        self.node = rclpy.create_node("walkthrough_probe", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.position: np.ndarray | None = None
        self.node.create_subscription(JointState, "/joint_states", self._on_state, 10)

    def _on_state(self, msg: JointState) -> None:
        names = list(msg.name)
        if all(j in names for j in JOINTS):
            self.position = np.array([msg.position[names.index(j)] for j in JOINTS])

    def until(self, done, timeout: float, what: str, procs=()) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            for proc, log in procs:
                assert proc.poll() is None, f"{what}: the command ended (exit {proc.returncode}):\n{tail(log)}"
            assert time.monotonic() < deadline, f"no {what} within {timeout:g} s"
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def test_the_walkthrough_runs_as_written(tmp_path, domain_id, ros_context):
    commands = walkthrough_commands(GUIDE.read_text())
    assert [step_of(c) for c in commands] == STEPS
    out = tmp_path / "cal"
    walk = Walk(tmp_path, domain_id)
    probe = Probe(ros_context)
    try:
        for i, written in enumerate(commands):
            command = OUT.sub(str(out), written)
            step = step_of(command)
            if step in ("calibrate", "scheduler", "shaper_node"):
                assert str(out) in command, f"the output folder was not found in {written!r}"
            if command.endswith("&"):
                proc, log = walk.start(command, i)
                walk.background.append((proc, log))
                _check_node(step, probe, [(proc, log)])
                continue
            timeout = {"plan": 300.0, "calibrate": 1200.0, "send_goal": 600.0}[step]
            code, text = walk.run(command, i, timeout)
            assert code == 0, f"{written!r} exited {code}:\n{text[-3000:]}"
            _check_result(step, text, out, probe, walk)
    finally:
        walk.close()
        probe.close()


def _check_node(step: str, probe: Probe, procs) -> None:
    if step == "sim_plant":
        probe.until(lambda: probe.position is not None, 180.0, "joint states of the arm", procs)
        assert probe.position == pytest.approx(HOME, abs=1e-3)
    elif step == "scheduler":
        client = probe.node.create_client(ShaperAt, "/scheduler/shaper_at")
        probe.until(client.service_is_ready, 180.0, "service /scheduler/shaper_at", procs)
    elif step == "shaper_node":
        action = ActionClient(probe.node, FollowJointTrajectory, "/shaper/follow_joint_trajectory")
        probe.until(action.server_is_ready, 180.0, "action server /shaper/follow_joint_trajectory", procs)
    else:
        pytest.fail(f"no check for a background {step}")


def _check_result(step: str, text: str, out: pathlib.Path, probe: Probe, walk: Walk) -> None:
    if step == "plan":
        assert "calibration plan:" in text and "plan only" in text, text
        assert not out.exists()  # a plan writes nothing
    elif step == "calibrate":
        for name in ("report.json", "report.md", "scheduler.yaml", "shaper.yaml", "modes_vs_pose.png",
                     "residual.png"):
            assert (out / name).is_file(), f"{name} not written:\n{text[-2000:]}"
        shaper = yaml.safe_load((out / "shaper.yaml").read_text())["/**"]["ros__parameters"]
        assert shaper["joint_names"] == JOINTS and shaper["action"]["scheduler"] == "/scheduler"
    elif step == "send_goal":
        assert "send_goal: succeeded: error_code 0" in text, text
        goal = [float(x) for x in re.search(r"--positions ((?:\S+ ){5}\S+)", _command(walk, "send_goal")).group(1)
                .split()]
        probe.position = None
        probe.until(lambda: probe.position is not None and np.allclose(probe.position, goal, atol=1e-3), 120.0,
                    f"joint states at the goal {goal}")
        shaper_log = next(log for _, log in walk.background if "shaper_node" in log.name)
        deadline = time.monotonic() + 60.0
        while "goal shaped for its final pose" not in shaper_log.read_text(errors="replace"):
            assert time.monotonic() < deadline, f"the shaper node did not shape for the final pose:\n{tail(shaper_log)}"
            probe.executor.spin_once(timeout_sec=0.1)
    else:
        pytest.fail(f"no check for {step}")


def _command(walk: Walk, step: str) -> str:
    return next(c for c in walkthrough_commands(GUIDE.read_text()) if step_of(c) == step)
