"""Pinhole camera model, camera pose sampling and silhouette rasterisation.

T_world_camera is the pose of the optical frame (x right, y down, z forward) in the world frame.
MuJoCo cameras look along their -z with +y up, i.e. R_world_mjcam = R_world_camera @ diag(1, -1, -1).
"""

from dataclasses import dataclass

import cv2
import numpy as np

OPTICAL_TO_MUJOCO = np.diag([1.0, -1.0, -1.0])


@dataclass
class RgbdFrame:
    """One rendered frame. labels: 0 background/table, i + 1 = scene object i."""

    rgb: np.ndarray
    depth_m: np.ndarray
    labels: np.ndarray
    K: np.ndarray
    T_world_camera: np.ndarray
    visible_fraction: np.ndarray
    stamp_s: float = 0.0


def intrinsics(width: int = 640, height: int = 480, fovy_deg: float = 45.0) -> np.ndarray:
    """Pinhole K (pixels) for a vertical field of view, square pixels, centred principal point."""
    fy = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2)
    return np.array([[fy, 0.0, width / 2.0], [0.0, fy, height / 2.0], [0.0, 0.0, 1.0]])


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """T_world_camera of an optical frame at eye looking at target (image 'up' towards up)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def sample_camera_pose(
    rng: np.random.Generator, table_centre, min_distance_m: float = 0.125, max_distance_m: float = 1.5,
    min_elevation_deg: float = 15.0,
) -> np.ndarray:
    """A camera pose as in the paper's benchmark table: position uniform in the half-shell between
    min and max distance above the table centre, looking at a random point in a sphere of radius
    min(distance / 2, 0.25). A minimum elevation keeps the table in view."""
    table_centre = np.asarray(table_centre, dtype=np.float64)
    while True:
        direction = rng.normal(size=3)
        direction[2] = abs(direction[2])
        direction /= np.linalg.norm(direction)
        if np.degrees(np.arcsin(direction[2])) >= min_elevation_deg:
            break
    radius = rng.uniform(min_distance_m**3, max_distance_m**3) ** (1.0 / 3.0)
    eye = table_centre + radius * direction
    offset = rng.normal(size=3)
    offset *= min(radius / 2, 0.25) * rng.uniform() ** (1 / 3) / np.linalg.norm(offset)
    return look_at(eye, table_centre + offset)


def project_points(points_world: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray):
    """World points (N,3) -> pixel coordinates (N,2) and optical-frame depth (N,)."""
    T_camera_world = np.linalg.inv(T_world_camera)
    p = points_world @ T_camera_world[:3, :3].T + T_camera_world[:3, 3]
    z = p[:, 2]
    uv = (p[:, :2] / np.maximum(z[:, None], 1e-9)) * np.diag(K)[:2] + K[:2, 2]
    return uv, z


def silhouette(vertices_world, faces, K, T_world_camera, width: int, height: int, near_m: float = 0.01):
    """Boolean mask of the pixels a mesh covers when rendered alone (one vectorised fillPoly)."""
    uv, z = project_points(np.asarray(vertices_world), K, T_world_camera)
    faces = np.asarray(faces)
    in_front = np.all(z[faces] > near_m, axis=1)
    triangles = np.round(uv[faces[in_front]] * 16).astype(np.int32)
    mask = np.zeros((height, width), np.uint8)
    if len(triangles):
        cv2.fillPoly(mask, list(triangles), 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def backproject(depth_m: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray) -> np.ndarray:
    """Depth image -> (H,W,3) world points (NaN where depth is 0)."""
    h, w = depth_m.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    z = np.where(depth_m > 0, depth_m, np.nan).astype(np.float32)
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    p = np.stack([x, y, z], -1)
    return p @ T_world_camera[:3, :3].T.astype(np.float32) + T_world_camera[:3, 3].astype(np.float32)
