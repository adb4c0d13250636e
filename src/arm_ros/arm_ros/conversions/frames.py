"""RGB-D frames: the camera topics (rgb, depth, camera_info, pose) and arm_interfaces/SegmentedFrame
<-> arm_core.frames.RgbdFrame. Decoders raise ConversionError with a readable reason."""

import numpy as np
from geometry_msgs.msg import Pose, PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from arm_core.frames import RgbdFrame
from arm_interfaces.msg import SegmentedFrame
from arm_ros.conversions import ConversionError
from arm_ros.conversions.images import (
    K_from_camera_info,
    camera_info_from_K,
    depth_to_metres,
    labels_to_numpy,
    numpy_to_image,
    rgb_to_numpy,
)
from arm_ros.conversions.poses import matrix_to_pose, pose_to_matrix


def _stamp_s(header) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _size(shape) -> str:
    return f"{shape[1]}x{shape[0]}"


def _decode(rgb_msg: Image | None, depth_msg: Image, info: CameraInfo, pose: Pose, world_frame_id: str) -> RgbdFrame:
    depth_m = depth_to_metres(depth_msg)
    rgb = None if rgb_msg is None else rgb_to_numpy(rgb_msg)
    if rgb is not None and rgb.shape[:2] != depth_m.shape:
        raise ConversionError(f"rgb is {_size(rgb.shape)} but depth is {_size(depth_m.shape)}")
    K = K_from_camera_info(info)
    info_shape = (int(info.height), int(info.width))
    if info_shape != (0, 0) and info_shape != depth_m.shape:
        raise ConversionError(f"camera_info is {_size(info_shape)} but depth is {_size(depth_m.shape)}")
    T_world_camera = pose_to_matrix(pose)
    return RgbdFrame(rgb, depth_m, K, T_world_camera, None, world_frame_id or "world", _stamp_s(depth_msg.header))


def frame_from_camera_msgs(rgb_msg: Image, depth_msg: Image, info: CameraInfo, pose_msg: PoseStamped) -> RgbdFrame:
    """One synchronized set of camera messages -> RgbdFrame without labels (world frame: the pose's
    frame_id, 'world' when empty)."""
    return _decode(rgb_msg, depth_msg, info, pose_msg.pose, pose_msg.header.frame_id)


def labels_from_msg(msg: Image, shape: tuple[int, int]) -> np.ndarray:
    """Instance label image of a frame of the given (H, W) -> uint16 HxW."""
    labels = labels_to_numpy(msg)
    if labels.shape != tuple(shape):
        raise ConversionError(f"labels are {_size(labels.shape)} but depth is {_size(shape)}")
    return labels


def frame_from_msg(msg: SegmentedFrame) -> RgbdFrame:
    """SegmentedFrame -> RgbdFrame with labels (rgb None when the message carries none)."""
    rgb_msg = msg.rgb if msg.rgb.height and msg.rgb.width else None
    frame = _decode(rgb_msg, msg.depth, msg.camera_info, msg.camera_pose, msg.world_frame_id)
    frame.labels = labels_from_msg(msg.labels, frame.depth_m.shape)
    return frame


def segmented_frame_msg(
    frame: RgbdFrame, header=None, camera_info: CameraInfo | None = None, camera_pose: Pose | None = None
) -> SegmentedFrame:
    """RgbdFrame with labels -> SegmentedFrame (rgb8, 32FC1 metres, 16UC1 labels, all with header).
    camera_info / camera_pose: the camera's own messages, passed through unchanged; built from
    frame.K and frame.T_world_camera when None."""
    if frame.labels is None:
        raise ConversionError("a SegmentedFrame needs labels")
    msg = SegmentedFrame()
    if header is not None:
        msg.header = header
    depth_m = np.asarray(frame.depth_m, dtype=np.float32)
    if frame.rgb is not None:
        msg.rgb = numpy_to_image(np.asarray(frame.rgb, dtype=np.uint8), "rgb8", msg.header)
    msg.depth = numpy_to_image(depth_m, "32FC1", msg.header)
    if camera_info is None:
        camera_info = camera_info_from_K(frame.K, depth_m.shape[1], depth_m.shape[0], msg.header)
    msg.camera_info = camera_info
    msg.camera_pose = matrix_to_pose(frame.T_world_camera) if camera_pose is None else camera_pose
    msg.world_frame_id = frame.world_frame_id
    labels = np.asarray(frame.labels, dtype=np.uint16)
    msg.labels = numpy_to_image(labels, "16UC1", msg.header)
    msg.instance_ids = [int(i) for i in np.unique(labels) if i > 0]
    return msg
