import json
import pathlib

import numpy as np
import rclpy
from ament_index_python.packages import get_package_share_directory
from builtin_interfaces.msg import Time
from tf2_msgs.msg import TFMessage

from arm_core.camera import look_at
from arm_ros.conversions.poses import matrix_to_transform_msg, transform_msg_to_matrix
from arm_ros.tf import Tf2RosListener, TfListener, tf_listener


class _Node:
    def create_subscription(self, *args):
        return None


def _turn(angle: float, xyz) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    T[:3, 3] = xyz
    return T


def test_transform_message_round_trip():
    T = look_at((0.4, -0.2, 0.6), (0.0, 0.1, 0.0))
    msg = matrix_to_transform_msg(T, "world", "camera_color_optical_frame", Time(sec=3))
    assert (msg.header.frame_id, msg.child_frame_id, msg.header.stamp.sec) == ("world", "camera_color_optical_frame", 3)
    assert np.allclose(transform_msg_to_matrix(msg), T)


def test_listener_chains_the_tree_both_ways_and_keeps_the_newest():
    T_world_base, T_base_camera = _turn(0.3, (0.1, 0.2, 0.0)), look_at((0.5, 0.0, 0.7), (0.9, 0.0, 0.0))
    T_base_camera_later = look_at((0.5, 0.1, 0.7), (0.9, 0.0, 0.0))
    T_world_table = _turn(0.0, (0.6, 0.0, 0.75))
    listener = TfListener(_Node())
    send = [
        matrix_to_transform_msg(T_world_base, "world", "base_link", Time()),
        matrix_to_transform_msg(T_base_camera, "/base_link", "camera", Time()),
        matrix_to_transform_msg(T_world_table, "world", "table", Time()),
    ]
    listener.on_message(TFMessage(transforms=send))
    assert np.allclose(listener.lookup("world", "camera"), T_world_base @ T_base_camera)
    assert np.allclose(listener.lookup("table", "camera"), np.linalg.inv(T_world_table) @ T_world_base @ T_base_camera)
    assert np.allclose(listener.lookup("camera", "world"), np.linalg.inv(T_world_base @ T_base_camera))
    moved = matrix_to_transform_msg(T_base_camera_later, "base_link", "camera", Time())
    listener.on_message(TFMessage(transforms=[moved]))
    assert np.allclose(listener.lookup("world", "camera"), T_world_base @ T_base_camera_later)
    assert listener.lookup("world", "elsewhere") is None and np.allclose(listener.lookup("table", "table"), np.eye(4))


def test_listener_skips_malformed_transforms_and_holds_a_bounded_number_of_frames():
    listener = TfListener(_Node(), max_frames=10)
    bad = matrix_to_transform_msg(np.eye(4), "world", "broken", Time())
    bad.transform.rotation.w = float("nan")
    good = matrix_to_transform_msg(np.eye(4), "world", "fine", Time())
    listener.on_message(TFMessage(transforms=[bad, good]))
    assert listener.lookup("world", "fine") is not None and listener.lookup("world", "broken") is None
    many = [matrix_to_transform_msg(_turn(0.0, (i, 0, 0)), "world", f"f{i}", Time()) for i in range(50)]
    listener.on_message(TFMessage(transforms=many))
    assert len(listener.frames()) <= 11 and np.allclose(listener.lookup("world", "f49")[:3, 3], (49, 0, 0))


def test_tf_message_has_the_wire_type_of_ros2_tf2_msgs():
    """Where tf2_msgs is built from compat/: same type name and fields, and geometry_msgs' own
    TransformStamped (same type hash) inside, so the RIHS01 type hash is a full ROS 2 install's."""
    description = json.loads((pathlib.Path(get_package_share_directory("tf2_msgs")) / "msg/TFMessage.json").read_text())
    root = description["type_description_msg"]["type_description"]
    assert root["type_name"] == "tf2_msgs/msg/TFMessage"
    (field,) = root["fields"]
    assert field["name"] == "transforms" and field["type"]["nested_type_name"] == "geometry_msgs/msg/TransformStamped"
    assert field["type"]["type_id"] == 145 and field["type"]["capacity"] == 0  # unbounded sequence of a message
    geometry = json.loads(
        (pathlib.Path(get_package_share_directory("geometry_msgs")) / "msg/TransformStamped.json").read_text()
    )
    hashes = {h["type_name"]: h["hash_string"] for h in description["type_hashes"]}
    assert hashes["geometry_msgs/msg/TransformStamped"] == geometry["type_hashes"][0]["hash_string"]


def test_the_listener_is_tf2_ros_where_installed_else_the_chaining_one():
    rclpy.init()
    try:
        node = rclpy.create_node("tf_listener_choice")
        listener = tf_listener(node)
        try:
            import tf2_ros  # noqa: F401
        except ImportError:
            assert isinstance(listener, TfListener)
        else:
            assert isinstance(listener, Tf2RosListener) and listener.lookup("a", "b") is None
        node.destroy_node()
    finally:
        rclpy.shutdown()
