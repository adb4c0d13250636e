"""control_msgs as plan_node and sim_node use it has ros2_control's wire types. Where the workspace
builds it from compat/ (no control_msgs installed), its messages must hash as control_msgs 5.x on
ROS 2 Jazzy does (RIHS01 hashes of the generated code), and the actions must have its fields."""

import json
import pathlib

from ament_index_python.packages import get_package_share_directory

SHARE = pathlib.Path(get_package_share_directory("control_msgs"))

# RIHS01 type hashes of control_msgs 5.x as generated on a full ROS 2 install.
JAZZY_HASHES = {
    "control_msgs/msg/JointTolerance": "RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648",
    "control_msgs/msg/JointComponentTolerance": (
        "RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4"
    ),
    "control_msgs/msg/GripperCommand": "RIHS01_57eb8f326c9889ca8bb34ead82cc94cc09bf6bc5c3b6c09546dca3a00b589890",
}


def _description(relative: str) -> dict:
    return json.loads((SHARE / relative).read_text())


def _fields(description: dict, type_name: str) -> list[tuple[str, int, str]]:
    msg = description["type_description_msg"]
    types = [msg["type_description"], *msg["referenced_type_descriptions"]]
    (found,) = [t for t in types if t["type_name"] == type_name]
    return [(f["name"], f["type"]["type_id"], f["type"]["nested_type_name"]) for f in found["fields"]]


def test_messages_hash_as_on_ros2_jazzy():
    for type_name, expected in JAZZY_HASHES.items():
        hashes = _description(f"msg/{type_name.rsplit('/', 1)[1]}.json")["type_hashes"]
        assert hashes[0]["type_name"] == type_name and hashes[0]["hash_string"] == expected


def test_follow_joint_trajectory_has_the_controllers_fields():
    description = _description("action/FollowJointTrajectory.json")
    goal = _fields(description, "control_msgs/action/FollowJointTrajectory_Goal")
    assert [name for name, _, _ in goal] == [
        "trajectory",
        "multi_dof_trajectory",
        "path_tolerance",
        "component_path_tolerance",
        "goal_tolerance",
        "component_goal_tolerance",
        "goal_time_tolerance",
    ]
    assert goal[0][2] == "trajectory_msgs/msg/JointTrajectory" and goal[2][2] == "control_msgs/msg/JointTolerance"
    result = _fields(description, "control_msgs/action/FollowJointTrajectory_Result")
    assert result == [("error_code", 6, ""), ("error_string", 17, "")]  # int32, string
    feedback = [name for name, _, _ in _fields(description, "control_msgs/action/FollowJointTrajectory_Feedback")]
    assert feedback == [
        "header",
        "joint_names",
        "desired",
        "actual",
        "error",
        "multi_dof_joint_names",
        "multi_dof_desired",
        "multi_dof_actual",
        "multi_dof_error",
    ]
    hashes = {h["type_name"]: h["hash_string"] for h in description["type_hashes"]}
    assert hashes["control_msgs/msg/JointTolerance"] == JAZZY_HASHES["control_msgs/msg/JointTolerance"]


def test_gripper_command_has_the_controllers_fields():
    description = _description("action/GripperCommand.json")
    goal = _fields(description, "control_msgs/action/GripperCommand_Goal")
    assert goal == [("command", 1, "control_msgs/msg/GripperCommand")]
    result = [name for name, _, _ in _fields(description, "control_msgs/action/GripperCommand_Result")]
    assert result == ["position", "effort", "stalled", "reached_goal"]
