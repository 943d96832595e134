"""The sim plant's writer profile (node/writer_profile): the installed file's times; when the executable names it."""

from __future__ import annotations

import pathlib
import xml.etree.ElementTree as ET

from sim_plant_node.node.writer_profile import PROFILES_ENV, QOS_FROM_XML_ENV, profile_path, use_writer_profile

NS = {"d": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def _seconds(times: ET.Element, name: str) -> float:
    element = times.find(f"d:{name}", NS)
    assert element is not None, name
    return int(element.findtext("d:sec", "0", NS)) + int(element.findtext("d:nanosec", "0", NS)) * 1e-9


def test_the_installed_profile_is_a_default_writer_profile_with_the_times_and_no_qos() -> None:
    root = ET.parse(profile_path()).getroot()
    writers = root.findall("d:profiles/d:data_writer", NS)
    assert len(writers) == 1 and writers[0].get("is_default_profile") == "true"
    assert writers[0].find("d:qos", NS) is None  # the node's QoS stays the node's
    times = writers[0].find("d:times", NS)
    assert times is not None
    assert _seconds(times, "nackSupressionDuration") == 0.01
    assert _seconds(times, "heartbeatPeriod") == 0.1
    assert not root.findall("d:profiles/d:participant", NS) and not root.findall("d:profiles/d:data_reader", NS)


def test_named_when_the_environment_names_no_profile() -> None:
    env: dict[str, str] = {"OTHER": "1", QOS_FROM_XML_ENV: "0"}
    assert use_writer_profile(env) == profile_path()
    assert env[PROFILES_ENV] == str(profile_path())


def test_a_profile_the_environment_names_wins(tmp_path: pathlib.Path) -> None:
    own = str(tmp_path / "own.xml")
    env = {PROFILES_ENV: own}
    assert use_writer_profile(env) is None
    assert env == {PROFILES_ENV: own}


def test_left_alone_when_rmw_takes_the_qos_from_xml_or_the_file_is_missing(tmp_path: pathlib.Path) -> None:
    env = {QOS_FROM_XML_ENV: "1"}
    assert use_writer_profile(env) is None and PROFILES_ENV not in env
    env = {}
    assert use_writer_profile(env, tmp_path / "missing.xml") is None and env == {}
