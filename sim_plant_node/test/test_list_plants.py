"""The LIST plants (seed 003, cases 1 to 4) against independent solvers, and in the sim plant node."""

from __future__ import annotations

import gc
import itertools
import math
import os
import pathlib

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp

from shaper_nodes.core.shaping.families import Mode, design
from shaper_nodes.core.shaping.fir import StreamingShaper, discretize
from sim_plant_node.models.plants import (
    LIST_FORCE_LIMIT,
    LIST_STIFFNESS_CUBIC,
    PLANT_MODELS,
    CycleTask,
    ListPlant,
    MckPlant,
    make_plant,
)

CONFIG = pathlib.Path(__file__).resolve().parents[1] / "config"
M, B, K = 1.0, 1.0, 100.0  # the paper's plant: 10 rad/s, zeta 0.05
RATE = 500.0


def default_task(rate: float = RATE, dwell: float = 4.0) -> np.ndarray:
    """One cycle of the example task of config/list_case*.yaml: 1 m, 1 m/s, 2 m/s^2."""
    task = CycleTask([0.0], [1.0], 1.0, 2.0, dwell, rate, 1)
    return np.array([task.step()[0][0] for _ in range(task.samples_per_cycle)])


def zv_shaped(raw: np.ndarray, rate: float = RATE) -> np.ndarray:
    return StreamingShaper(discretize(design("zv", [Mode(10.0, 0.05)]), rate), 1).process(raw[:, None])[:, 0]


def run(plant, commands, t0: float | None = 0.0) -> dict[str, np.ndarray]:
    """Step ``plant`` through ``commands`` (samples x joints), cycle time from t0; record its outputs."""
    out: dict[str, list] = {k: [] for k in ("x", "v", "a", "f")}
    for i, u in enumerate(np.asarray(commands, dtype=float).reshape(len(commands), -1)):
        plant.step(u, cycle_time=None if t0 is None else t0 + i / plant.rate)
        out["x"].append(plant.tip_position)
        out["v"].append(plant.tip_velocity)
        out["a"].append(plant.tip_acceleration)
        if isinstance(plant, ListPlant):
            out["f"].append(plant.applied_force)
    return {k: np.array(v) for k, v in out.items()}


def test_every_node_model_has_a_plant():
    assert PLANT_MODELS == ("mck", "list_linear", "list_time_varying", "list_hardening", "list_saturation")
    for name in PLANT_MODELS:
        plant = make_plant(name, [M], [B], [K], RATE)
        assert isinstance(plant, MckPlant if name == "mck" else ListPlant)


# ----------------------------------------------------------------- against independent solvers
def test_linear_matches_lsim():
    """Case 1: X/U = k / (m s^2 + b s + k) under a first-order hold of the command (lsim interp)."""
    m, b, k, rate = 2.0, 3.0, 500.0, 200.0
    t = np.arange(400) / rate
    u = np.where(t < 0.5, t, 0.5) + 0.1 * np.sin(7 * t)
    u[0] = 0.0
    plant = ListPlant("linear", [m], [b], [k], rate)
    out = run(plant, u[1:])
    _, y, xs = signal.lsim(signal.StateSpace([[0.0, 1.0], [-k / m, -b / m]], [[0.0], [k / m]], [[1.0, 0.0]], [[0.0]]),
                           u, t, interp=True)
    scale = np.max(np.abs(y))
    np.testing.assert_allclose(out["x"][:, 0], y[1:], atol=1e-8 * scale)
    np.testing.assert_allclose(out["v"][:, 0], xs[1:, 1], atol=1e-7 * np.max(np.abs(xs[:, 1])))
    np.testing.assert_allclose(out["a"][:, 0], (k * (u[1:] - y[1:]) - b * xs[1:, 1]) / m,
                               atol=1e-6 * np.max(np.abs(out["a"])))


