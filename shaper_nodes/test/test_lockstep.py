"""The lockstep exchange's rules (shaper_nodes.core.lockstep), without rclpy."""

import subprocess
import sys

import pytest

from shaper_nodes.core.checks import InputError
from shaper_nodes.core.lockstep import (
    ASK_LABELS,
    Asks,
    Dim,
    ask_label,
    ask_layout,
    block_rows,
    is_late,
    lockstep_block,
)


def test_the_module_imports_no_rclpy():
    code = "import sys, shaper_nodes.core.lockstep; assert 'rclpy' not in sys.modules, sorted(sys.modules)"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_labels_number_the_asks():
    assert ask_label(1, block=False) == "joints, ask 1"
    assert ask_label(17, block=True) == "samples, ask 17"
    assert all(ask_label(3, b).startswith(ASK_LABELS) for b in (False, True))


def test_one_setpoint_has_a_one_dimensional_layout():
    assert ask_layout(4, 1, 6, block=False) == [Dim("joints, ask 4", 6, 6)]


def test_a_block_is_samples_by_joints():
    assert ask_layout(2, 50, 3, block=True) == [Dim("samples, ask 2", 50, 150), Dim("joints", 3, 3)]
    # the last block of a run may hold one row: still a block's layout
    assert ask_layout(9, 1, 3, block=True) == [Dim("samples, ask 9", 1, 3), Dim("joints", 3, 3)]


def test_asks_count_and_keep_the_pending_label():
    asks = Asks(2, block=True)
    assert asks.pending == "" and asks.count == 0
    layout = asks.next(5)
    assert layout[0] == Dim("samples, ask 1", 5, 10) and asks.pending == "samples, ask 1"
    asks.next(5)
    assert asks.count == 2 and asks.pending == "samples, ask 2"
    assert asks.late("samples, ask 1")
    assert not asks.late("samples, ask 2")


@pytest.mark.parametrize(("label", "late"), [
    ("joints, ask 3", False),  # the pending ask
    ("joints, ask 2", True),  # an earlier ask: came after lockstep_timeout
    ("samples, ask 2", True),
    (None, False),  # no layout: the answer to the pending ask
    ("", False),
    ("joints", False),  # a layout of its own (a peer that does not pass the plant's on)
    ("x", False),
])
def test_the_late_answer_rule(label, late):
    assert is_late(label, "joints, ask 3") is late


@pytest.mark.parametrize(("sizes", "values", "rows"), [
    ((), 3, 1),  # no layout
    ((3,), 3, 1),  # forward_command_controller's layout of one dimension
    ((7,), 3, 1),  # (one dimension: the size is not checked here; the data's size is, elsewhere)
    ((4, 3), 12, 4),
    ((1, 3), 3, 1),
    ((100, 3), 300, 100),
])
def test_block_rows(sizes, values, rows):
    assert block_rows(sizes, values, 3, 100) == rows


@pytest.mark.parametrize(("sizes", "values"), [
    ((4, 2), 8),  # not the joints
    ((4, 3), 11),  # not the data
    ((0, 3), 0),  # no samples
    ((2, 3, 1), 6),  # three dimensions
])
def test_a_layout_that_does_not_describe_the_data_is_refused(sizes, values):
    with pytest.raises(InputError) as err:
        block_rows(sizes, values, 3, 100)
    assert err.value.kind == "wrong_size"
    assert f"does not describe samples x 3 joints in {values} values" in str(err.value)


def test_a_block_beyond_max_samples_is_refused():
    with pytest.raises(InputError) as err:
        block_rows((101, 3), 303, 3, 100)
    assert err.value.kind == "too_large"
    assert "a block of 101 samples is more than limits.max_trajectory_samples (100)" in str(err.value)


@pytest.mark.parametrize(("rate", "block"), [(500.0, 50), (1000.0, 100), (100.0, 10), (4.0, 1), (1.0, 1),
                                             (125.0, 12)])
def test_lockstep_block_is_a_tenth_of_a_second(rate, block):
    assert lockstep_block(rate) == block
