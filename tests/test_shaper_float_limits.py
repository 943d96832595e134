"""The shaper node's ~/set_shaper over real DDS with the core's float-limit refusals: a design mode too
slow to have a float period (5e-324 Hz), amplitudes near 1.7e308, and modes far above the command rate
(a designed family's, refused by check_design; a custom shaper's label, refused by ``exact``) are each
refused with a reason that names the problem, the active shaper stays, and the node keeps shaping;
the slow mode through the parameters too (shaper.frequencies_hz).

The node and a probe in one executor with a fresh Context (``Rig`` of test_shaper_node.py); every wait
is for a state (the service's answer, a shaped sample) with a timeout, never a fixed sleep.
"""

from __future__ import annotations

import pytest
from rclpy.parameter import Parameter
from test_shaper_node import Rig, send_valid_array_and_expect_output

from shaper_msgs.msg import Shaper as ShaperMsg
from shaper_msgs.srv import SetShaper
from shaper_nodes.ros.conversions import mode_msg

pytestmark = pytest.mark.integration

#: the Rig's command rate, Hz, and a mode far above it: zeta omega Ts = 0.05 * 2 pi * 1e8 / 100 ~ 3.1e5
RATE = 100.0
FAR_HZ = 1e8

CASES = [
    # (request, words the answer must hold)
    (ShaperMsg(family="zv", design_modes=[mode_msg(5e-324, 0.0)]),
     ["invalid shaper", "design mode 0", "too slow to design for", "exceeds the limit of 60000 s"]),
    (ShaperMsg(family="zvd", design_modes=[mode_msg(3.0, 0.05), mode_msg(FAR_HZ, 0.05)]),
     ["1e+08 Hz is outside [0.01, 1000] Hz"]),
    (ShaperMsg(family="custom", amplitudes=[0.5, 0.5], times=[0.0, 0.1234],
               design_modes=[mode_msg(3.0, 0.05), mode_msg(FAR_HZ, 0.05)]),
     ["exact discretisation", "design mode 1 (1e+08 Hz, damping ratio 0.05)", "beyond the limit of 700",
      "use 'split'"]),
    (ShaperMsg(family="custom", amplitudes=[1.7e308, -1.7e308, 1.0], times=[0.0, 0.1, 0.2]),
     ["invalid shaper", "amplitude 1.7e+308 of impulse 0 exceeds the limit of 1e+300 in magnitude"]),
]


@pytest.fixture
def exact_rig(ros_context):
    r = Rig(ros_context, discretization="exact", **{"shaper.max_gain": 100.0})
    yield r
    r.close()


def test_set_shaper_refuses_float_limit_modes_and_amplitudes_by_name_and_keeps_shaping(exact_rig):
    rig = exact_rig
    send_valid_array_and_expect_output(rig, 0.0)
    before = rig.active[-1]
    assert before.family == "zv"
    for shaper, words in CASES:
        shaper.source = "user"
        resp = rig.call(SetShaper, "/shaper/set_shaper", SetShaper.Request(shaper=shaper))
        assert not resp.success, (shaper.family, resp.message)
        for w in words:
            assert w in resp.message, (w, resp.message)
        assert "design failed" not in resp.message and "Warning" not in resp.message  # no overflow on the way
        assert resp.active.family == "zv" and resp.active.revision == before.revision
        send_valid_array_and_expect_output(rig, 0.5)  # still shaping, with the old shaper
    # the parameters' path: the same mode through shaper.frequencies_hz (no range of its own but Mode's)
    result = rig.node.set_parameters_atomically([Parameter("shaper.frequencies_hz", value=[5e-324]),
                                                 Parameter("shaper.damping_ratios", value=[0.05])])
    assert not result.successful and "too slow to design for" in result.reason, result.reason
    assert "shaper.frequencies_hz[0] 5e-324 Hz" in result.reason, result.reason  # the parameter, in its unit
    assert rig.active[-1].revision == before.revision
    send_valid_array_and_expect_output(rig, 0.5)
    # the same custom shaper with modes the command rate can hold is accepted, discretised exactly
    ok = ShaperMsg(family="custom", amplitudes=[0.5, 0.5], times=[0.0, 0.1234], design_modes=[mode_msg(3.0, 0.05)],
                   source="user")
    resp = rig.call(SetShaper, "/shaper/set_shaper", SetShaper.Request(shaper=ok))
    assert resp.success, resp.message
    assert resp.active.family == "custom" and resp.active.revision == before.revision + 1
    for _ in range(30):  # longer than the shaper (0.1234 s: 13 samples at 100 Hz)
        send_valid_array_and_expect_output(rig, 1.0)
    assert rig.array_out[-1] == pytest.approx([1.0] * 3, abs=1e-9)
