"""Message-level processing of one synchronized frame, without rclpy (testable on its own).

decode_frame() turns the four camera messages into numpy inputs and rejects anything that cannot
be one consistent RGB-D frame; segment_messages() runs the segmentation (or passes ground-truth
masks through) and builds the SegmentedFrame and the overlay image to publish.
"""

from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from arm_interfaces.msg import SegmentedFrame
from arm_ros.conversions import (
    ConversionError,
    K_from_camera_info,
    depth_to_metres,
    image_to_numpy,
    numpy_to_image,
    pose_to_matrix,
)
from arm_segmentation.geometry import InputError
from arm_segmentation.segmentation import SegmentationParams, segment
from arm_segmentation.visualization import overlay

RGB_ENCODINGS = ("rgb8", "bgr8")
DEPTH_ENCODINGS = ("32FC1", "16UC1", "mono16")
LABEL_ENCODINGS = ("16UC1", "mono16")


class FrameError(ValueError):
    """The synchronized messages do not form a usable frame; nothing must be published."""


@dataclass
class DecodedFrame:
    rgb: np.ndarray  # HxWx3 uint8, RGB order
    depth_m: np.ndarray  # HxW float32 metres, 0 = no return
    K: np.ndarray  # 3x3
    T_world_camera: np.ndarray  # 4x4
    world_frame_id: str


def decode_frame(rgb_msg: Image, depth_msg: Image, info_msg: CameraInfo, pose_msg: PoseStamped) -> DecodedFrame:
    """Decode and cross-check one frame. Raises FrameError with a readable reason."""
    if rgb_msg.encoding not in RGB_ENCODINGS:
        raise FrameError(f"rgb encoding '{rgb_msg.encoding}' not supported (expected one of {RGB_ENCODINGS})")
    if depth_msg.encoding not in DEPTH_ENCODINGS:
        raise FrameError(f"depth encoding '{depth_msg.encoding}' not supported (expected one of {DEPTH_ENCODINGS})")
    try:
        rgb = image_to_numpy(rgb_msg)
        depth_m = depth_to_metres(depth_msg)
        K = K_from_camera_info(info_msg)
        T = pose_to_matrix(pose_msg.pose)
    except ConversionError as error:
        raise FrameError(str(error)) from error
    if rgb.shape[:2] != depth_m.shape:
        raise FrameError(f"rgb is {rgb.shape[1]}x{rgb.shape[0]} but depth is {depth_m.shape[1]}x{depth_m.shape[0]}")
    if info_msg.width and info_msg.height and (info_msg.height, info_msg.width) != depth_m.shape:
        raise FrameError(
            f"camera_info is {info_msg.width}x{info_msg.height} but depth is {depth_m.shape[1]}x{depth_m.shape[0]}"
        )
    world = pose_msg.header.frame_id or "world"
    return DecodedFrame(rgb, depth_m, K, T, world)


def decode_labels(labels_msg: Image, shape: tuple[int, int]) -> np.ndarray:
    """Ground-truth label image -> uint16 HxW. Raises FrameError on a wrong encoding or size."""
    if labels_msg.encoding not in LABEL_ENCODINGS:
        raise FrameError(f"label encoding '{labels_msg.encoding}' not supported (expected 16UC1)")
    try:
        labels = image_to_numpy(labels_msg)
    except ConversionError as error:
        raise FrameError(str(error)) from error
    if labels.shape != shape:
        raise FrameError(f"labels are {labels.shape[1]}x{labels.shape[0]} but depth is {shape[1]}x{shape[0]}")
    return labels.astype(np.uint16)


def build_segmented_frame(
    frame: DecodedFrame, depth_msg: Image, info_msg: CameraInfo, pose_msg: PoseStamped, labels: np.ndarray
) -> SegmentedFrame:
    msg = SegmentedFrame()
    msg.header = depth_msg.header
    msg.rgb = numpy_to_image(frame.rgb, "rgb8", depth_msg.header)
    msg.depth = numpy_to_image(frame.depth_m, "32FC1", depth_msg.header)
    msg.camera_info = info_msg
    msg.camera_pose = pose_msg.pose
    msg.world_frame_id = frame.world_frame_id
    msg.labels = numpy_to_image(labels.astype(np.uint16), "16UC1", depth_msg.header)
    ids = np.unique(labels)
    msg.instance_ids = [int(i) for i in ids[ids > 0]]
    return msg


def segment_messages(
    rgb_msg: Image,
    depth_msg: Image,
    info_msg: CameraInfo,
    pose_msg: PoseStamped,
    labels_msg: Image | None = None,
    params: SegmentationParams | None = None,
) -> tuple[SegmentedFrame, Image]:
    """One synchronized frame -> (SegmentedFrame, overlay rgb8 Image).

    With labels_msg (ground-truth masks) the labels are passed through instead of segmenting.
    Raises FrameError for frames that must not be published.
    """
    frame = decode_frame(rgb_msg, depth_msg, info_msg, pose_msg)
    if labels_msg is not None:
        labels = decode_labels(labels_msg, frame.depth_m.shape)
    else:
        try:
            labels = segment(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params)
        except InputError as error:
            raise FrameError(str(error)) from error
    segmented = build_segmented_frame(frame, depth_msg, info_msg, pose_msg, labels)
    overlay_msg = numpy_to_image(overlay(frame.rgb, labels), "rgb8", depth_msg.header)
    return segmented, overlay_msg
