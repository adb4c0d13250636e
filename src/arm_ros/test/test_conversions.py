import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from arm_core.camera import intrinsics, look_at
from arm_core.frames import RgbdFrame
from arm_interfaces.msg import ReconstructedObject
from arm_ros.conversions import ConversionError
from arm_ros.conversions.frames import frame_from_camera_msgs, frame_from_msg, labels_from_msg, segmented_frame_msg
from arm_ros.conversions.images import (
    K_from_camera_info,
    camera_info_from_K,
    depth_to_metres,
    image_to_numpy,
    numpy_to_image,
)
from arm_ros.conversions.meshes import (
    mesh_to_msg,
    msg_to_mesh,
    reconstructed_object_from_msg,
    reconstructed_object_msg,
)
from arm_ros.conversions.poses import matrix_to_pose, pose_to_matrix
from arm_ros.conversions.stamps import cdr_header_stamp_ns, ns_to_time, seconds_to_duration, time_ns


def test_images_round_trip():
    rgb = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
    assert np.array_equal(image_to_numpy(numpy_to_image(rgb, "rgb8")), rgb)
    depth = np.random.default_rng(0).random((4, 5)).astype(np.float32)
    assert np.array_equal(depth_to_metres(numpy_to_image(depth, "32FC1")), depth)
    mm = (depth * 1000).astype(np.uint16)
    assert np.allclose(depth_to_metres(numpy_to_image(mm, "16UC1")), mm / 1000.0)


def test_malformed_images_raise_conversion_errors():
    msg = numpy_to_image(np.zeros((4, 5), np.float32), "32FC1")
    msg.data = msg.data[:10]
    with pytest.raises(ConversionError):
        image_to_numpy(msg)
    with pytest.raises(ConversionError):
        image_to_numpy(Image(encoding="yuv422", height=2, width=2, step=4, data=bytes(8)))
    with pytest.raises(ConversionError):
        K_from_camera_info(CameraInfo())
    assert np.allclose(
        K_from_camera_info(camera_info_from_K(np.array([[500, 0, 320], [0, 500, 240], [0, 0, 1.0]]), 640, 480))[0, 0],
        500,
    )


def test_poses_and_meshes_round_trip():
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    T = np.eye(4)
    T[:3, :3] = q * np.sign(np.linalg.det(q))
    T[:3, 3] = rng.normal(size=3)
    assert np.allclose(pose_to_matrix(matrix_to_pose(T)), T)
    vertices, faces = rng.random((6, 3)), np.array([[0, 1, 2], [3, 4, 5]])
    v, f = msg_to_mesh(mesh_to_msg(vertices, faces))
    assert np.allclose(v, vertices) and np.array_equal(f, faces)
    bad = matrix_to_pose(T)
    bad.position.x = float("nan")
    with pytest.raises(ConversionError):
        pose_to_matrix(bad)


def _frame(labels=True) -> RgbdFrame:
    rng = np.random.default_rng(2)
    rgb = rng.integers(0, 255, (12, 16, 3), dtype=np.uint8)
    depth = rng.uniform(0.3, 2.0, (12, 16)).astype(np.float32)
    depth[0, 0] = 0.0
    label_image = np.zeros((12, 16), np.uint16)
    label_image[4:8, 4:8], label_image[9:, 12:] = 3, 1
    T = look_at((0.5, 0.2, 0.6), (0.0, 0.0, 0.0))
    return RgbdFrame(rgb, depth, intrinsics(16, 12), T, label_image if labels else None, "map")


