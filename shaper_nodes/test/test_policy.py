"""The shaper node's update policy, without DDS (core/shaping/policy.py)."""

from __future__ import annotations

import pytest

from shaper_nodes.core.shaping import MAX_STAGES, Mode, design, none_shaper
from shaper_nodes.core.shaping.policy import DEFAULT_SOURCE, PolicyError, UpdatePolicy, check_representable

ZV = design("zv", [Mode.from_hz(5.0, 0.05)])  # 0.1 s long
POLICY = UpdatePolicy.of(["parameters", "learner", "scheduler"], retime=["scheduler"])


def test_only_allowed_sources_change_the_shaper_and_the_refusal_says_why():
    assert POLICY.decide("learner", ZV, 500.0, [0, 0]) == "switch"
    with pytest.raises(PolicyError, match=r"update policy: source 'intruder' is not in allowed_sources"):
        POLICY.decide("intruder", ZV, 500.0, [0, 0])
    assert UpdatePolicy.source_of("  ") == DEFAULT_SOURCE and UpdatePolicy.source_of(" user ") == "user"


def test_retime_sources_retime_and_others_switch():
    assert POLICY.how("scheduler") == "retime" and POLICY.how("learner") == "switch"
    assert POLICY.decide("scheduler", ZV, 500.0, [MAX_STAGES]) == "retime"  # needs no new stage


def test_a_switch_beyond_the_stage_limit_waits_for_the_old_shapers_to_retire():
    assert POLICY.decide("learner", ZV, 500.0, [MAX_STAGES - 1, 0]) == "switch"
    with pytest.raises(PolicyError, match="still settling"):
        POLICY.decide("learner", ZV, 500.0, [0, MAX_STAGES])
    with pytest.raises(PolicyError, match="still settling"):
        POLICY.settled([MAX_STAGES])


def test_a_shaper_shorter_than_one_command_period_is_refused_but_the_identity_is_not():
    with pytest.raises(PolicyError, match="shorter than one command period"):
        POLICY.decide("learner", ZV, 5.0, [0])  # 0.1 s at 5 Hz: half a period
    assert POLICY.decide("learner", none_shaper(), 5.0, [0]) == "switch"
    check_representable(ZV, 10.0)  # one period exactly: representable
    with pytest.raises(PolicyError, match=r"100 ms is shorter than one command period \(200 ms\)"):
        check_representable(ZV, 5.0)  # the same check, for a shaper used on one trajectory only
    check_representable(none_shaper(), 5.0)
