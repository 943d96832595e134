"""The committed reference recordings (bags/): every message decodes with independent readers, and
the suite's analysis finds in them what they were recorded from."""

from __future__ import annotations

import collections
import pathlib

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from shaper_nodes.analysis.analyze import Options, analyze
from shaper_nodes.analysis.streams import read_recording

BAGS = pathlib.Path(__file__).resolve().parents[2] / "bags"
RECORDINGS = sorted(p.parent for p in BAGS.glob("*/metadata.yaml"))


def test_there_are_reference_recordings_and_they_stay_small():
    assert RECORDINGS, f"no recording under {BAGS}"
    total = sum(f.stat().st_size for f in BAGS.rglob("*") if f.is_file())
    assert total < 8 * 2**20, f"bags/ holds {total / 2**20:.1f} MiB; a few MB in all is the budget"


@pytest.mark.parametrize("folder", RECORDINGS, ids=lambda p: p.name)
def test_every_message_decodes_with_the_independent_readers(folder: pathlib.Path):
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    expected = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    (mcap_file,) = [folder / name for name in meta["relative_file_paths"]]
    counts: collections.Counter[str] = collections.Counter()
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        compressions = {c.compression for c in reader.get_summary().chunk_indexes}
        for _, channel, _, decoded in reader.iter_decoded_messages():
            assert decoded is not None
            counts[channel.topic] += 1
    assert compressions == {"zstd"}
    assert dict(counts) == {t: n for t, n in expected.items() if n}


def test_the_demo_recording_gives_its_plants_mode_and_the_shaped_cycles_at_the_noise_floor():
    an = analyze(read_recording(BAGS / "demo_joint_5hz_none_zvd"), Options(learners=()))
    assert [r.shaper.split()[0] for r in an.cycles] == ["none", "none", "zvd", "zvd"]
    assert an.modes[0].hz == pytest.approx(5.0, rel=0.01)
    assert an.modes[0].zeta == pytest.approx(0.01, rel=0.2)
    unshaped, shaped = an.cycles[0].rms, max(r.rms for r in an.cycles[2:])
    assert shaped < 0.01 * unshaped  # the ZVD on the true mode leaves the noise floor
    assert shaped < 3 * 0.01 * 3**0.5  # accelerometer noise 0.01 m/s^2 per axis
