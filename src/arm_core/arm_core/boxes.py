"""The box around a mask's pixels: one helper for every crop (segmentation's fine pass, figures),
and the intrinsics of a cropped or resized image."""

from __future__ import annotations

import numpy as np


def mask_box(
    mask: np.ndarray, margin_px: int = 0, stride: int = 1, shape: tuple[int, int] | None = None
) -> tuple[slice, slice] | None:
    """(rows, cols) slices boxing the mask's nonzero pixels with margin_px to spare on each side,
    clipped to the image; None for an empty mask. stride: the image has stride times the mask's
    resolution (mask pixel (r, c) covers image rows r * stride .. (r + 1) * stride - 1), margin_px
    and the slices are in image pixels; shape: the image's (rows, cols), the mask's times stride by
    default."""
    rows = np.flatnonzero(np.any(mask, axis=1))  # projections: cheaper than every nonzero pixel
    if rows.size == 0:
        return None
    cols = np.flatnonzero(np.any(mask, axis=0))
    height, width = shape if shape is not None else (mask.shape[0] * stride, mask.shape[1] * stride)
    return (
        slice(max(int(rows[0]) * stride - margin_px, 0), min((int(rows[-1]) + 1) * stride + margin_px, height)),
        slice(max(int(cols[0]) * stride - margin_px, 0), min((int(cols[-1]) + 1) * stride + margin_px, width)),
    )


def cropped_intrinsics(K: np.ndarray, crop: tuple[slice, slice]) -> np.ndarray:
    """The pinhole K of the (rows, cols) crop of an image with intrinsics K."""
    K_crop = np.array(K, dtype=np.float64)
    K_crop[0, 2] -= crop[1].start
    K_crop[1, 2] -= crop[0].start
    return K_crop


def resized_intrinsics(K: np.ndarray, from_shape: tuple[int, int], to_shape: tuple[int, int]) -> np.ndarray:
    """The pinhole K of an image with intrinsics K resized from from_shape to to_shape (rows, cols);
    pixel centres at integer coordinates, as OpenCV's resize places them."""
    sy, sx = to_shape[0] / from_shape[0], to_shape[1] / from_shape[1]
    K_resized = np.array(K, dtype=np.float64)
    K_resized[0, 0], K_resized[0, 1], K_resized[0, 2] = K[0, 0] * sx, K[0, 1] * sx, (K[0, 2] + 0.5) * sx - 0.5
    K_resized[1, 1], K_resized[1, 2] = K[1, 1] * sy, (K[1, 2] + 0.5) * sy - 0.5
    return K_resized
