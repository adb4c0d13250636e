"""numpy <-> ROS message conversions shared by every node (no cv_bridge on this platform).

Only message classes are imported, never rclpy, so the conversions stay testable without a ROS graph.
"""

import numpy as np
from geometry_msgs.msg import Point, Pose
from sensor_msgs.msg import CameraInfo, Image
from shape_msgs.msg import Mesh, MeshTriangle

# encoding -> (numpy dtype, channels)
IMAGE_ENCODINGS = {
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "mono8": (np.uint8, 1),
    "mono16": (np.uint16, 1),
    "16UC1": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "32SC1": (np.int32, 1),
}


class ConversionError(ValueError):
    """A message could not be converted: unknown encoding, wrong sizes, non-finite values."""


def image_to_numpy(msg: Image) -> np.ndarray:
    """Image -> HxW or HxWxC array (a copy). Raises ConversionError on malformed messages."""
    if msg.encoding not in IMAGE_ENCODINGS:
        raise ConversionError(f"unsupported image encoding '{msg.encoding}'")
    dtype, channels = IMAGE_ENCODINGS[msg.encoding]
    itemsize = np.dtype(dtype).itemsize
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ConversionError(f"empty image {width}x{height}")
    row_bytes = width * channels * itemsize
    if step < row_bytes or len(msg.data) < step * height:
        raise ConversionError(
            f"image data too short: {len(msg.data)} bytes for {width}x{height} {msg.encoding} step {step}"
        )
    buffer = np.frombuffer(bytes(msg.data), dtype=np.uint8, count=step * height).reshape(height, step)
    array = buffer[:, :row_bytes].copy().view(dtype)
    if msg.is_bigendian != (np.little_endian is False) and itemsize > 1:
        array = array.byteswap()
    array = array.reshape(height, width, channels)
    if msg.encoding == "bgr8":
        array = array[..., ::-1].copy()
    return array[..., 0] if channels == 1 else array


def numpy_to_image(array: np.ndarray, encoding: str, header=None) -> Image:
    """HxW or HxWxC array -> Image with the given encoding."""
    if encoding not in IMAGE_ENCODINGS:
        raise ConversionError(f"unsupported image encoding '{encoding}'")
    dtype, channels = IMAGE_ENCODINGS[encoding]
    array = np.ascontiguousarray(array, dtype=dtype)
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3 or array.shape[2] != channels:
        raise ConversionError(f"array of shape {array.shape} does not fit encoding {encoding}")
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(array.shape[0]), int(array.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(array.shape[1] * channels * array.itemsize)
    msg.data = array.tobytes()
    return msg


def depth_to_metres(msg: Image) -> np.ndarray:
    """Depth Image (32FC1 metres or 16UC1/mono16 millimetres) -> float32 metres, 0 = no return."""
    depth = image_to_numpy(msg)
    if msg.encoding in ("16UC1", "mono16"):
        depth_m = depth.astype(np.float32) * 1e-3
    elif msg.encoding == "32FC1":
        depth_m = depth.astype(np.float32)
    else:
        raise ConversionError(f"depth encoding must be 32FC1 or 16UC1, got '{msg.encoding}'")
    depth_m[~np.isfinite(depth_m) | (depth_m < 0)] = 0.0
    return depth_m


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


def mesh_to_msg(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """(N,3) vertices in metres and (M,3) triangle indices -> shape_msgs/Mesh."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.uint32).reshape(-1, 3)
    msg = Mesh()
    msg.vertices = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in vertices]
    msg.triangles = [MeshTriangle(vertex_indices=[int(a), int(b), int(c)]) for a, b, c in faces]
    return msg


def msg_to_mesh(msg: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """shape_msgs/Mesh -> ((N,3) float64 vertices, (M,3) int64 faces). Raises on bad indices."""
    vertices = np.array([(p.x, p.y, p.z) for p in msg.vertices], dtype=np.float64).reshape(-1, 3)
    faces = np.array([t.vertex_indices for t in msg.triangles], dtype=np.int64).reshape(-1, 3)
    if not np.all(np.isfinite(vertices)):
        raise ConversionError("mesh has non-finite vertices")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ConversionError("mesh triangle indices out of range")
    return vertices, faces


def camera_info_from_K(K: np.ndarray, width: int, height: int, header=None) -> CameraInfo:
    info = CameraInfo()
    if header is not None:
        info.header = header
    info.width, info.height = int(width), int(height)
    info.distortion_model = "plumb_bob"
    info.d = [0.0] * 5
    info.k = [float(v) for v in np.asarray(K, dtype=np.float64).reshape(9)]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    P = np.zeros((3, 4))
    P[:3, :3] = np.asarray(K).reshape(3, 3)
    info.p = [float(v) for v in P.reshape(12)]
    return info


def K_from_camera_info(info: CameraInfo) -> np.ndarray:
    """CameraInfo -> 3x3 K. Raises ConversionError on zero or non-finite intrinsics."""
    K = np.array(info.k, dtype=np.float64).reshape(3, 3)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not np.all(np.isfinite(K)) or fx <= 0 or fy <= 0 or cx <= 0 or cy <= 0:
        raise ConversionError(f"invalid intrinsics fx={fx} fy={fy} cx={cx} cy={cy}")
    return K


def object_msg(
    object_id: int,
    T_world_object,
    mesh_local,
    convex_parts_local=(),
    visible_fraction: float = -1.0,
    method: str = "",
    grid=None,
):
    """Object-frame meshes (trimesh or (V, F)) + T_world_object -> arm_interfaces/ReconstructedObject."""
    from arm_interfaces.msg import ReconstructedObject

    msg = ReconstructedObject(id=int(object_id), visible_fraction=float(visible_fraction), method=method)
    msg.pose = matrix_to_pose(T_world_object)
    msg.mesh = mesh_to_msg(*_as_vf(mesh_local))
    msg.convex_parts = [mesh_to_msg(*_as_vf(p)) for p in convex_parts_local]
    if grid is not None:
        msg.grid = grid
    return msg


def _as_vf(mesh) -> tuple[np.ndarray, np.ndarray]:
    return (np.asarray(mesh.vertices), np.asarray(mesh.faces)) if hasattr(mesh, "vertices") else mesh


def reconstructed_object_msg(
    object_id: int, mesh_world, convex_parts_world=(), visible_fraction: float = -1.0, method: str = "", grid=None
):
    """World-frame meshes -> ReconstructedObject whose object frame is parallel to the world frame with its
    origin at the mesh's vertex centroid (see the message definition)."""
    vertices, faces = _as_vf(mesh_world)
    T = np.eye(4)
    T[:3, 3] = np.asarray(vertices, dtype=np.float64).mean(axis=0) if len(vertices) else 0.0
    parts = [(np.asarray(v) - T[:3, 3], f) for v, f in map(_as_vf, convex_parts_world)]
    return object_msg(object_id, T, (np.asarray(vertices) - T[:3, 3], faces), parts, visible_fraction, method, grid)


def reconstructed_object_from_msg(msg) -> tuple[np.ndarray, tuple, list]:
    """arm_interfaces/ReconstructedObject -> (T_world_object, (V, F) mesh, [(V, F)] convex parts), object frame."""
    T = pose_to_matrix(msg.pose)
    return T, msg_to_mesh(msg.mesh), [msg_to_mesh(p) for p in msg.convex_parts]
