"""Whole-trajectory shaping and input validation."""

import numpy as np
import pytest

from shaper_nodes.core.checks import InputError, finite_array, joint_permutation, strictly_increasing
from shaper_nodes.core.shaping.families import design
from shaper_nodes.core.shaping.fir import discretize
from shaper_nodes.core.shaping.trajectory import shape_trajectory
from shaper_nodes.core.shaping.types import Mode

FIR = discretize(design("zvd", [Mode.from_hz(4.0, 0.02)]), 250.0)


@pytest.mark.parametrize("velocities", [None, np.array([[0, 0], [1.0, -1.0], [0, 0]])])
def test_shaped_trajectory_meets_joint_trajectory_controller_checks(velocities):
    times = np.array([0.1, 0.6, 1.2])
    pos = np.array([[0.0, 1.0], [0.4, 0.7], [1.0, 0.0]])
    out = shape_trajectory(times, pos, FIR, 250.0, velocities)
    assert np.all(np.diff(out.times) > 0) and out.times[0] == pytest.approx(0.1)
    for arr in (out.positions, out.velocities, out.accelerations):
        assert np.all(np.isfinite(arr)) and arr.shape == (out.times.size, 2)
    np.testing.assert_allclose(out.positions[-1], pos[-1], atol=1e-12)
    assert np.all(out.velocities[-1] == 0) and np.all(out.accelerations[-1] == 0)
    np.testing.assert_allclose(out.positions[0], pos[0], atol=1e-12)
    shaper_duration = design("zvd", [Mode.from_hz(4.0, 0.02)]).duration
    assert out.times[-1] >= times[-1] + shaper_duration - 1e-9


def test_trajectory_bad_input():
    with pytest.raises(InputError) as e:
        shape_trajectory(np.array([0.0, 0.5, 0.5]), np.zeros((3, 2)), FIR, 250.0)
    assert e.value.kind == "non_increasing_time"
    with pytest.raises(InputError) as e:
        shape_trajectory(np.array([0.0, 0.5]), np.array([[0, 1], [np.nan, 1]]), FIR, 250.0)
    assert e.value.kind == "non_finite"


def test_validation_kinds():
    assert joint_permutation(["a", "b", "c"], ["c", "a", "b"]).tolist() == [1, 2, 0]
    for received, kind in [(["a", "b", "x"], "unknown_joint"), (["a", "b"], "missing_joint"),
                           (["a", "a", "b", "c"], "duplicate_joint"), ([], "empty")]:
        with pytest.raises(InputError) as e:
            joint_permutation(["a", "b", "c"], received)
        assert e.value.kind == kind
    with pytest.raises(InputError, match="has 2 values, expected 3") as e:
        finite_array("data", [1.0, 2.0], size=3)
    assert e.value.kind == "wrong_size"
    with pytest.raises(InputError, match="non-finite values at index \\[1\\]"):
        finite_array("data", [1.0, float("inf"), 2.0])
    with pytest.raises(InputError, match="not strictly increasing"):
        strictly_increasing("t", np.array([0.0, 0.2, 0.1]))
