"""Message-level processing of one synchronized frame, without rclpy (testable on its own).

decode_camera_frame() decodes the camera messages (arm_ros.conversions.frames; colour in any of
arm_ros.colour.COLOUR_ENCODINGS) and undistorts colour and depth to the CameraInfo's K
(arm_core.distortion); segment_frame() runs the segmentation (or passes ground-truth masks through)
and builds the SegmentedFrame and the overlay image to publish; segment_messages() does both.
"""

from collections.abc import Callable

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from arm_core.camera import backproject_image
from arm_core.distortion import DistortionError, Undistorter, is_distorted
from arm_core.frames import FrameInputError, RgbdFrame
from arm_interfaces.msg import SegmentedFrame
from arm_ros.colour import as_rgb8_msg
from arm_ros.conversions import ConversionError
from arm_ros.conversions.clouds import labelled_cloud_msg
from arm_ros.conversions.frames import frame_from_camera_msgs, labels_from_msg, segmented_frame_msg
from arm_ros.conversions.images import numpy_to_image
from arm_segmentation.segmentation import SegmentationParams, segment_detailed
from arm_segmentation.visualization import overlay

_UNDISTORTER = Undistorter()  # remap maps cached per camera, shared by the frames of this process


class FrameError(ValueError):
    """The synchronized messages do not form a usable frame; nothing must be published."""


def decode_camera_frame(
    rgb_msg: Image, depth_msg: Image, info_msg: CameraInfo, pose_msg: PoseStamped | None = None
) -> RgbdFrame:
    """Decode, cross-check and undistort one frame; without pose_msg its T_world_camera is None until
    the caller sets it (estimated camera pose). Raises FrameError with a readable reason."""
    try:
        frame = frame_from_camera_msgs(as_rgb8_msg(rgb_msg), depth_msg, info_msg, pose_msg or PoseStamped())
        frame.rgb, frame.depth_m = _UNDISTORTER.undistort(
            frame.rgb, frame.depth_m, info_msg.distortion_model, info_msg.d, frame.K
        )
    except ConversionError as error:
        raise FrameError(str(error)) from error
    except DistortionError as error:
        raise FrameError(f"camera_info: {error}") from error
    if pose_msg is None:
        frame.T_world_camera = None
    return frame


def undistorted_info(info_msg: CameraInfo) -> CameraInfo:
    """The CameraInfo of the undistorted images: the same K, D all zero."""
    if not is_distorted(info_msg.distortion_model, info_msg.d):
        return info_msg
    info = CameraInfo(header=info_msg.header, height=info_msg.height, width=info_msg.width)
    info.distortion_model, info.d = "plumb_bob", [0.0] * 5
    info.k, info.r, info.p = info_msg.k, info_msg.r, info_msg.p
    info.binning_x, info.binning_y, info.roi = info_msg.binning_x, info_msg.binning_y, info_msg.roi
    return info


def segment_frame(
    frame: RgbdFrame,
    depth_msg: Image,
    info_msg: CameraInfo,
    pose_msg: PoseStamped,
    labels_msg: Image | None = None,
    params: SegmentationParams | None = None,
    exclude_fn: Callable | None = None,
) -> tuple[SegmentedFrame, Image]:
    """A decoded frame whose T_world_camera is known (pose_msg carries it) -> (SegmentedFrame, overlay
    rgb8 Image). With labels_msg (ground-truth masks) the labels are passed through instead of
    segmenting; exclude_fn(frame) -> HxW bool marks pixels that are never objects (the robot's self
    mask). The SegmentedFrame carries the depth message's header, the camera's camera_info (D
    zeroed when the images were undistorted) and pose. Raises FrameError."""
    reason = ""
    try:
        if labels_msg is not None:
            frame.labels = labels_from_msg(labels_msg, frame.depth_m.shape)
            reason = "" if frame.labels.any() else "the ground-truth masks hold no object"
        else:
            exclude = exclude_fn(frame) if exclude_fn is not None else None
            result = segment_detailed(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params, exclude)
            frame.labels, reason = result.labels, result.empty_reason
    except (ConversionError, FrameInputError) as error:
        raise FrameError(str(error)) from error
    segmented = segmented_frame_msg(frame, depth_msg.header, undistorted_info(info_msg), pose_msg.pose)
    segmented.empty_reason = reason
    overlay_msg = numpy_to_image(overlay(frame.rgb, frame.labels), "rgb8", depth_msg.header)
    return segmented, overlay_msg


def segment_messages(
    rgb_msg: Image,
    depth_msg: Image,
    info_msg: CameraInfo,
    pose_msg: PoseStamped,
    labels_msg: Image | None = None,
    params: SegmentationParams | None = None,
    exclude_fn: Callable | None = None,
) -> tuple[SegmentedFrame, Image]:
    """One synchronized frame -> (SegmentedFrame, overlay rgb8 Image); see segment_frame."""
    frame = decode_camera_frame(rgb_msg, depth_msg, info_msg, pose_msg)
    return segment_frame(frame, depth_msg, info_msg, pose_msg, labels_msg, params, exclude_fn)


def object_cloud(frame: RgbdFrame, header) -> PointCloud2:
    """PointCloud2 of the segmented frame's object pixels with depth: x, y, z in the camera's optical
    frame (header's frame_id, metres), their colour and their instance label (arm_ros.conversions.clouds)."""
    has = (frame.labels > 0) & (frame.depth_m > 0)
    points = backproject_image(np.where(has, frame.depth_m, 0.0).astype(np.float32), frame.K)[has]
    return labelled_cloud_msg(points, frame.rgb[has], frame.labels[has], header)
