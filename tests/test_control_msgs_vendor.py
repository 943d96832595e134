"""The vendored control_msgs keeps the layout of control_msgs 5.x (ROS 2 Jazzy) exactly.

Fields (names, types, order) and constants are what the DDS types and the CDR encoding are
made of; the RIHS01 type hashes that rosidl computes from them are pinned too, so that any
change to vendor/control_msgs (a renamed field, a new default value) fails here.
"""

from __future__ import annotations

import json
import pathlib

import pytest
from ament_index_python.packages import get_package_share_directory
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointComponentTolerance, JointTolerance

GOAL = [
    ("trajectory", "trajectory_msgs/JointTrajectory"),
    ("multi_dof_trajectory", "trajectory_msgs/MultiDOFJointTrajectory"),
    ("path_tolerance", "sequence<control_msgs/JointTolerance>"),
    ("component_path_tolerance", "sequence<control_msgs/JointComponentTolerance>"),
    ("goal_tolerance", "sequence<control_msgs/JointTolerance>"),
    ("component_goal_tolerance", "sequence<control_msgs/JointComponentTolerance>"),
    ("goal_time_tolerance", "builtin_interfaces/Duration"),
]
RESULT = [("error_code", "int32"), ("error_string", "string")]
FEEDBACK = [
    ("header", "std_msgs/Header"),
    ("joint_names", "sequence<string>"),
    ("desired", "trajectory_msgs/JointTrajectoryPoint"),
    ("actual", "trajectory_msgs/JointTrajectoryPoint"),
    ("error", "trajectory_msgs/JointTrajectoryPoint"),
    ("multi_dof_joint_names", "sequence<string>"),
    ("multi_dof_desired", "trajectory_msgs/MultiDOFJointTrajectoryPoint"),
    ("multi_dof_actual", "trajectory_msgs/MultiDOFJointTrajectoryPoint"),
    ("multi_dof_error", "trajectory_msgs/MultiDOFJointTrajectoryPoint"),
]
JOINT_TOLERANCE = [("name", "string"), ("position", "double"), ("velocity", "double"), ("acceleration", "double")]
JOINT_COMPONENT_TOLERANCE = [("joint_name", "string"), ("component", "uint16"), ("position", "double"),
                             ("velocity", "double"), ("acceleration", "double")]
RESULT_CODES = {"SUCCESSFUL": 0, "INVALID_GOAL": -1, "INVALID_JOINTS": -2, "OLD_HEADER_TIMESTAMP": -3,
                "PATH_TOLERANCE_VIOLATED": -4, "GOAL_TOLERANCE_VIOLATED": -5}
COMPONENTS = {"X_AXIS": 1, "Y_AXIS": 2, "Z_AXIS": 3, "TRANSLATION": 4, "ROTATION": 5}

# RIHS01 hashes generated from vendor/control_msgs by rosidl (Jazzy). Compare with the
# system package on an apt machine (see vendor/control_msgs/README.md).
HASHES = {
    "control_msgs/action/FollowJointTrajectory":
        "RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6",
    "control_msgs/action/FollowJointTrajectory_Goal":
        "RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205",
    "control_msgs/action/FollowJointTrajectory_Result":
        "RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220",
    "control_msgs/action/FollowJointTrajectory_Feedback":
        "RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49",
    "control_msgs/msg/JointTolerance":
        "RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648",
    "control_msgs/msg/JointComponentTolerance":
        "RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4",
}


@pytest.mark.parametrize("cls, fields", [
    (FollowJointTrajectory.Goal, GOAL), (FollowJointTrajectory.Result, RESULT),
    (FollowJointTrajectory.Feedback, FEEDBACK), (JointTolerance, JOINT_TOLERANCE),
    (JointComponentTolerance, JOINT_COMPONENT_TOLERANCE)])
def test_fields_names_types_and_order(cls, fields):
    assert list(cls.get_fields_and_field_types().items()) == fields


def test_constants():
    assert {k: getattr(FollowJointTrajectory.Result, k) for k in RESULT_CODES} == RESULT_CODES
    assert {k: getattr(JointComponentTolerance, k) for k in COMPONENTS} == COMPONENTS


def test_type_hashes_are_pinned():
    share = pathlib.Path(get_package_share_directory("control_msgs"))
    hashes = {}
    for path in [share / "action" / "FollowJointTrajectory.json", share / "msg" / "JointTolerance.json",
                 share / "msg" / "JointComponentTolerance.json"]:
        hashes.update({h["type_name"]: h["hash_string"] for h in json.loads(path.read_text())["type_hashes"]})
    assert {k: hashes.get(k) for k in HASHES} == HASHES
