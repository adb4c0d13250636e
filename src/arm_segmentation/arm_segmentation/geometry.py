"""Organized point clouds: validation, back-projection and surface normals (all vectorized)."""

import cv2
import numpy as np


class InputError(ValueError):
    """The RGB-D frame cannot be segmented: wrong shapes, bad intrinsics or a bad camera pose."""


def validate_frame(rgb, depth_m, K, T_world_camera):
    """Check and normalise one RGB-D frame.

    Returns (rgb uint8 HxWx3, depth_m float32 HxW with 0 where invalid, K float64 3x3,
    T_world_camera float64 4x4). Raises InputError on anything that cannot be repaired.
    """
    depth = np.asarray(depth_m)
    if depth.ndim != 2 or depth.shape[0] < 4 or depth.shape[1] < 4:
        raise InputError(f"depth must be an HxW image, got shape {depth.shape}")
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[:2] != depth.shape:
        raise InputError(f"rgb shape {rgb.shape} does not match depth shape {depth.shape} (HxWx3 expected)")
    if rgb.dtype != np.uint8:
        raise InputError(f"rgb must be uint8, got {rgb.dtype}")
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError("K must be a finite 3x3 pinhole matrix with fx, fy > 0")
    T = np.asarray(T_world_camera, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("T_world_camera must be a finite 4x4 matrix")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0.5:
        raise InputError("T_world_camera rotation is not orthonormal")
    depth = depth.astype(np.float32, copy=True)
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0
    return rgb, depth, K, T


def backproject(depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Depth (HxW, metres) -> camera-frame points HxWx3 (float32); invalid pixels give (0, 0, 0)."""
    h, w = depth_m.shape
    u = (np.arange(w, dtype=np.float32) - np.float32(K[0, 2])) / np.float32(K[0, 0])
    v = (np.arange(h, dtype=np.float32) - np.float32(K[1, 2])) / np.float32(K[1, 1])
    points = np.empty((h, w, 3), dtype=np.float32)
    points[..., 0] = depth_m * u[None, :]
    points[..., 1] = depth_m * v[:, None]
    points[..., 2] = depth_m
    return points


def transform_points(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (..., 3) points."""
    R = T[:3, :3].astype(np.float32)
    t = T[:3, 3].astype(np.float32)
    return points @ R.T + t


def preprocess_depth(depth_m: np.ndarray, fill_radius_px: int = 1, smooth_sigma_m: float = 0.01) -> np.ndarray:
    """Fill small holes whose neighbourhood lies on one surface, then edge-preserving smoothing.

    Holes next to a depth discontinuity stay 0; the bilateral filter does not average across
    discontinuities larger than a few smooth_sigma_m.
    """
    valid = depth_m > 0
    filled = depth_m
    if fill_radius_px > 0 and not np.all(valid):
        ksize = (2 * fill_radius_px + 1, 2 * fill_radius_px + 1)
        kernel = np.ones(ksize, np.uint8)
        total = cv2.boxFilter(depth_m, -1, ksize, normalize=False, borderType=cv2.BORDER_REPLICATE)
        count = cv2.boxFilter(valid.astype(np.float32), -1, ksize, normalize=False, borderType=cv2.BORDER_REPLICATE)
        local_max = cv2.dilate(depth_m, kernel)
        local_min = cv2.erode(np.where(valid, depth_m, np.float32(1e6)), kernel)
        mean = total / np.maximum(count, 1.0)
        fill = ~valid & (count >= 2) & (local_max - local_min <= 0.01 + 0.02 * local_max)
        filled = np.where(fill, mean, depth_m).astype(np.float32)
    if smooth_sigma_m <= 0:
        return filled
    smoothed = cv2.bilateralFilter(filled, 5, smooth_sigma_m, 2.0)
    smoothed[filled <= 0] = 0.0
    return smoothed


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