def reference(rhs, u: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """x and x' at every sample from solve_ivp, one solve per period with the command linear in it."""
    y = np.zeros(2)
    xs, vs = [], []
    for i in range(1, u.size):
        t0, t1 = (i - 1) / rate, i / rate
        slope = (u[i] - u[i - 1]) * rate
        sol = solve_ivp(lambda t, s, u0=u[i - 1], slope=slope, t0=t0: [s[1], rhs(t, s[0], s[1], u0 + slope * (t - t0))],
                        (t0, t1), y, method="DOP853", rtol=1e-12, atol=1e-14)
        y = sol.y[:, -1]
        xs.append(y[0])
        vs.append(y[1])
    return np.array(xs), np.array(vs)


def mass_of_t(m: float, t: float) -> float:
    return m * (1.0 + t) if t < 1.0 else 2.0 * m


# m, b, k, k3, Kp, f_max of two joints: the paper's plant and a different one, vectorised
JOINTS = [(1.0, 1.0, 100.0, LIST_STIFFNESS_CUBIC, 100.0, LIST_FORCE_LIMIT), (2.0, 0.5, 300.0, 4e5, 250.0, 3.0)]
RHS = {
    "linear": lambda m, b, k, k3, kp, fm: lambda t, x, v, u: (-b * v - k * (x - u)) / m,
    "time_varying": lambda m, b, k, k3, kp, fm: lambda t, x, v, u: (-b * v - k * (x - u)) / mass_of_t(m, t),
    "hardening": lambda m, b, k, k3, kp, fm: lambda t, x, v, u: (-b * v - k * (x - u) - k3 * (x - u) ** 3) / m,
    "saturation": lambda m, b, k, k3, kp, fm: lambda t, x, v, u: (min(max(kp * (u - x), -fm), fm) - b * v) / m,
}


@pytest.mark.parametrize("model", list(RHS))
def test_each_model_matches_solve_ivp(model):
    """RK4 with substeps is within 1e-7 (x, x') and 1e-6 (x'') of the peak of an adaptive 8th-order solution."""
    rate = 200.0
    raw = default_task(rate, dwell=0.5)[:500]  # 2.5 s: the mass ramps, the move saturates
    commands = np.column_stack([raw, 0.6 * raw])
    m, b, k, k3, kp, f_max = (np.array(p) for p in zip(*JOINTS, strict=True))
    plant = ListPlant(model, m, b, k, rate, stiffness_cubic=k3, gain=kp, force_limit=f_max)
    plant.reset([0.0, 0.0])
    out = run(plant, commands)
    u = np.vstack([np.zeros((1, 2)), commands])
    for j, params in enumerate(JOINTS):
        rhs = RHS[model](*params)
        x, v = reference(rhs, u[:, j], rate)
        a = np.array([rhs((i + 1) / rate, xi, vi, ui)
                      for i, (xi, vi, ui) in enumerate(zip(x, v, u[1:, j], strict=True))])
        for name, got, want in (("x", out["x"][:, j], x), ("v", out["v"][:, j], v), ("a", out["a"][:, j], a)):
            err = np.max(np.abs(got - want)) / np.max(np.abs(want))
            assert err < (1e-6 if name == "a" else 1e-7), (model, j, name, err)


# ----------------------------------------------------------------- case 2: time-varying mass
def test_time_varying_mass_doubles_over_the_first_second():
    plant = ListPlant("time_varying", [1.0, 3.0], B, K, RATE)
    for t, factor in ((0.0, 1.0), (0.25, 1.25), (0.999, 1.999), (1.0, 2.0), (7.0, 2.0), (None, 2.0)):
        np.testing.assert_allclose(plant.mass_at(t), factor * np.array([1.0, 3.0]))
    # natural frequency and damping ratio are those of the nominal (t = 0) plant
    np.testing.assert_allclose(plant.natural_frequency, np.sqrt(K / np.array([1.0, 3.0])))


def test_time_varying_mass_switch_at_one_second():
    """Before 1 s the plant differs from a constant mass; from 1 s on it is the linear plant with 2 m."""
    u = default_task()[:1500]
    tv = run(ListPlant("time_varying", M, B, K, RATE), u, t0=0.0)
    lin_m = run(ListPlant("linear", M, B, K, RATE), u)
    assert np.max(np.abs(tv["x"][:400] - lin_m["x"][:400])) > 1e-3  # the mass grows during the move
    # restart both from the state at exactly 1 s: equal from then on
    after = u[500:]
    plants = [ListPlant("time_varying", M, B, K, RATE), ListPlant("linear", 2 * M, B, K, RATE)]
    ref = ListPlant("time_varying", M, B, K, RATE)
    run(ref, u[:500], t0=0.0)
    assert ref.cycle_time == pytest.approx(1.0)
    for p in plants:
        p.state = ref.state.copy()
    a = run(plants[0], after, t0=1.0)
    b = run(plants[1], after)
    np.testing.assert_allclose(a["x"], b["x"], rtol=0, atol=1e-13)
    # no cycle (cycle_time None) is the mass after the ramp
    c = run(ListPlant("time_varying", M, B, K, RATE), u, t0=None)
    d = run(ListPlant("linear", 2 * M, B, K, RATE), u)
    np.testing.assert_allclose(c["x"], d["x"], rtol=0, atol=1e-13)


def crossing_frequency(x: np.ndarray, rate: float) -> float:
    """Mean angular frequency (rad/s) from the zero crossings of x, interpolated."""
    idx = np.where(np.sign(x[:-1]) != np.sign(x[1:]))[0]
    times = (idx + x[idx] / (x[idx] - x[idx + 1])) / rate
    return math.pi / float(np.mean(np.diff(times)))


def test_time_varying_residual_vibration_is_at_the_doubled_mass():
    out = run(ListPlant("time_varying", M, B, K, RATE), default_task(), t0=0.0)
    w = crossing_frequency(out["x"][int(2.0 * RATE):, 0] - 1.0, RATE)
    zeta = B / (2 * math.sqrt(K * 2 * M))
    assert w == pytest.approx(math.sqrt(K / (2 * M)) * math.sqrt(1 - zeta**2), rel=2e-3)


# ----------------------------------------------------------------- case 3: hardening spring
def test_hardening_with_no_cubic_term_is_the_linear_plant():
    u = default_task()
    a = run(ListPlant("hardening", M, B, K, RATE, stiffness_cubic=0.0), u)
    b = run(ListPlant("linear", M, B, K, RATE), u)
    for key in ("x", "v", "a", "f"):
        np.testing.assert_array_equal(a[key], b[key])


def free_vibration_frequency(plant, amplitude: float, seconds: float = 3.0) -> float:
    plant.reset(0.0)
    plant.state[:, 0] = amplitude  # released from rest, deflected by ``amplitude``
    out = run(plant, np.zeros(int(seconds * plant.rate)))
    return crossing_frequency(out["x"][:, 0], plant.rate)


def test_hardening_frequency_rises_with_amplitude():
    k3 = LIST_STIFFNESS_CUBIC
    freqs = [free_vibration_frequency(ListPlant("hardening", M, 0.0, K, RATE, stiffness_cubic=k3), amp)
             for amp in (1e-4, 0.005, 0.01, 0.02)]
    assert freqs[0] == pytest.approx(10.0, rel=1e-3)  # small amplitude: the linearised mode
    assert all(f2 > f1 for f1, f2 in itertools.pairwise(freqs))
    assert freqs[-1] > 1.25 * freqs[0]
    # first-order (Lindstedt) estimate for the Duffing oscillator: omega0 (1 + 3 k3 A^2 / (8 k))
    assert freqs[1] == pytest.approx(10.0 * (1 + 3 * k3 * 0.005**2 / (8 * K)), rel=5e-3)


def test_default_cubic_stiffness_is_significant_in_the_default_task():
    """k3 = k^3 / (m a)^2: the cubic force reaches the linear one during the move; ZV at 10 rad/s fails."""
    assert pytest.approx(K**3 / (M * 2.0) ** 2) == LIST_STIFFNESS_CUBIC
    raw = default_task()
    hard = run(ListPlant("hardening", M, B, K, RATE), raw)
    d = raw - hard["x"][:, 0]
    assert np.max(LIST_STIFFNESS_CUBIC * d**2 / K) > 1.0  # cubic/linear force ratio at the peak deflection
    window = slice(int(2.5 * RATE), None)  # residual vibration, 1 s after the move
    shaped = run(ListPlant("hardening", M, B, K, RATE), zv_shaped(raw))
    linear_shaped = run(ListPlant("linear", M, B, K, RATE), zv_shaped(raw))
    peak = lambda out: np.max(np.abs(out["a"][window]))  # noqa: E731
    assert peak(linear_shaped) < 1e-3 * peak(run(ListPlant("linear", M, B, K, RATE), raw))
    assert peak(shaped) > 0.2 * peak(hard)  # a shaper for the linearised mode leaves a lot


# ----------------------------------------------------------------- case 4: saturation
def test_saturation_without_a_limit_is_the_linear_closed_loop():
    u = default_task()
    kp = 150.0
    sat = run(ListPlant("saturation", M, B, 1.0, RATE, gain=kp, force_limit=np.inf), u)
    lin = run(ListPlant("linear", M, B, kp, RATE), u)
    np.testing.assert_allclose(sat["x"], lin["x"], rtol=0, atol=1e-14)
    t = np.arange(u.size + 1) / RATE
    _, y, _ = signal.lsim(signal.lti([kp], [M, B, kp]), np.concatenate([[0.0], u]), t, interp=True)
    np.testing.assert_allclose(sat["x"][:, 0], y[1:], atol=1e-8)
    plant = ListPlant("saturation", M, B, 1.0, RATE, gain=kp)
    assert plant.natural_frequency[0] == pytest.approx(math.sqrt(kp / M))
    assert plant.damping_ratio[0] == pytest.approx(B / (2 * math.sqrt(kp * M)))


def test_saturation_clips_the_force():
    u = default_task()
    f_max = 1.5
    out = run(ListPlant("saturation", M, B, K, RATE, gain=K, force_limit=f_max), u)
    assert np.max(np.abs(out["f"])) == pytest.approx(f_max)
    np.testing.assert_allclose(out["a"], (out["f"] - B * out["v"]) / M, atol=1e-12)
    assert np.mean(np.abs(out["f"][: int(0.5 * RATE)]) >= f_max) > 0.5  # at the limit most of the acceleration
    lin = run(ListPlant("saturation", M, B, K, RATE, gain=K, force_limit=np.inf), u)
    assert np.max(np.abs(out["x"] - lin["x"])) > 0.05  # the clipped loop lags far behind


def test_default_force_limit_acts_in_the_acceleration_phase_shaped_or_not():
    """f_max = 2.5 N < m a + b v = 3 N at the end of the acceleration phase of the default task."""
    assert LIST_FORCE_LIMIT < M * 2.0 + B * 1.0
    raw = default_task()
    accel = slice(0, int(0.5 * RATE))
    clipped = {}
    for name, cmd in (("raw", raw), ("zv", zv_shaped(raw))):
        out = run(ListPlant("saturation", M, B, K, RATE), cmd)
        clipped[name] = float(np.mean(np.abs(out["f"][accel, 0]) >= LIST_FORCE_LIMIT - 1e-12))
    # the shares quoted in docs/design/list_plants.md and config/list_case4.yaml
    assert clipped["raw"] == pytest.approx(0.64, abs=0.01)
    assert clipped["zv"] == pytest.approx(0.19, abs=0.01)


# ----------------------------------------------------------------- interface and validation
def test_mck_plant_accepts_and_ignores_the_cycle_time():
    u = default_task()[:600]
    a = run(MckPlant(M, B, K, RATE), u, t0=0.0)
    b = run(MckPlant(M, B, K, RATE), u, t0=None)
    np.testing.assert_array_equal(a["x"], b["x"])


def test_base_is_the_command_for_every_model():
    u = default_task()[:300]
    for model in ("linear", "time_varying", "hardening", "saturation"):
        plant = ListPlant(model, [M, M], B, K, RATE)
        plant.reset([0.0, 0.5])
        plant.step([u[0], 0.5 + u[0]])
        plant.step([u[1], 0.5 + u[1]], cycle_time=0.002)
        np.testing.assert_allclose(plant.base_position, [u[1], 0.5 + u[1]])
        np.testing.assert_allclose(plant.base_velocity, [(u[1] - u[0]) * RATE] * 2)
        assert plant.joints == 2 and plant.rate == RATE


@pytest.mark.parametrize("bad, name", [
    (dict(mass=[0.0]), "mass"), (dict(mass=[np.inf]), "mass"), (dict(damping=[-1.0]), "damping"),
    (dict(stiffness=[np.nan]), "stiffness"), (dict(stiffness_cubic=[-1.0]), "stiffness_cubic"),
    (dict(gain=[0.0]), "gain"), (dict(force_limit=[0.0]), "force_limit"), (dict(force_limit=[np.nan]), "force_limit"),
    (dict(damping=[1.0, 2.0]), "damping"), (dict(model="quadratic"), "model"),
])
def test_invalid_parameters_name_the_parameter(bad, name):
    args = dict(model="hardening", mass=[1.0], damping=[1.0], stiffness=[100.0], stiffness_cubic=[1e5], gain=[100.0],
                force_limit=[2.0]) | bad
    with pytest.raises(ValueError, match=rf"^{name} "):
        ListPlant(args.pop("model"), args.pop("mass"), args.pop("damping"), args.pop("stiffness"), 100.0, **args)


def test_make_plant_checks_every_parameter_whatever_the_model():
    with pytest.raises(ValueError, match=r"^force_limit "):
        make_plant("mck", [1.0], [1.0], [100.0], 100.0, force_limit=[-1.0])
    with pytest.raises(ValueError, match=r"^model "):
        make_plant("list_quadratic", [1.0], [1.0], [100.0], 100.0)


# ----------------------------------------------------------------- in the node
needs_ros = pytest.mark.integration


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


def make_node(ctx, params: dict | None = None, config: str | None = None):
    from rclpy.parameter import Parameter

    from sim_plant_node.node.sim_plant import SimPlantNode

    cli = ["--ros-args", "--params-file", str(CONFIG / config)] if config else None
    overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
    return SimPlantNode(context=ctx, cli_args=cli, parameter_overrides=overrides)


def run_task(node) -> list[tuple[np.ndarray, float | None, float]]:
    """Lockstep without a shaper: answer every raw setpoint with itself until the task ends."""
    from std_msgs.msg import Float64MultiArray

    ok, why = node._start_task()
    assert ok, why
    log = []
    while node.task is not None or node._waiting_since is not None:  # the last setpoint is answered too
        node._on_command(Float64MultiArray(data=node._raw.tolist()))
        log.append((node.plant.tip_position, node.plant.cycle_time, node.plant.tip_acceleration[0]))
    return log


@needs_ros
@pytest.mark.parametrize("case, model", [(1, "linear"), (2, "time_varying"), (3, "hardening"), (4, "saturation")])
def test_example_configs_load(ros_context, case, model):
    node = make_node(ros_context, config=f"list_case{case}.yaml")
    try:
        assert isinstance(node.plant, ListPlant) and node.plant.model == model
        assert node.plant.natural_frequency[0] == pytest.approx(10.0)
        assert node.plant.damping_ratio[0] == pytest.approx(0.05)
        if model == "hardening":
            assert node.plant.k3[0] == LIST_STIFFNESS_CUBIC
        if model == "saturation":
            assert node.plant.f_max[0] == LIST_FORCE_LIMIT and node.plant.kp[0] == 100.0
        g = lambda name: node.get_parameter(name).value  # noqa: E731
        task = CycleTask(g("task.start"), g("task.goal"), g("task.max_velocity"), g("task.max_acceleration"),
                         g("task.dwell"), node.rate, 1)
        assert task.move_duration == pytest.approx(1.5)
    finally:
        node.destroy_node()


@needs_ros
def test_node_tells_the_plant_the_cycle_time(ros_context):
    """The node's time-varying plant equals an offline one stepped with the time since each START."""
    node = make_node(ros_context, {"plant.model": "list_time_varying", "plant.mass": [M], "plant.damping": [B],
                                   "plant.stiffness": [K], "task.start": [0.0], "task.goal": [1.0],
                                   "task.max_velocity": 1.0, "task.max_acceleration": 2.0, "task.dwell": 0.6,
                                   "task.cycles": 2, "task.preroll": 0.1})
    try:
        log = run_task(node)
    finally:
        node.destroy_node()
    preroll = int(0.1 * RATE)
    assert all(cycle_time is None for _, cycle_time, _ in log[:preroll])
    task = CycleTask([0.0], [1.0], 1.0, 2.0, 0.6, RATE, 2)
    n = task.samples_per_cycle
    assert [c for _, c, _ in log[preroll:preroll + 2]] == pytest.approx([1 / RATE, 2 / RATE])
    assert log[preroll + n][1] == pytest.approx(1 / RATE)  # the second cycle restarts the clock
    plant = ListPlant("time_varying", M, B, K, RATE)
    offline = []
    for i in range(task.cycles * n):
        plant.step(task.step()[0], cycle_time=(i % n) / RATE)
        offline.append(plant.tip_position[0])
    np.testing.assert_allclose([x[0] for x, _, _ in log[preroll:]], offline, rtol=0, atol=1e-12)


@needs_ros
def test_node_refuses_bad_plant_parameters_and_switches_models_live(ros_context):
    from rclpy.parameter import Parameter

    node = make_node(ros_context)
    try:
        assert isinstance(node.plant, MckPlant)
        for name, value, words in (("plant.force_limit", [-1.0], "plant.force_limit"),
                                   ("plant.stiffness_cubic", [-5.0], "plant.stiffness_cubic"),
                                   ("plant.gain", [0.0], "plant.gain"),
                                   ("plant.model", "list_quadratic", "plant.model must be one of"),
                                   ("plant.mass", [1.0, 2.0], "plant.mass")):
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and words in result.reason, (name, result.reason)
            assert isinstance(node.plant, MckPlant)
        node.plant.state[:, 1] = 0.25
        assert node.set_parameters([Parameter("plant.model", value="list_saturation"),
                                    Parameter("plant.force_limit", value=[math.inf])])[0].successful
        assert isinstance(node.plant, ListPlant) and node.plant.model == "saturation"
        assert node.plant.tip_velocity[0] == 0.25  # the state carries over
        assert np.isinf(node.plant.f_max[0])
        assert node.set_parameters([Parameter("plant.model", value="mck")])[0].successful
        assert isinstance(node.plant, MckPlant)
    finally:
        node.destroy_node()


@pytest.mark.parametrize("model", ["linear", "time_varying", "hardening", "saturation"])
@pytest.mark.parametrize("shaped", [False, True])
def test_one_joint_in_floats_is_the_array_code_bit_for_bit(model, shaped):
    # ListPlant steps one joint in Python floats (models/list_scalar.py); the array code, with which several joints
    # step, must give the very same bits: corners (the force limit, the end of the mass ramp) and the cube included
    rate = 250.0
    raw = default_task(rate, dwell=1.0)
    commands = np.concatenate([zv_shaped(raw, rate) if shaped else raw, raw[::-1], np.full(40, 0.3)])
    fast = ListPlant(model, M, B, K, rate)
    slow = ListPlant(model, M, B, K, rate)
    assert fast._one is not None
    slow._one = None  # the array code
    for plant in (fast, slow):
        plant.reset([0.0])
    for i, u in enumerate(commands):
        cycle_time = None if i < 5 else (i - 5) / rate - 0.3 * (i > 300)
        fast.step([u], cycle_time)
        slow.step([u], cycle_time)
        assert fast.state.tobytes() == slow.state.tobytes(), (i, fast.state, slow.state)
        assert fast.cycle_time == slow.cycle_time
        assert fast.tip_acceleration.tobytes() == slow.tip_acceleration.tobytes()
    two = ListPlant(model, [M, M], [B, B], [K, K], rate)
    assert two._one is None  # several joints: the array code
