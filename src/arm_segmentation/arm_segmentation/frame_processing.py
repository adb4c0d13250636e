"""Message-level processing of one synchronized frame, without rclpy (testable on its own).

segment_messages() decodes the four camera messages (arm_ros.conversions.frames), runs the
segmentation (or passes ground-truth masks through) and builds the SegmentedFrame and the overlay
image to publish.
"""

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from arm_core.frames import FrameInputError
from arm_interfaces.msg import SegmentedFrame
from arm_ros.conversions import ConversionError
from arm_ros.conversions.frames import frame_from_camera_msgs, labels_from_msg, segmented_frame_msg
from arm_ros.conversions.images import numpy_to_image
from arm_segmentation.segmentation import SegmentationParams, segment
from arm_segmentation.visualization import overlay


class FrameError(ValueError):
    """The synchronized messages do not form a usable frame; nothing must be published."""


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
    The SegmentedFrame carries the depth message's header and the camera's own camera_info and pose.
    Raises FrameError for frames that must not be published.
    """
    try:
        frame = frame_from_camera_msgs(rgb_msg, depth_msg, info_msg, pose_msg)
        if labels_msg is not None:
            frame.labels = labels_from_msg(labels_msg, frame.depth_m.shape)
        else:
            frame.labels = segment(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params)
    except (ConversionError, FrameInputError) as error:
        raise FrameError(str(error)) from error
    segmented = segmented_frame_msg(frame, depth_msg.header, info_msg, pose_msg.pose)
    overlay_msg = numpy_to_image(overlay(frame.rgb, frame.labels), "rgb8", depth_msg.header)
    return segmented, overlay_msg
