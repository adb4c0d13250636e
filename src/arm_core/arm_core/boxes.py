"""The box around a mask's pixels: one helper for every crop (segmentation's fine pass, figures)."""

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
