"""The one pinhole camera model: intrinsics, poses, projection, back-projection and silhouettes.

T_world_camera is the pose of the optical frame (x right, y down, z forward) in the world frame;
K is a 3x3 pinhole matrix in pixels; depth is metres along the optical axis, 0 = no return.
"""

import cv2
import numpy as np


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


def pixel_coordinates(points_camera: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Optical-frame points (..., 3), z > 0 -> pixel coordinates (u, v), each of shape (...)."""
    x, y, z = points_camera[..., 0], points_camera[..., 1], points_camera[..., 2]
    return x / z * K[0, 0] + K[0, 2], y / z * K[1, 1] + K[1, 2]


def project_points(points_world: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray):
    """World points (N,3) -> pixel coordinates (N,2) and optical-frame depth (N,)."""
    T_camera_world = np.linalg.inv(T_world_camera)
    p = points_world @ T_camera_world[:3, :3].T + T_camera_world[:3, 3]
    z = p[:, 2]
    u, v = pixel_coordinates(np.column_stack([p[:, :2], np.maximum(z, 1e-9)]), K)
    return np.stack([u, v], axis=1), z


def fill_convex_hull(mask: np.ndarray, points_px: np.ndarray) -> None:
    """Set the pixels of mask whose centres lie inside the 2D convex hull of points_px (N, 2) (image
    coordinates of project_points: pixel (row v, column u) has its centre at (u + 0.5, v + 0.5)),
    which reproduces MuJoCo's rendered silhouettes."""
    if len(points_px) < 3:
        return
    hull = cv2.convexHull(np.asarray(points_px, np.float32)).reshape(-1, 2).astype(np.float64)
    if len(hull) < 3:
        return
    height, width = mask.shape
    lo = np.maximum(np.ceil(hull.min(0) - 0.5), 0).astype(np.int64)
    hi = np.minimum(np.floor(hull.max(0) - 0.5), [width - 1, height - 1]).astype(np.int64)
    if np.any(hi < lo):
        return
    # Row by row: each edge bounds the centres' u on one side (cross product >= 0 towards the inside).
    edges = np.roll(hull, -1, axis=0) - hull
    orientation = np.sign(np.sum(hull[:, 0] * np.roll(hull[:, 1], -1) - np.roll(hull[:, 0], -1) * hull[:, 1]))
    rows = np.arange(lo[1], hi[1] + 1)
    pv = rows[:, None] + 0.5
    # cross = edge_u * (pv - hull_v) - edge_v * (pu - hull_u) = level - edge_v * pu
    level = orientation * (edges[:, 0] * (pv - hull[:, 1]) + edges[:, 1] * hull[:, 0])
    slope = orientation * edges[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = level / slope
    u_min = np.max(np.where(slope < 0, bound, -np.inf), axis=1)
    u_max = np.min(np.where(slope > 0, bound, np.inf), axis=1)
    flat_outside = np.any((slope == 0) & (level < 0), axis=1)
    pu = np.arange(lo[0], hi[0] + 1) + 0.5
    inside = (pu >= u_min[:, None]) & (pu <= u_max[:, None]) & ~flat_outside[:, None]
    mask[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1] |= inside


def silhouette(convex_parts_world, K, T_world_camera, width: int, height: int, near_m: float = 0.01) -> np.ndarray:
    """Boolean mask of the pixels an object covers when rendered alone: the union of the projections
    of its convex parts (each projects to the convex hull of its projected vertices), given as a list
    of (N, 3) world-frame vertex arrays."""
    mask = np.zeros((height, width), bool)
    for vertices in convex_parts_world:
        uv, z = project_points(np.asarray(vertices, dtype=np.float64), K, T_world_camera)
        fill_convex_hull(mask, np.clip(uv[z > near_m], -1e5, 1e5))
    return mask


def normalized_coordinates(v, u, K: np.ndarray, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Pixel rows v and columns u -> (x / z, y / z): where their rays cross the optical frame's
    z = 1 plane, computed in dtype."""
    x = (np.asarray(u).astype(dtype) - dtype(K[0, 2])) / dtype(K[0, 0])
    y = (np.asarray(v).astype(dtype) - dtype(K[1, 2])) / dtype(K[1, 1])
    return x, y


def transform_points(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (..., 3) points, in the points' dtype."""
    R = T[:3, :3].astype(points.dtype)
    t = T[:3, 3].astype(points.dtype)
    return points @ R.T + t


def backproject_image(depth_m: np.ndarray, K: np.ndarray, dtype=np.float32) -> np.ndarray:
    """Organized depth image (HxW, metres) -> HxWx3 optical-frame points in dtype; pixels without a
    return (depth 0) give (0, 0, 0)."""
    h, w = depth_m.shape
    x, _ = normalized_coordinates(0, np.arange(w), K, dtype)
    _, y = normalized_coordinates(np.arange(h), 0, K, dtype)
    points = np.empty((h, w, 3), dtype=dtype)
    points[..., 0] = depth_m * x[None, :]
    points[..., 1] = depth_m * y[:, None]
    points[..., 2] = depth_m
    return points


def organized_normals(points: np.ndarray, step_px: int = 2) -> np.ndarray:
    """Unit normals (HxWx3, camera frame, pointing towards the camera) from central differences.

    Differences are taken `step_px` pixels apart; pixels whose neighbours are missing get a zero normal.
    """
    s = step_px
    h, w, _ = points.shape
    dx = np.zeros_like(points)
    dy = np.zeros_like(points)
    dx[:, s:-s] = points[:, 2 * s :] - points[:, : -2 * s]
    dy[s:-s, :] = points[2 * s :, :] - points[: -2 * s, :]
    nx = dx[..., 1] * dy[..., 2] - dx[..., 2] * dy[..., 1]
    ny = dx[..., 2] * dy[..., 0] - dx[..., 0] * dy[..., 2]
    nz = dx[..., 0] * dy[..., 1] - dx[..., 1] * dy[..., 0]
    z = points[..., 2]
    ok = z > 0
    ok[:, s:-s] &= (z[:, 2 * s :] > 0) & (z[:, : -2 * s] > 0)
    ok[s:-s, :] &= (z[2 * s :, :] > 0) & (z[: -2 * s, :] > 0)
    ok[:, :s] = ok[:, -s:] = ok[:s, :] = ok[-s:, :] = False
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    ok &= norm > 1e-12
    towards_camera = nx * points[..., 0] + ny * points[..., 1] + nz * z <= 0
    scale = np.where(ok, np.where(towards_camera, 1.0, -1.0) / np.where(ok, norm, 1.0), 0.0).astype(np.float32)
    return np.stack([nx * scale, ny * scale, nz * scale], axis=-1)


def backproject_pixels(depth_m: np.ndarray, v: np.ndarray, u: np.ndarray, K, T_world_camera, dtype=np.float64):
    """Pixels (rows v, columns u) of a depth image (metres) -> (N, 3) world points in dtype."""
    z = depth_m[v, u].astype(dtype)
    x, y = normalized_coordinates(v, u, K, dtype)
    return transform_points(np.stack([x * z, y * z, z], 1), T_world_camera)


def world_height(depth_m: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray) -> np.ndarray:
    """HxW float32 world z of every pixel of a depth image (meaningless where depth is 0)."""
    h, w = depth_m.shape
    r = T_world_camera[2, :3]
    x, _ = normalized_coordinates(0, np.arange(w), K, np.float32)
    _, y = normalized_coordinates(np.arange(h), 0, K, np.float32)
    u, v = x * np.float32(r[0]), y * np.float32(r[1])
    return depth_m * (u[None, :] + v[:, None] + np.float32(r[2])) + np.float32(T_world_camera[2, 3])


def ray_directions_world(v, u, K: np.ndarray, T_world_camera: np.ndarray) -> np.ndarray:
    """(N, 3) float32 world-frame direction of the rays of pixels (v, u), scaled to unit optical depth."""
    x, y = normalized_coordinates(v, u, K, np.float32)
    R = T_world_camera[:3, :3].astype(np.float32)
    return x[:, None] * R[:, 0] + y[:, None] * R[:, 1] + R[:, 2]
