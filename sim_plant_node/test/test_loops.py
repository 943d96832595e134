"""Loop plants (seeds 001 and 002) without ROS: against the cores' independent checks and the papers."""

from __future__ import annotations

import gc
import math
import os

import numpy as np
import pytest

from shaper_nodes.core.closed_loop import qft
from shaper_nodes.core.closed_loop.time_delay import growth_rate, sampled_loop_matrix
from sim_plant_node.models.loops import LOOP_MODELS, DelayLoopPlant, QftLoopPlant, make_loop_plant

WA, T = 3.0, math.pi / 9.0


def step_response(plant, seconds: float, level: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    plant.reset(0.0)
    n = int(round(seconds * plant.rate))
    out = []
    for i in range(n):
        plant.step(np.full(plant.joints, level), i / plant.rate)
        out.append(plant.output.copy())
    return np.arange(1, n + 1) / plant.rate, np.array(out)


def delay_loop(omega_r, rate=100.0, substeps=10, **extra) -> DelayLoopPlant:
    w = np.atleast_1d(np.asarray(omega_r, dtype=float))
    return make_loop_plant("delay_loop", np.ones(w.size), [0.0], w**2, rate,
                           {"loop.substeps": substeps, "loop.assumed_frequency": WA, "loop.delay": T, **extra})


def test_delay_loop_with_the_exact_model_settles_at_two_t_without_overshoot():
    p = delay_loop(3.0)
    assert p.delay == pytest.approx(0.349) and p.delay_samples == 349
    t, y = step_response(p, 3.0)
    assert y.max() <= 1.0 + 1e-12
    assert np.all(np.abs(y[t >= 2 * p.delay - 1e-9] - 1.0) < 1e-9)
    assert np.abs(y[t < 2 * p.delay - 0.02] - 1.0).min() > 1e-3  # not before


def test_delay_loop_equals_the_sampled_data_matrix_of_the_core():
    """The node's loop and the core's independent check are the same sampled system (reference 0)."""
    p = delay_loop(4.0, rate=1000.0, substeps=1)
    m = sampled_loop_matrix(WA, p.delay_samples, p.h, 4.0)
    # free response from an initial tip displacement, reference 0, controller at rest at 0
    p.reset(0.0)
    p._state[0, 0] = 0.1
    x = np.zeros(m.shape[0])
    x[0] = 0.1
    ys = []
    for _ in range(400):
        p.step(np.array([0.0]), None)
        x = m @ x
        ys.append((p.output[0], x[0]))
    ys = np.array(ys)
    assert np.abs(ys).max() > 0.05
    assert np.allclose(ys[:, 0], ys[:, 1], atol=1e-12)


def test_delay_loop_growth_matches_the_analysis_side():
    p = delay_loop([2.9, 4.0], substeps=2)  # loop at 200 Hz: T = 70 samples = 0.35 s
    t, y = step_response(p, 40.0)
    e = np.abs(y - 1.0)
    for j, w in enumerate((2.9, 4.0)):
        rate = math.log(e[t > 35, j].max() / e[(t > 5) & (t < 10), j].max()) / 30.0
        assert rate == pytest.approx(growth_rate(WA, p.delay, w, p.delay_samples), abs=0.02)


def test_qft_loops_track_a_step_on_every_corner():
    cs = qft.corners()
    for model in ("qft_fb", "qft_ffb"):
        p = make_loop_plant(model, [c.m for c in cs], [c.c for c in cs], [c.k for c in cs], 1000.0,
                            {"loop.substeps": 10})
        t, y = step_response(p, 1.5)
        assert np.all(np.abs(y[t > 1.0] - 1.0) < 1e-4), model


def test_qft_ffb_on_the_nominal_plant_is_the_model():
    """F = P0, Gr = 1: with P = P0, Y/R = P0 whatever G does, so the output is the open loop's."""
    p0 = qft.nominal()
    ffb = make_loop_plant("qft_ffb", [p0.m], [p0.c], [p0.k], 1000.0, {"loop.substeps": 10})
    open_ = make_loop_plant("qft_open", [p0.m], [p0.c], [p0.k], 1000.0, {"loop.substeps": 10})
    _, y1 = step_response(ffb, 0.5)
    _, y2 = step_response(open_, 0.5)
    # F's samples are P0's through the plant's own hold, so the error is zero to rounding: the same output
    assert np.abs(y1 - y2).max() < 1e-9


def test_output_disturbance_and_noise():
    p0 = qft.nominal()
    params = {"loop.substeps": 10, "loop.disturbance_step": 0.5, "loop.disturbance_time": 0.2}
    p = make_loop_plant("qft_ffb", [p0.m], [p0.c], [p0.k], 1000.0, params)
    t, y = step_response(p, 1.0)
    i = np.searchsorted(t, 0.2 - 1e-9)
    assert y[i, 0] - y[i - 1, 0] > 0.45  # the disturbance appears on the output
    assert abs(y[-1, 0] - 1.0) < 1e-3              # and the loop removes it
    o = make_loop_plant("qft_open", [p0.m], [p0.c], [p0.k], 1000.0, params)
    t, y = step_response(o, 1.0)
    assert y[-1, 0] == pytest.approx(1.5, abs=1e-3)  # the open loop keeps it
    n = make_loop_plant("qft_ffb", [p0.m], [p0.c], [p0.k], 1000.0, {"loop.substeps": 10, "loop.noise_step": 0.5,
                                                                    "loop.noise_time": 0.2})
    t, y = step_response(n, 1.0)
    assert y[-1, 0] == pytest.approx(0.5, abs=1e-3)  # the loop follows the noise: y / n = -T
    assert n.measured[0] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("params, words", [
    ({"loop.substeps": 0}, "loop.substeps"),
    ({"loop.assumed_frequency": -1.0}, "loop.assumed_frequency"),
    ({"loop.delay": 0.0}, "loop.delay"),
    ({"loop.noise_stddev": -0.1}, "loop.noise_stddev"),
    ({"loop.disturbance_step": float("nan")}, "loop.disturbance_step"),
])
def test_bad_loop_parameters_are_named(params, words):
    with pytest.raises(ValueError, match=words):
        make_loop_plant("delay_loop", [1.0], [0.0], [9.0], 100.0, params)


def test_bad_qft_parameters_are_named():
    with pytest.raises(ValueError, match=r"loop.nominal"):
        QftLoopPlant("qft_fb", [1.0], [1.0], [1.0], 1000.0, {"loop.nominal": [1.0, 2.0]})
    with pytest.raises(ValueError, match=r"loop.gain"):
        QftLoopPlant("qft_fb", [1.0], [1.0], [1.0], 1000.0, {"loop.gain": -3.0})
    with pytest.raises(ValueError, match="loop model"):
        make_loop_plant("pid", [1.0], [1.0], [1.0], 1000.0, {})


@pytest.fixture
def ros_context():
    rclpy = pytest.importorskip("rclpy")
    try:
        from shaper_msgs.msg import CycleEvent  # noqa: F401
    except ImportError:
        pytest.skip("shaper_msgs is not built (use ./run test)")
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=1 + int(os.environ.get("ROS_DOMAIN_ID", "30")) % 200)
    yield ctx
    gc.collect()  # rclpy's objects sit in cycles: freed now, while their context is valid (tests/conftest.py)
    ctx.try_shutdown()


