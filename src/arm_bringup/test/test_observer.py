"""The demo's observer finds the segmented frame a mesh array was built from."""

import rclpy
from std_msgs.msg import Header

from arm_bringup.observer import SEGMENTED_FRAMES_KEPT, Observer
from arm_interfaces.msg import SegmentedFrame
from arm_ros.common import use_private_domain


def _frame(sec: int) -> SegmentedFrame:
    frame = SegmentedFrame()
    frame.header.stamp.sec = sec
    frame.header.stamp.nanosec = 5
    return frame


def test_the_segmented_frame_of_a_mesh_array_is_found_by_stamp_and_old_frames_are_let_go():
    use_private_domain()
    rclpy.init()
    try:
        node = rclpy.create_node("observer_test")
        observer = Observer(node)
        for sec in range(SEGMENTED_FRAMES_KEPT + 5):
            observer._store("arm/segmented_frame", _frame(sec))
        meshes_header = Header()
        meshes_header.stamp.sec, meshes_header.stamp.nanosec = 20, 5
        assert observer.segmented_frame_for(meshes_header).header.stamp.sec == 20
        meshes_header.stamp.nanosec = 6
        assert observer.segmented_frame_for(meshes_header) is None, "another frame's stamp"
        meshes_header.stamp.sec, meshes_header.stamp.nanosec = 2, 5
        assert observer.segmented_frame_for(meshes_header) is None, "older than the frames kept"
        assert len(observer.segmented_frames) == SEGMENTED_FRAMES_KEPT
        node.destroy_node()
    finally:
        rclpy.shutdown()


def test_a_message_newer_than_a_stamp_is_awaited_and_an_older_one_is_not_taken():
    use_private_domain()
    rclpy.init()
    try:
        node = rclpy.create_node("observer_newer_test")
        observer = Observer(node)
        observer._store("arm/segmented_frame", _frame(10))
        after = _frame(10).header.stamp
        assert observer.newer("arm/segmented_frame", after, timeout_s=0.2) is None, "not newer"
        observer._store("arm/segmented_frame", _frame(11))
        assert observer.newer("arm/segmented_frame", after, timeout_s=0.2).header.stamp.sec == 11
        node.destroy_node()
    finally:
        rclpy.shutdown()
