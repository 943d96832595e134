"""The lockstep exchange between the simulated plant and the shaper, free of ROS.

In lockstep (the sim plant's ``mode: lockstep``) the plant asks the shaper for the shaped setpoints of
its next steps and steps only once the answer is in. This module is the one home of that exchange's
rules; the sim plant node, the shaper node and the reproductions use it.

Asks
    Each ask is a std_msgs/Float64MultiArray of raw setpoints, numbered in its layout's first label:
    ``"joints, ask K"`` for one setpoint (layout [joints]), ``"samples, ask K"`` for a block of the
    setpoints of several steps (layout [samples, joints], ``lockstep.block`` > 1). The shaper passes
    the layout on with the shaped data (:class:`Asks`, :func:`ask_layout`).
Late answers
    An answer labelled with another ask than the pending one (it came after ``lockstep_timeout`` went
    by) is ignored and counted, so that it is never applied to a later step. An answer with no layout,
    or with a layout of its own (a peer that does not pass the plant's on), is taken as the answer to
    the pending ask (:func:`is_late`).
Blocks
    How many samples a received array carries, from its layout sizes (:func:`block_rows`: one without
    a layout or with one dimension, ``sizes[0]`` for [samples, joints]; a layout that does not describe
    the data, or a block of more samples than allowed, is refused with the reason).
Block size
    The block a run at a given rate uses (:func:`lockstep_block`: 0.1 s of samples per exchange).

A layout dimension is a :class:`Dim` (label, size, stride), the fields of
std_msgs/MultiArrayDimension; the nodes convert at the edge.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from .checks import InputError

__all__ = ["ASK_LABELS", "JOINTS_LABEL", "Asks", "Dim", "ask_label", "ask_layout", "block_rows", "is_late",
           "lockstep_block"]

#: how the first layout label of an ask begins (then the ask's number): one setpoint, a block
ASK_LABELS = ("joints, ask ", "samples, ask ")
#: the second label of a block's layout
JOINTS_LABEL = "joints"


class Dim(NamedTuple):
    """One dimension of a Float64MultiArray layout (std_msgs/MultiArrayDimension's fields)."""

    label: str
    size: int
    stride: int


def ask_label(ask: int, block: bool) -> str:
    """The first layout label of ask number ``ask``: ``"joints, ask K"``, or ``"samples, ask K"`` for a
    block (``block``: the plant exchanges blocks, ``lockstep.block`` > 1)."""
    return f"{ASK_LABELS[1 if block else 0]}{ask}"


def ask_layout(ask: int, rows: int, joints: int, block: bool) -> list[Dim]:
    """The layout of ask number ``ask`` carrying ``rows`` setpoints of ``joints`` joints.

    Parameters
    ----------
    ask : int
        The ask's number (1 for the first).
    rows : int
        Setpoints (samples) in the ask; 1 unless ``block``.
    joints : int
        Values per setpoint.
    block : bool
        The plant exchanges blocks (``lockstep.block`` > 1): layout [samples, joints] even for one row,
        otherwise [joints].

    Returns
    -------
    list of Dim
        [("joints, ask K", joints, joints)], or [("samples, ask K", rows, rows joints),
        ("joints", joints, joints)].
    """
    label = ask_label(ask, block)
    if not block:
        return [Dim(label, joints, joints)]
    return [Dim(label, rows, rows * joints), Dim(JOINTS_LABEL, joints, joints)]


def is_late(label: str | None, pending: str) -> bool:
    """Whether an answer whose first layout label is ``label`` (None: no layout) answers an earlier ask
    than the ``pending`` one: it carries an ask's label, and not the pending ask's. An answer with no
    layout, or with a label of its own, is not late (it is taken as the pending ask's answer)."""
    if not label:
        return False
    return label != pending and label.startswith(ASK_LABELS)


def block_rows(sizes: Sequence[int], values: int, joints: int, max_samples: int) -> int:
    """The samples a received Float64MultiArray carries, from its layout's sizes.

    Parameters
    ----------
    sizes : sequence of int
        The sizes of the layout's dimensions, in order (empty: no layout).
    values : int
        The number of values in the data.
    joints : int
        Values per sample.
    max_samples : int
        The largest block taken, samples.

    Returns
    -------
    int
        1 without a layout or with a layout of one dimension (forward_command_controller's input);
        ``sizes[0]`` for a layout of two, [samples, joints] (the sim plant's blocks), whose rows are
        consecutive samples.

    Raises
    ------
    InputError
        ``wrong_size``: the layout does not describe samples x ``joints`` in ``values`` values;
        ``too_large``: a block of more than ``max_samples`` samples.
    """
    if len(sizes) <= 1:
        return 1
    shape = [int(s) for s in sizes]
    if len(shape) != 2 or shape[1] != joints or shape[0] * joints != values or shape[0] < 1:
        raise InputError("wrong_size", f"layout {shape} does not describe samples x {joints} joints in"
                         f" {values} values")
    if shape[0] > max_samples:
        raise InputError("too_large", f"a block of {shape[0]} samples is more than"
                         f" limits.max_trajectory_samples ({max_samples})")
    return shape[0]


def lockstep_block(rate: float) -> int:
    """The sim plant's ``lockstep.block`` for a run at ``rate`` Hz: 0.1 s of samples per exchange with the
    shaper, at least 1. For a feedforward command path (the shaper between the task and the plant, changed
    only at rest between cycles) a run in blocks is the run one setpoint at a time
    (tests/test_lockstep_blocks.py), with ten to fifty times fewer round trips through DDS."""
    return max(1, int(round(0.1 * rate)))


class Asks:
    """The plant's side of the exchange: numbers its asks and tells late answers from the pending one.

    Parameters
    ----------
    joints : int
        Values per setpoint.
    block : bool
        The plant exchanges blocks (``lockstep.block`` > 1).
    """

    def __init__(self, joints: int, block: bool) -> None:
        self.joints = joints
        self.block = block
        #: asks made so far
        self.count = 0
        #: the first layout label of the pending (latest) ask; '' before the first
        self.pending = ""

    def next(self, rows: int) -> list[Dim]:
        """Number a new ask of ``rows`` setpoints (it becomes the pending one); returns its layout."""
        self.count += 1
        layout = ask_layout(self.count, rows, self.joints, self.block)
        self.pending = layout[0].label
        return layout

    def late(self, label: str | None) -> bool:
        """Whether an answer with first layout label ``label`` (None: no layout) is late (:func:`is_late`)."""
        return is_late(label, self.pending)
