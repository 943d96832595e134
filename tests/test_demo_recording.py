"""The demo runs end to end, and its recording decodes with independent readers.

The demo's run is the session's shared one (tests/conftest.py's ``joint_demo``: one plant, the shapers none, zv
and zvd, one cycle each), which test_bag_analysis_over_dds.py analyses too.
"""

from collections import Counter

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

pytestmark = pytest.mark.integration


def test_demo_prints_table_and_writes_a_decodable_recording(joint_demo):
    out, proc = joint_demo
    assert proc["returncode"] == 0, proc["stdout"] + proc["stderr"]
    assert "Residual vibration" in proc["stdout"] and "zvd" in proc["stdout"]
    assert (out / "accelerometer.png").stat().st_size > 10_000
    assert (out / "recording" / "metadata.yaml").exists()

    mcaps = list((out / "recording").glob("*.mcap"))
    assert len(mcaps) == 1
    types = Counter()
    with open(mcaps[0], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, _channel, _message, decoded in reader.iter_decoded_messages():
            types[schema.name] += 1
            assert decoded is not None
    for t in ("sensor_msgs/msg/Imu", "sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray",
              "shaper_msgs/msg/CycleEvent", "shaper_msgs/msg/CycleReport", "shaper_msgs/msg/Shaper"):
        assert types[t] > 0, (t, types)
    assert types["shaper_msgs/msg/CycleEvent"] == 3 * 3  # 3 cases x 1 cycle x START, MOTION_END, END
    # rosbags reads the folder (metadata.yaml) and agrees on the counts
    with Reader(out / "recording") as bag:
        counts = Counter(c.msgtype for c, _, _ in bag.messages())
    assert counts == types
