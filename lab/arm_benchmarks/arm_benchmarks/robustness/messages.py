"""Input messages for the nodes: header stamps, camera messages, segmented frames, joint states."""

from __future__ import annotations

import dataclasses

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from arm_ros.conversions.frames import segmented_frame_msg as frame_to_segmented_msg
from arm_ros.conversions.images import camera_info_from_K, numpy_to_image
from arm_ros.conversions.poses import matrix_to_pose
from arm_sim import robot

CAMERA_TOPICS = ("camera/color/image_raw", "camera/depth/image_raw", "camera/camera_info", "camera/pose")


def stamp_of(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def header_at(stamp_s: float, frame_id: str) -> Header:
    header = Header(frame_id=frame_id)
    ns = int(round(stamp_s * 1e9))
    header.stamp.sec, header.stamp.nanosec = ns // 10**9, ns % 10**9
    return header


def camera_messages(
    frame, stamp_s: float, camera_frame_id: str = "camera_color_optical_frame", world_frame_id: str = "world"
) -> dict:
    """rgb, depth, camera_info and pose messages of one RgbdFrame, keyed by CAMERA_TOPICS."""
    header = header_at(stamp_s, camera_frame_id)
    h, w = frame.depth_m.shape
    return {
        "camera/color/image_raw": numpy_to_image(frame.rgb, "rgb8", header),
        "camera/depth/image_raw": numpy_to_image(frame.depth_m, "32FC1", header),
        "camera/camera_info": camera_info_from_K(frame.K, w, h, header),
        "camera/pose": PoseStamped(
            header=header_at(stamp_s, world_frame_id), pose=matrix_to_pose(frame.T_world_camera)
        ),
    }


def segmented_frame_msg(frame, stamp_s: float, labels: np.ndarray | None = None):
    """SegmentedFrame of an RgbdFrame with its simulator labels (the ground-truth segmentation)."""
    labels = frame.labels if labels is None else labels
    header = header_at(stamp_s, "camera_color_optical_frame")
    return frame_to_segmented_msg(dataclasses.replace(frame, labels=labels, world_frame_id="world"), header)


def joint_state_msg(stamp_s: float = 0.0, q=None, opening_m: float = 0.04) -> JointState:
    q = robot.HOME_Q if q is None else q
    names = list(robot.JOINT_NAMES) + [robot.FINGER_JOINT_NAMES[0]]
    return JointState(header=header_at(stamp_s, ""), name=names, position=[float(v) for v in q] + [float(opening_m)])