def test_segmented_frames_round_trip():
    frame = _frame()
    header = Header(frame_id="camera")
    header.stamp.sec, header.stamp.nanosec = 3, 500_000_000
    msg = segmented_frame_msg(frame, header)
    assert list(msg.instance_ids) == [1, 3] and msg.world_frame_id == "map"
    assert msg.labels.encoding == "16UC1" and msg.depth.encoding == "32FC1" and msg.rgb.encoding == "rgb8"
    back = frame_from_msg(msg)
    assert np.array_equal(back.rgb, frame.rgb) and np.array_equal(back.depth_m, frame.depth_m)
    assert np.array_equal(back.labels, frame.labels) and back.instance_ids == [1, 3]
    assert np.array_equal(back.K, frame.K) and np.allclose(back.T_world_camera, frame.T_world_camera, atol=1e-12)
    assert back.world_frame_id == "map" and back.stamp_s == 3.5
    info = CameraInfo(width=16, height=12, k=list(frame.K.ravel()), distortion_model="equidistant")
    pose = msg.camera_pose
    passed = segmented_frame_msg(frame, header, info, pose)
    assert passed.camera_info.distortion_model == "equidistant" and passed.camera_pose is pose
    without_rgb = RgbdFrame(None, frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    no_rgb = frame_from_msg(segmented_frame_msg(without_rgb))
    assert no_rgb.rgb is None
    with pytest.raises(ConversionError, match="labels"):
        segmented_frame_msg(_frame(labels=False))


def _camera_msgs(frame):
    header = Header(frame_id="camera")
    pose = PoseStamped(pose=matrix_to_pose(frame.T_world_camera))
    pose.header.frame_id = "world"
    info = camera_info_from_K(frame.K, 16, 12, header)
    return numpy_to_image(frame.rgb, "rgb8", header), numpy_to_image(frame.depth_m, "32FC1", header), info, pose


def test_camera_messages_decode_to_a_frame():
    frame = _frame()
    rgb_msg, depth_msg, info, pose = _camera_msgs(frame)
    decoded = frame_from_camera_msgs(numpy_to_image(frame.rgb[..., ::-1], "bgr8"), depth_msg, info, pose)
    assert np.array_equal(decoded.rgb, frame.rgb) and np.array_equal(decoded.depth_m, frame.depth_m)
    assert decoded.labels is None and decoded.world_frame_id == "world"
    assert np.array_equal(labels_from_msg(numpy_to_image(frame.labels, "16UC1"), (12, 16)), frame.labels)


@pytest.mark.parametrize("problem", ["rgb_encoding", "depth_encoding", "size", "info_size", "zero_K", "nan_pose"])
def test_malformed_camera_messages_raise_conversion_errors(problem):
    frame = _frame()
    rgb_msg, depth_msg, info, pose = _camera_msgs(frame)
    if problem == "rgb_encoding":
        rgb_msg = numpy_to_image(frame.rgb[..., 0], "mono8")
    elif problem == "depth_encoding":
        depth_msg = numpy_to_image(frame.labels, "32SC1")
    elif problem == "size":
        rgb_msg = numpy_to_image(frame.rgb[:-1], "rgb8")
    elif problem == "info_size":
        info.width = 8
    elif problem == "zero_K":
        info.k = [0.0] * 9
    elif problem == "nan_pose":
        pose.pose.position.x = float("nan")
    with pytest.raises(ConversionError):
        frame_from_camera_msgs(rgb_msg, depth_msg, info, pose)
    with pytest.raises(ConversionError):
        labels_from_msg(numpy_to_image(frame.labels[:-1], "16UC1"), (12, 16))
    with pytest.raises(ConversionError):
        labels_from_msg(numpy_to_image(frame.labels.astype(np.uint8), "mono8"), (12, 16))


def test_reconstructed_objects_round_trip():
    rng = np.random.default_rng(4)
    vertices, faces = rng.random((5, 3)) + (1.0, 2.0, 0.5), np.array([[0, 1, 2], [2, 3, 4]])
    msg = reconstructed_object_msg(7, (vertices, faces), [(vertices[:4], faces[:1])], 0.4, "arm")
    assert isinstance(msg, ReconstructedObject) and msg.id == 7 and msg.method == "arm"
    T, (v, f), parts = reconstructed_object_from_msg(msg)
    assert np.allclose(T[:3, 3], vertices.mean(0)) and np.allclose(v + T[:3, 3], vertices)
    assert np.array_equal(f, faces) and len(parts) == 1 and np.allclose(parts[0][0] + T[:3, 3], vertices[:4])
    msg.mesh.triangles[0].vertex_indices = [0, 1, 9]
    with pytest.raises(ConversionError, match="out of range"):
        reconstructed_object_from_msg(msg)


def test_stamps_round_trip_exactly_through_nanoseconds():
    ns = 1_732_000_000_123_456_789
    stamp = ns_to_time(ns)
    assert (stamp.sec, stamp.nanosec) == (1_732_000_000, 123_456_789) and time_ns(stamp) == ns
    assert time_ns(ns_to_time(-5)) == 0


def test_durations_round_to_whole_nanoseconds():
    assert (seconds_to_duration(1.5).sec, seconds_to_duration(1.5).nanosec) == (1, 500_000_000)
    below_one = seconds_to_duration(0.9999999999999999)
    assert (below_one.sec, below_one.nanosec) == (1, 0)
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="finite and >= 0"):
            seconds_to_duration(bad)


@pytest.mark.parametrize("message_type", [Image, CameraInfo, PoseStamped])
def test_header_stamps_are_read_from_serialized_messages(message_type):
    msg = message_type()
    msg.header = Header(stamp=ns_to_time(1_764_000_000_123_456_789), frame_id="camera_optical")
    assert cdr_header_stamp_ns(serialize_message(msg)) == 1_764_000_000_123_456_789


def test_big_endian_cdr_stamps_are_read_and_other_bytes_are_refused():
    big_endian = b"\x00\x00\x00\x00" + (12).to_bytes(4, "big") + (5).to_bytes(4, "big") + b"\x00" * 8
    assert cdr_header_stamp_ns(big_endian) == 12_000_000_005
    assert cdr_header_stamp_ns(b"\x00\x01\x00\x00\x01") is None  # too short
    assert cdr_header_stamp_ns(b"\x00\x07\x00\x00" + b"\x00" * 12) is None  # another encapsulation
