"""The sim plant's lockstep in blocks (``lockstep.block``) through a real shaper process over DDS: the
same run as one setpoint per exchange, sample for sample; and the shaper's block input refused whole."""

import math

import pytest
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from shaper_msgs.msg import CycleEvent
from shaper_nodes.ros.conversions import time_to_sec
from sim_plant_node.clients.conductor import Conductor

pytestmark = pytest.mark.integration

HZ, ZETA, RATE = 4.0, 0.02, 250.0
RELIABLE = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)


def _run(start_node, ros_context, block: int) -> dict[str, list]:
    """Two cycles with ZVD, a change to ZV at rest, two cycles more; what the plant published."""
    plant = start_node("sim_plant_node", "sim_plant", {
        "joint_names": ["a", "b"], "rate": RATE, "mode": "lockstep", "lockstep.block": block,
        "task.start": [0.0, 0.2], "task.goal": [0.5, -0.3], "task.dwell": 1.0, "task.preroll": 0.3,
        "task.max_velocity": 1.0, "task.max_acceleration": 8.0, "lockstep_timeout": 60.0})
    shaper = start_node("shaper_nodes", "shaper_node", {"joint_names": ["a", "b"], "command_rate": RATE})
    got: dict[str, list] = {"imu": [], "js": [], "events": []}
    conductor = Conductor(context=ros_context)
    conductor.create_subscription(Imu, "/tip_imu", lambda m: got["imu"].append(
        (time_to_sec(m.header.stamp), m.linear_acceleration.x, m.linear_acceleration.y)), RELIABLE)
    conductor.create_subscription(JointState, "/joint_states", lambda m: got["js"].append(
        (time_to_sec(m.header.stamp), *m.position, *m.velocity)), RELIABLE)
    conductor.create_subscription(CycleEvent, "/cycle_events", lambda m: got["events"].append(
        (time_to_sec(m.header.stamp), m.event, m.cycle)), RELIABLE)
    try:
        conductor.wait_ready(60.0, {"/shaper/commands": 1, "/forward_position_controller/commands": 1,
                                    "/tip_imu": 2, "/joint_states": 2, "/cycle_events": 2})
        conductor.set_plant_mode(2 * math.pi * HZ, ZETA)
        conductor.set_shaper("zvd", 2 * math.pi * HZ, ZETA)
        conductor.run_cycles(2, timeout=300.0)
        conductor.set_shaper("zv", 2 * math.pi * HZ * 1.1, ZETA)
        conductor.run_cycles(2, timeout=300.0)
        ends = lambda: [e[0] for e in got["events"] if e[1] == CycleEvent.END]  # noqa: E731
        conductor.spin_until(lambda: len(ends()) == 4, 60.0, "the four cycles' ends")
        conductor.spin_until(lambda: all(got[k] and max(r[0] for r in got[k]) >= ends()[-1] for k in ("imu", "js")),
                             60.0, "the samples up to the last end")
    finally:
        conductor.close()
    assert plant.running() and shaper.running()
    assert plant.stop() == 0 and shaper.stop() == 0
    return got


def test_a_run_in_blocks_is_the_run_one_setpoint_at_a_time(start_node, ros_context):
    one = _run(start_node, ros_context, 1)
    block = _run(start_node, ros_context, 25)
    assert [e for e in block["events"]] == [e for e in one["events"]]
    for key in ("imu", "js"):
        a, b = {r[0]: r[1:] for r in one[key]}, {r[0]: r[1:] for r in block[key]}
        # step for step the same stamps; a loaded machine may keep a sample or two of a fast reliable stream
        # from this reader (seen once: 1781 of 1782 IMU samples), which says nothing of the plant
        assert len(a) > 4 * RATE and len(set(a) ^ set(b)) <= 2, (key, len(a), len(b), sorted(set(a) ^ set(b)))
        common = sorted(set(a) & set(b))
        scale = max(abs(v) for t in common for v in a[t])
        worst = max(abs(x - y) for t in common for x, y in zip(a[t], b[t], strict=True))
        assert worst <= 1e-9 * scale, (key, worst, scale)
    assert max(abs(r[1]) for r in one["imu"]) > 0.1  # the run moved and rang