@pytest.mark.integration
def test_node_builds_loop_plants_and_refuses_bad_loop_parameters(ros_context):
    from rclpy.parameter import Parameter

    from sim_plant_node.node.sim_plant import SimPlantNode

    node = SimPlantNode(context=ros_context, parameter_overrides=[Parameter("plant.model", value="delay_loop")])
    try:
        assert isinstance(node.plant, DelayLoopPlant)
        result = node.set_parameters([Parameter("loop.substeps", value=0)])[0]
        assert not result.successful and "loop.substeps" in result.reason
        assert isinstance(node.plant, DelayLoopPlant)
        for model in LOOP_MODELS[1:]:
            assert node.set_parameters([Parameter("plant.model", value=model)])[0].successful
            assert isinstance(node.plant, QftLoopPlant) and node.plant.model == model
    finally:
        node.destroy_node()


@pytest.mark.integration
@pytest.mark.parametrize("config, cls", [("delay_loop.yaml", DelayLoopPlant), ("qft_ffb.yaml", QftLoopPlant)])
def test_example_configs_load(ros_context, config, cls):
    import pathlib

    from sim_plant_node.node.sim_plant import SimPlantNode

    path = pathlib.Path(__file__).resolve().parents[1] / "config" / config
    node = SimPlantNode(context=ros_context, cli_args=["--ros-args", "--params-file", str(path)])
    try:
        assert isinstance(node.plant, cls)
        if cls is DelayLoopPlant:
            assert node.plant.delay_samples == 349 and node.plant.natural_frequency[0] == pytest.approx(4.0)
        else:
            assert node.plant.model == "qft_ffb" and node.plant.gain == qft.GAIN_FFB
    finally:
        node.destroy_node()


