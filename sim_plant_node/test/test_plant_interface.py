"""Every model behind the one Plant interface (sim_plant_node.models.base), built by name as the node
builds them (sim_plant_node.node.models), and the feedforward profile's rules (node.feedforward)."""

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from sim_plant_node.models.base import Plant
from sim_plant_node.models.plants import mck_from_mode
from sim_plant_node.node.feedforward import Feedforward, check_profile
from sim_plant_node.node.models import BUILDERS, START_ONLY, NodeValues, build_plant
from sim_plant_node.node.parameters import MODELS, PARAMETERS

RATE = 500.0
DEFAULTS = {spec.name: spec.default for spec in PARAMETERS}


class FakeNode:
    """What NodeValues reads of the node: its rate, joint count and parameters."""

    def __init__(self, n: int, **values: Any) -> None:
        self.rate, self.n = RATE, n
        self._values = {**DEFAULTS, **values}

    def get_parameter(self, name: str) -> SimpleNamespace:
        return SimpleNamespace(value=self._values[name])


#: a plant seed 000's PID stabilises (10 rad/s, zeta 0.3; tests/test_pid_loop.py)
PID_PLANT = dict(zip(("plant.mass", "plant.damping", "plant.stiffness"), ([v] for v in mck_from_mode(10.0, 0.3)),
                     strict=True))


def plant_of(model: str, n: int = 2) -> Plant:
    values = {"plant.model": model, **(PID_PLANT if model == "mck_pid" else {})}
    return build_plant(NodeValues(FakeNode(n, **values), {}), n)


def test_every_model_has_a_builder():
    assert set(BUILDERS) == set(MODELS)
    assert set(START_ONLY) <= set(MODELS)


@pytest.mark.parametrize("model", MODELS)
def test_every_model_is_a_plant_and_steps_through_the_interface(model):
    plant = plant_of(model)
    assert isinstance(plant, Plant)
    n = 2 if plant.joint_names is None else len(plant.joint_names)
    plant.reset(np.full(n, 0.1))
    rest = plant.setpoint_at_rest
    assert rest.shape == (n,)
    plant.set_effort(None)
    plant.step(rest + 0.01, cycle_time=None, velocity=None)
    position, velocity, effort = plant.joint_state()
    assert position.shape == velocity.shape == (n,) and (effort is None or effort.shape == (n,))
    tip_position, tip_velocity = plant.tip_state()
    assert tip_position.shape == tip_velocity.shape == (n,)
    samples = plant.imu(0.0, 1.0 / RATE, [0, 1, -1])
    assert samples and all(np.asarray(acc).shape == (3,) and np.all(np.isfinite(acc)) for _, acc, _ in samples)
    assert samples[-1][0] == pytest.approx(1.0 / RATE)
    signals = plant.loop_state()
    assert (signals is None) == (not plant.loop_signals)
    if signals is not None:
        assert signals.shape == (n * len(plant.loop_signals),)
    assert "command" in plant.injections
    assert plant.natural_frequency.shape[0] >= 1 and plant.damping_ratio.shape == plant.natural_frequency.shape


@pytest.mark.parametrize("model", [m for m in MODELS if m not in START_ONLY])
def test_the_models_that_change_live_take_no_live_parameters_and_share_the_1d_traits(model):
    plant = plant_of(model)
    assert plant.changes_live and not plant.trajectory_controller and not plant.gravity_in_imu
    assert plant.joint_names is None and plant.live_parameters == ()
    with pytest.raises(ValueError):
        plant.prepare({"arm.payload_mass": 1.0})
    one_axis = plant.imu(0.0, 0.002, [1, -1, -1])
    assert len(one_axis) == 1 and one_axis[0][2] is None and one_axis[0][1][1:].tolist() == [0.0, 0.0]


def test_only_mck_pid_takes_an_effort_profile():
    assert [m for m in MODELS if "effort" in plant_of(m).injections] == ["mck_pid"]


def test_the_arm_takes_its_payload_live_validated_first():
    arm = plant_of("arm")
    assert arm.joint_names is not None and len(arm.joint_names) == 6
    assert not arm.changes_live and arm.trajectory_controller and arm.gravity_in_imu
    with pytest.raises(ValueError):
        arm.prepare({"arm.payload_mass": 1e6, "arm.payload_offset": 0.0})
    apply = arm.prepare({"arm.payload_mass": 1.0, "arm.payload_offset": 0.05})
    assert apply().startswith("payload 1 kg at 0.05 m: modes at the present pose now ")
    with pytest.raises(ValueError):
        arm.state = arm.state


def test_a_model_change_keeps_the_state_when_the_layouts_agree():
    old, new = plant_of("mck"), plant_of("list_linear")
    old.reset(np.array([0.2, 0.3]))
    new.state = old.state.copy()
    assert new.joint_state()[0].tolist() == pytest.approx([0.2, 0.3])
    with pytest.raises(ValueError):
        plant_of("mck_pid").state = old.state.copy()


def profile(injection="command", data=(0.1, 0.2, 0.3, 0.4), joints=("a", "b"), period=1 / RATE, iteration=3):
    return SimpleNamespace(injection=injection, data=list(data), joint_names=list(joints), sample_period=period,
                           iteration=iteration)


@pytest.mark.parametrize(("msg", "words"), [
    (profile(injection="torque"), "injection must be"),
    (profile(injection="effort"), "needs plant.model 'mck_pid'"),
    (profile(joints=("a", "c")), "do not match"),
    (profile(period=0.01), "sample period"),
    (profile(data=(0.1, 0.2, 0.3)), "whole number of samples"),
    (profile(data=(0.1, float("nan"))), "non-finite value at index 1"),
])
def test_a_profile_that_does_not_fit_is_refused_with_the_reason(msg, words):
    with pytest.raises(ValueError, match=words):
        check_profile(msg, ("command",), ["a", "b"], RATE)


def test_a_profile_is_installed_at_the_next_start_or_at_once():
    ff = Feedforward()
    assert ff.request(profile(), ("command",), ["a", "b"], RATE, at_once=False) == (
        True, "command profile of 2 samples (iteration 3) from the next START")
    assert ff.sample(0) is None
    ff.start()
    injection, sample = ff.sample(1)
    assert injection == "command" and sample.tolist() == [0.3, 0.4]
    assert ff.sample(2) is None and ff.sample(None) is None
    assert ff.request(profile(data=()), ("command",), ["a", "b"], RATE, at_once=True) == (
        True, "command profile of 0 samples (iteration 3) installed")
    assert ff.active is None
    ok, why = ff.request(profile(injection="effort"), ("command",), ["a", "b"], RATE, at_once=True)
    assert not ok and "mck_pid" in why
