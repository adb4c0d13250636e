"""Organized depth images: hole filling, smoothing and surface normals (all vectorized)."""

import cv2
import numpy as np


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