def test_the_shaper_shapes_a_block_as_its_samples_and_refuses_a_bad_one_whole(start_node, ros_context):
    shaper = start_node("shaper_nodes", "shaper_node", {"joint_names": ["a", "b"], "command_rate": RATE,
                                                      "limits.max_trajectory_samples": 100})
    conductor = Conductor(context=ros_context)
    out: list[Float64MultiArray] = []
    conductor.create_subscription(Float64MultiArray, "/forward_position_controller/commands", out.append, 100)
    pub = conductor.create_publisher(Float64MultiArray, "/shaper/commands", 100)
    try:
        conductor.spin_until(lambda: pub.get_subscription_count() > 0 and conductor.count_publishers(
            "/forward_position_controller/commands") > 0, 60.0, "the shaper's streams")
        conductor.set_shaper("zv", 2 * math.pi * HZ, 0.0)

        def block(rows: list[list[float]], dims: list[int] | None = None) -> Float64MultiArray:
            msg = Float64MultiArray(data=[v for r in rows for v in r])
            shape = dims or [len(rows), 2]
            msg.layout.dim = [MultiArrayDimension(label=name, size=n, stride=0)
                              for name, n in zip(("samples", "joints", "more"), shape, strict=False)]
            return msg

        pub.publish(Float64MultiArray(data=[0.0, 0.0]))  # at rest at zero
        conductor.spin_until(lambda: len(out) == 1, 60.0, "the first sample")
        pub.publish(block([[1.0, 2.0]] * 3))  # a step: ZV passes half at once
        conductor.spin_until(lambda: len(out) == 2, 60.0, "the block")
        assert [d.size for d in out[1].layout.dim] == [3, 2]
        assert out[1].data.tolist() == pytest.approx([0.5, 1.0] * 3, abs=1e-12)
        pub.publish(block([[1.0, 2.0], [math.nan, 2.0]]))  # refused whole
        pub.publish(block([[1.0, 2.0]] * 2, dims=[2, 3]))  # a layout not of samples x joints
        pub.publish(block([[1.0, 2.0]] * 101))  # more than limits.max_trajectory_samples
        pub.publish(Float64MultiArray(data=[1.0, 2.0]))  # one sample goes on where the stream was
        conductor.spin_until(lambda: len(out) == 3, 60.0, "the sample after the refused blocks")
        reasons = ("refused non_finite on /shaper/commands",
                   "layout [2, 3] does not describe samples x 2 joints in 4 values",
                   "a block of 101 samples is more than limits.max_trajectory_samples (100)")
        conductor.spin_until(lambda: all(r in shaper.log_path.read_text(errors="replace") for r in reasons), 60.0,
                             "the refusals in the shaper's log")
    finally:
        conductor.close()
    assert len(out[2].data) == 2 and out[2].data.tolist() == pytest.approx([0.5, 1.0], abs=1e-12)
    assert shaper.running()



@pytest.mark.parametrize("block", [1, 5])
def test_an_answer_that_comes_after_the_timeout_is_not_applied_to_a_later_step(start_node, ros_context, block):
    """A peer in the shaper's place leaves the first ask unanswered past ``lockstep_timeout`` (the plant holds the
    setpoint and asks again), answers it then, with values far from it, and from there answers every ask with its
    own data and layout, as the shaper does with no filter. The late answer is reported and applied to no step:
    the setpoints the plant applied (``~/reference``) are, ask by ask, the ask's own rows or, for an ask that timed
    out, the held setpoint."""
    plant = start_node("sim_plant_node", "sim_plant", {
        "joint_names": ["a", "b"], "rate": RATE, "mode": "lockstep", "lockstep.block": block,
        "task.start": [0.0, 0.2], "task.goal": [0.5, -0.3], "task.dwell": 0.2, "task.preroll": 0.1,
        "task.max_velocity": 1.0, "task.max_acceleration": 8.0, "task.cycles": 1, "lockstep_timeout": 1.0})
    asks: list[Float64MultiArray] = []
    applied: list[tuple[float, ...]] = []
    ends: list[int] = []
    conductor = Conductor(context=ros_context)
    # the reference subscription is announced before the command subscription, in order: once the plant has
    # matched the latter (its start gate), it has matched the former
    conductor.create_subscription(JointState, "/sim_plant/reference", lambda m: applied.append(tuple(m.position)),
                                  RELIABLE)
    conductor.create_subscription(CycleEvent, "/cycle_events",
                                  lambda m: ends.append(m.cycle) if m.event == CycleEvent.END else None, RELIABLE)
    conductor.create_subscription(Float64MultiArray, "/shaper/commands", asks.append, RELIABLE)
    answer = conductor.create_publisher(Float64MultiArray, "/forward_position_controller/commands", RELIABLE)
    try:
        conductor.start_task()  # once the plant has matched this peer's command endpoints (it asks again till then)
        conductor.spin_until(lambda: len(asks) >= 2, 60.0, "the ask after the first one's timeout")
        late = Float64MultiArray(data=[x + 0.3 for x in asks[0].data])
        late.layout = asks[0].layout
        answer.publish(late)
        conductor.spin_until(lambda: "ignored a late answer" in plant.log_path.read_text(), 60.0,
                             "the plant's report of the late answer")
        answered = 1
        while not ends:  # from the second ask on, every ask answered with its own data and layout
            conductor.spin_until(lambda n=answered: len(asks) > n or bool(ends), 60.0, "the next ask or the end")
            while answered < len(asks):
                answer.publish(asks[answered])
                answered += 1
        conductor.spin_until(lambda: len(applied) >= sum(len(a.data) // 2 for a in asks), 60.0, "every applied step")
    finally:
        conductor.close()
    log = plant.log_path.read_text()
    label = asks[0].layout.dim[0].label
    assert label.startswith("joints, ask " if block == 1 else "samples, ask ")
    assert len({a.layout.dim[0].label for a in asks}) == len(asks)  # each ask numbered
    assert f"ignored a late answer to '{label}'" in log, log
    held = (0.0, 0.2)  # task.start: what the plant applies before any answer
    k = 0
    for i, ask in enumerate(asks):
        rows = [tuple(ask.data[j:j + 2]) for j in range(0, len(ask.data), 2)]
        got = applied[k:k + len(rows)]
        k += len(rows)
        if i == 0 or got != rows:  # the first ask timed out; another one may under load, never a wrong answer
            assert got == [held] * len(rows), (i, got, rows)
        held = got[-1]
    assert plant.running() and plant.stop() == 0
