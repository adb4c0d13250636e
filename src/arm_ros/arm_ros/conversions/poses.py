"""geometry_msgs/Pose and TransformStamped <-> 4x4 homogeneous transforms."""

import numpy as np
from geometry_msgs.msg import Pose, TransformStamped

from arm_ros.conversions import ConversionError


def quaternion_to_matrix(xyzw) -> np.ndarray:
    x, y, z, w = (float(v) for v in xyzw)
    n = x * x + y * y + z * z + w * w
    if not np.isfinite(n) or n < 1e-12:
        raise ConversionError(f"invalid quaternion {xyzw}")
    s = 2.0 / n
    return np.array(
        [
            [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
            [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
            [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
        ]
    )


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """3x3 rotation -> quaternion (x, y, z, w), w >= 0."""
    # Imported here: mujoco takes ~0.4 s to import (python -X importtime) and only this function
    # needs it, while every node imports the conversions.
    import mujoco

    wxyz = np.zeros(4)
    mujoco.mju_mat2Quat(wxyz, np.ascontiguousarray(rotation, dtype=np.float64).reshape(9))
    xyzw = np.array([wxyz[1], wxyz[2], wxyz[3], wxyz[0]])
    return -xyzw if xyzw[3] < 0 else xyzw


def pose_to_matrix(pose: Pose) -> np.ndarray:
    """geometry_msgs/Pose -> 4x4 homogeneous transform. Raises ConversionError if non-finite."""
    T = np.eye(4)
    o, p = pose.orientation, pose.position
    T[:3, :3] = quaternion_to_matrix((o.x, o.y, o.z, o.w))
    T[:3, 3] = (p.x, p.y, p.z)
    if not np.all(np.isfinite(T)):
        raise ConversionError("pose has non-finite values")
    return T


def matrix_to_pose(T: np.ndarray) -> Pose:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConversionError("transform must be a finite 4x4 matrix")
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in T[:3, 3])
    q = matrix_to_quaternion(T[:3, :3])
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (float(v) for v in q)
    return pose


def matrix_to_transform_msg(T_parent_child: np.ndarray, parent: str, child: str, stamp) -> TransformStamped:
    """4x4 T_parent_child -> geometry_msgs/TransformStamped (header.frame_id parent, child_frame_id child)."""
    pose = matrix_to_pose(T_parent_child)
    msg = TransformStamped(child_frame_id=child)
    msg.header.frame_id, msg.header.stamp = parent, stamp
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = (
        pose.position.x,
        pose.position.y,
        pose.position.z,
    )
    msg.transform.rotation = pose.orientation
    return msg


def transform_msg_to_matrix(msg: TransformStamped) -> np.ndarray:
    """geometry_msgs/TransformStamped -> 4x4 T_parent_child. Raises ConversionError if non-finite."""
    t, r = msg.transform.translation, msg.transform.rotation
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = t.x, t.y, t.z
    pose.orientation = r
    return pose_to_matrix(pose)