def test_ramp_references_from_the_task():
    """A ramp (task.profile 'ramp') through the loops: the feedforward-feedback loop on the nominal plant
    follows it as the model P0 does (type 2: no lag at the end of the ramp), and the time-delay loop with
    the exact model lags by T (G_FF(s) = 1 - s T + ... for A1 + 2 A2 = 1) and arrives 2T after the ramp."""
    from sim_plant_node.models.plants import CycleTask

    p0 = qft.nominal()
    for plant, lag in ((make_loop_plant("qft_ffb", [p0.m], [p0.c], [p0.k], 1000.0, {"loop.substeps": 10}), 0.0),
                       (delay_loop(3.0, rate=1000.0, substeps=1), 0.349)):
        task = CycleTask([0.0], [1.0], 0.5, 1.0, 2.0, plant.rate, 1, profile="ramp")
        plant.reset(0.0)
        rs, ys = [], []
        while not task.done:
            r, _ = task.step()
            plant.step(r, len(rs) / plant.rate)
            rs.append(r[0])
            ys.append(plant.output[0])
        t = np.arange(1, len(ys) + 1) / plant.rate
        mid = np.searchsorted(t, 1.5)  # on the ramp (2 s long at 0.5 m/s)
        assert ys[mid] == pytest.approx(rs[mid] - 0.5 * lag, abs=2e-3)
        assert ys[-1] == pytest.approx(1.0, abs=1e-6)


def test_taking_over_a_state_puts_the_controller_at_rest_at_the_tip():
    p = delay_loop(3.0)
    p.state = np.array([[0.3, 0.0, 0.3, 0.0]])
    assert p.base_position[0] == 0.3 and p.effort[0] == 0.3
    for _ in range(300):
        p.step(np.array([0.3]), None)
    assert abs(p.output[0] - 0.3) < 1e-12  # at rest: nothing moves


def test_delay_loop_overshoot_converges_to_the_exact_continuous_loop():
    """Seed 001 at w_R = 4: the zero-order-hold loop's overshoot tends to the exact (method of steps) one at
    first order in the loop step, from above (the hold's lag adds overshoot)."""
    from shaper_nodes.core.closed_loop.time_delay import exact_step_response

    delay = 0.349  # on the grid of every step below
    exact = exact_step_response(WA, delay, 4.0).overshoot
    os_ = []
    for sub in (10, 20, 40):  # 1, 0.5, 0.25 ms
        plant = delay_loop(4.0, substeps=sub, **{"loop.delay": delay})
        os_.append(step_response(plant, 3.0)[1][:, 0].max() - 1.0)
    err = np.array(os_) - exact
    assert np.all(err > 0)
    assert 1.8 < err[0] / err[1] < 2.6 and 1.8 < err[1] / err[2] < 2.6
    assert err[0] < 2e-3  # the tolerance the ROS-graph test allows at 1 ms
    assert abs(2 * os_[1] - os_[0] - exact) < 1e-4  # Richardson


def test_modal_split_separates_settling_from_vibration():
    from reproductions.closed_loop_measures import dominant_oscillation, modal_split

    dt = 1e-3
    t = np.arange(900) * dt
    creep = 3e-4 * np.exp(-7.3 * t)
    ring = 2e-4 * np.exp(-60.0 * t) * np.cos(627.0 * t + 0.3)
    osc, slow, _ = modal_split(creep + ring, dt)
    assert np.allclose(osc, ring, atol=1e-12) and np.allclose(slow, creep, atol=1e-12)
    omega, zeta = dominant_oscillation(creep + ring, dt)
    assert omega == pytest.approx(math.hypot(60.0, 627.0), rel=1e-6)
    assert zeta == pytest.approx(60.0 / math.hypot(60.0, 627.0), rel=1e-6)
    osc, slow, _ = modal_split(np.zeros(50), dt)
    assert not osc.any() and not slow.any()
