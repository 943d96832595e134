"""The graph watch's decisions without a graph: findings, their status, and logging each once."""

from __future__ import annotations

from shaper_nodes.ros.diagnostics import ERROR, OK, WARN
from shaper_nodes.ros.graph_rules import (
    UNKNOWN_NODE,
    Endpoint,
    Latch,
    Watched,
    event_finding,
    fqn,
    graph_findings,
    summary,
)

ME = "/shaper"
ARRAY = "std_msgs/msg/Float64MultiArray"
TRAJ = "trajectory_msgs/msg/JointTrajectory"
IN_T, OUT_T = "/shaper/commands", "/forward_position_controller/commands"
WATCHED = [Watched(IN_T, "in", ARRAY), Watched(OUT_T, "out", ARRAY, own_publishers=1)]
NODES = [ME, "/shaper_trajectories", "/source"]


def mine() -> Endpoint:
    """The node's own publisher on OUT_T."""
    return Endpoint(ME, ARRAY)


def findings(nodes=NODES, pubs=None, subs=None):
    pubs = {IN_T: [Endpoint("/source", ARRAY)], OUT_T: [mine()], **(pubs or {})}
    subs = {IN_T: [Endpoint(ME, ARRAY)], OUT_T: [Endpoint("/controller", ARRAY)], **(subs or {})}
    return graph_findings(ME, nodes, WATCHED, pubs, subs)


def only(found, kind):
    assert [f.kind for f in found] == [kind], found
    return found[0]


def test_a_graph_as_drawn_has_no_findings_and_an_ok_status():
    assert findings() == []
    level, message, values = summary([])
    assert level == OK and "at most one publisher" in message and values == []


def test_names_are_fully_qualified_and_unknown_participants_named_as_such():
    assert fqn("shaper", "/") == "/shaper" and fqn("shaper", "/arm") == "/arm/shaper"
    assert fqn("_NODE_NAME_UNKNOWN_", "_NODE_NAMESPACE_UNKNOWN_") == UNKNOWN_NODE


def test_a_second_node_of_this_name_is_an_error_that_absorbs_its_outputs():
    f = only(findings(nodes=[*NODES, ME], pubs={OUT_T: [mine(), mine()]}), "duplicate_name")
    assert f.level == ERROR and "2 nodes named /shaper" in f.message and OUT_T in f.message
    assert dict(f.values) == {"node": ME, "count": "2", "also_publishes": OUT_T}


def test_our_own_publisher_twice_without_a_twin_is_another_publisher_of_our_name():
    """Without a second node of this name in the node list, a surplus publisher under it is still reported."""
    f = only(findings(pubs={OUT_T: [mine(), mine()]}), "other_publisher")
    assert f.nodes == (ME,)


def test_two_publishers_on_an_input_warn_with_both_names():
    f = only(findings(pubs={IN_T: [Endpoint("/b", ARRAY), Endpoint("/a", ARRAY)]}), "publishers")
    assert f.level == WARN and f.nodes == ("/a", "/b") and f.topic == IN_T
    assert dict(f.values)["publishers"] == "/a, /b" and dict(f.values)["count"] == "2"


def test_one_node_with_two_publishers_on_an_input_is_counted():
    f = only(findings(pubs={IN_T: [Endpoint("/a", ARRAY), Endpoint("/a", ARRAY)]}), "publishers")
    assert dict(f.values)["publishers"] == "/a (2)"


def test_another_publisher_on_an_output_is_an_error():
    f = only(findings(pubs={OUT_T: [Endpoint("/teleop", ARRAY), mine()]}), "other_publisher")
    assert f.level == ERROR and f.nodes == ("/teleop",) and "not shape" in f.message
    assert dict(f.values) == {"topic": OUT_T, "publishers": "/teleop", "types": ARRAY}


def test_a_wrong_type_on_an_input_or_an_output_is_an_error_naming_both_types():
    f = only(findings(pubs={IN_T: [Endpoint("/src", "std_msgs/msg/String")]}), "wrong_type")
    assert f.level == ERROR and "never reach /shaper" in f.message
    assert dict(f.values) == {"topic": IN_T, "publishers": "/src", "type": "std_msgs/msg/String", "expected": ARRAY}
    f = only(findings(subs={OUT_T: [Endpoint("/controller", TRAJ)]}), "wrong_type")
    assert dict(f.values)["subscribers"] == "/controller" and "gets nothing from" in f.message


def test_incompatible_qos_names_the_node_and_the_reason():
    problem = "Best effort publisher and reliable subscription"
    f = only(findings(pubs={IN_T: [Endpoint("/src", ARRAY, problem)]}), "qos")
    assert f.level == ERROR and f.nodes == ("/src",) and problem in f.message
    assert dict(f.values) == {"topic": IN_T, "publishers": "/src", "reason": problem}
    # QoS of endpoints on the node's own side is not compared (its subscribers of an input do not matter)
    assert findings(subs={IN_T: [Endpoint("/spy", ARRAY, "whatever")]}) == []


def test_several_findings_make_one_status_with_the_worst_level_and_prefixed_values():
    found = findings(pubs={IN_T: [Endpoint("/a", ARRAY), Endpoint("/b", "std_msgs/msg/String")]})
    assert [f.kind for f in found] == ["publishers", "wrong_type"]
    level, message, values = summary(found)
    assert level == ERROR and message.startswith("2 problems in the graph")
    keys = dict(values)
    assert keys[f"publishers@{IN_T}.publishers"] == "/a, /b"
    assert keys[f"wrong_type@{IN_T}.type"] == "std_msgs/msg/String"


def test_the_latch_tells_a_finding_once_until_it_clears_and_comes_back():
    latch = Latch()
    two = findings(pubs={IN_T: [Endpoint("/a", ARRAY), Endpoint("/b", ARRAY)]})
    assert latch.update(two) == (two, two, [])
    for _ in range(5):
        assert latch.update(two) == (two, [], [])
    assert latch.update([]) == ([], [], two)
    assert latch.update(two) == (two, two, [])
    three = findings(pubs={IN_T: [Endpoint("/a", ARRAY), Endpoint("/b", ARRAY), Endpoint("/c", ARRAY)]})
    assert latch.update(three) == (three, three, two)  # other nodes: another finding


def test_a_finding_without_a_node_holds_only_after_settling():
    """A new node's endpoints are discovered before its name: such a finding must last to be told."""
    latch = Latch(settle=3)
    nameless = findings(pubs={OUT_T: [mine(), Endpoint(UNKNOWN_NODE, ARRAY)]})
    assert nameless[0].nodes == (UNKNOWN_NODE,)
    assert latch.update(nameless) == ([], [], [])
    assert latch.update(nameless) == ([], [], [])
    assert latch.update(nameless) == (nameless, nameless, [])
    assert latch.update([]) == ([], [], nameless)
    assert latch.update(nameless) == ([], [], [])  # the streak starts again


def test_an_unexplained_middleware_event_names_its_policy():
    f = event_finding(IN_T, "qos", "in", "RELIABILITY")
    assert f.level == ERROR and "publisher" in f.message and "RELIABILITY" in f.message
    assert dict(f.values)["policy"] == "RELIABILITY"
