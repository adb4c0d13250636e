"""Full-resolution border refinement of instance labels from colour.

Depth edges are a poor guide to an object's outline on a real sensor: returns are lost on both
sides of the edge and depth is registered to colour about a pixel off. Pixels within band_px of
an instance's outline are given to the side whose colour they resemble: each is compared with
the nearest pixels well inside the instance and well outside it (the background at that place),
sampled from a lightly blurred image.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from arm_core.boxes import mask_box
from arm_core.vectors import channel_sum


@dataclass(frozen=True)
class BorderParams:
    """Parameters of refine_borders (full-resolution pixels)."""

    band_px: int = 2  # pixels this near an outline are decided anew
    blur_px: int = 3  # box filter of the colour samples
    margin: float = 0.0  # a band pixel becomes object when d_object + margin < d_background


def nearest_pixel(mask: np.ndarray, at: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of a nearest pixel of the non-empty HxW bool mask to each pixel at = (rows, cols)
    (OpenCV's 5x5 distance transform: a few times faster than an exact one, and exact this near)."""
    _, index = cv2.distanceTransformWithLabels(
        (~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE, labelType=cv2.DIST_LABEL_PIXEL
    )
    flat = np.flatnonzero(mask)  # row-major, the order OpenCV numbers the mask's pixels in
    return np.divmod(flat[index[at] - 1], mask.shape[1])


def refine_borders(labels: np.ndarray, rgb: np.ndarray, params: BorderParams = BorderParams()) -> np.ndarray:
    """uint16 labels with the pixels near the instances' outlines reassigned by colour."""
    box = mask_box(labels, 3 * params.band_px + 2)
    if params.band_px <= 0 or box is None:
        return labels
    out = labels.copy()
    out[box] = _refine(labels[box], rgb[box], params)
    return out


@dataclass
class OutlineBand:
    """The band pixels (rows, cols) of a label image, each with its nearest pixel well inside an
    instance (inside_rows, inside_cols) and well outside every instance (outside_rows, outside_cols),
    and the instance it would join (candidate)."""

    rows: np.ndarray
    cols: np.ndarray
    inside_rows: np.ndarray
    inside_cols: np.ndarray
    outside_rows: np.ndarray
    outside_cols: np.ndarray
    candidate: np.ndarray


def outline_band(labels: np.ndarray, band_px: int) -> OutlineBand | None:
    """The pixels within band_px of the outline between the instances and the background (the
    image border is no outline), or None when there is no instance or no background."""
    covered = (labels > 0).astype(np.uint8)
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    inside = cv2.erode(covered, disk, borderValue=1) > 0
    outside = cv2.erode(1 - covered, disk, borderValue=1) > 0
    if not np.any(inside) or not np.any(outside):
        return None
    rows, cols = np.nonzero(~inside & ~outside)
    iy, ix = nearest_pixel(inside, (rows, cols))
    oy, ox = nearest_pixel(outside, (rows, cols))
    return OutlineBand(rows, cols, iy, ix, oy, ox, labels[iy, ix])


def _refine(labels: np.ndarray, rgb: np.ndarray, params: BorderParams) -> np.ndarray:
    band = outline_band(labels, params.band_px)
    if band is None:
        return labels
    colour = cv2.blur(rgb, (params.blur_px, params.blur_px)).astype(np.float32) if params.blur_px > 1 else rgb
    colour = np.asarray(colour, dtype=np.float32)
    pixel = rgb[band.rows, band.cols].astype(np.float32)
    to_object = channel_sum(np.abs(pixel - colour[band.inside_rows, band.inside_cols]))
    to_background = channel_sum(np.abs(pixel - colour[band.outside_rows, band.outside_cols]))
    is_object = to_object + params.margin < to_background
    out = labels.copy()
    out[band.rows, band.cols] = np.where(is_object, band.candidate, 0)
    return out


def grow_into_objectness(labels: np.ndarray, objectness: np.ndarray, threshold: float, reach_px: int) -> np.ndarray:
    """uint16 labels with the unlabelled pixels whose object probability (HxW, the boundary
    network's object channel at full resolution) exceeds threshold and that lie within reach_px of
    an instance given to the nearest instance: flat bases in the table band and surfaces without
    depth that geometry leaves out."""
    box = mask_box(labels, reach_px + 1)
    if box is None or reach_px <= 0:
        return labels
    crop = labels[box]
    free = crop == 0
    distance = cv2.distanceTransform(free.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    grow = free & (objectness[box] > threshold) & (distance <= reach_px)
    if not np.any(grow):
        return labels
    rows, cols = np.nonzero(grow)
    iy, ix = nearest_pixel(~free, (rows, cols))
    grown = crop.copy()
    grown[rows, cols] = crop[iy, ix]
    out = labels.copy()
    out[box] = grown
    return out
