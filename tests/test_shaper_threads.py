"""The shaper node's two threads: streamed samples shaped on one while the shaper changes on the other.

With ``stream_executor`` 'thread' the array input is shaped on the stream node's thread and
``~/set_shaper`` is served on the node's own; :attr:`ShaperNode.stream_lock` must put every change
between two samples. Here the real node's array callback runs in a loop on a thread of the test while
the main thread changes the shaper as fast as the policy lets it; what the node published must be,
sample for sample, what one filter gives when the same changes come between the same samples
(found from the node's own array filter). A torn change (a filter switched while a sample is shaped, a
last-sent command that aliases the filters' state) would differ.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from shaper_nodes.core.shaping import Mode, StreamingShaper, design, discretize
from shaper_nodes.nodes.shaper import ShaperNode

pytestmark = pytest.mark.integration
JOINTS = ["j1", "j2", "j3"]
RATE = 250.0
MIN_SAMPLES, MIN_CHANGES, MAX_SAMPLES = 6000, 20, 200_000  # the stream's length: see stream() below


def motion(n: int) -> np.ndarray:
    """Back-and-forth moves of the three joints (m), n samples at RATE."""
    t = np.arange(n) / RATE
    return np.column_stack([np.sin(2 * np.pi * 0.7 * t), 0.5 * np.sign(np.sin(2 * np.pi * 1.3 * t)),
                            np.clip(3 * np.sin(2 * np.pi * 0.2 * t), -1, 1)])


def test_shaper_changes_on_the_main_thread_land_between_two_streamed_samples(ros_context):
    node = ShaperNode(context=ros_context, parameter_overrides=[
        Parameter("joint_names", value=JOINTS), Parameter("command_rate", value=RATE),
        Parameter("shaper.family", value="zv"), Parameter("shaper.frequency_hz", value=5.0),
        Parameter("shaper.damping_ratio", value=0.05)])
    try:
        filt = node._array_filter
        assert isinstance(filt, StreamingShaper)
        shaped: list[int] = [0]  # samples the array filter has shaped
        changes: list[tuple[int, object]] = []  # (samples shaped before it, the FIR switched to)
        process, switch = filt.process_values, filt.switch  # the node's one-sample path

        def counting_process(x):
            y = process(x)
            shaped[0] += 1
            return y

        def recording_switch(fir):
            changes.append((shaped[0], fir))  # under stream_lock, as process: the count is the change's place
            switch(fir)

        filt.process_values, filt.switch = counting_process, recording_switch
        published: list[np.ndarray] = []
        node._array_pub.publish = lambda raw: published.append(deserialize_message(raw, Float64MultiArray).data)
        moves = motion(6000)
        sent: list[np.ndarray] = []
        done = threading.Event()

        def stream() -> None:  # the stream node's callback, on a thread of its own
            # at least the 6000 samples of the moves, and on (the moves again) until 20 changes have landed
            # between them: how the two threads interleave is the scheduler's (a loaded machine may run the
            # whole stream before the main thread gets far), so the stream waits for the state, not a count
            while len(sent) < MIN_SAMPLES or (len(changes) < MIN_CHANGES and len(sent) < MAX_SAMPLES):
                row = moves[len(sent) % moves.shape[0]]
                sent.append(row)
                node._on_array(serialize_message(Float64MultiArray(data=row.tolist())), None)  # as taken raw
            done.set()

        thread = threading.Thread(target=stream)
        thread.start()
        shapers = [design(f, [Mode.from_hz(hz, 0.05)]) for f in ("zv", "zvd", "ei") for hz in (4.0, 5.0, 6.5)]
        tries = 0
        while not done.is_set():
            node.request(shapers[tries % len(shapers)], "learner")  # refused while too many are settling
            tries += 1
        thread.join()
    finally:
        node.destroy_node()
    x = np.array(sent)
    assert len(published) == x.shape[0] and shaped[0] == x.shape[0]
    assert len(changes) >= MIN_CHANGES, f"only {len(changes)} changes of {tries} landed in {x.shape[0]} samples"
    assert any(0 < k < x.shape[0] for k, _ in changes)
    ref = StreamingShaper(discretize(design("zv", [Mode.from_hz(5.0, 0.05)]), RATE), len(JOINTS))
    want, k0 = [], 0
    for k, fir in [*changes, (x.shape[0], None)]:
        if k > k0:
            want += [ref.process(row) for row in x[k0:k]]
        if fir is not None:
            ref.switch(fir)
        k0 = k
    np.testing.assert_allclose(np.vstack(published), np.vstack(want), rtol=0, atol=1e-12)
