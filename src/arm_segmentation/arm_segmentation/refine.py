"""Full-resolution refinement of instance labels computed on a subsampled working grid.

The upsampled labels are cut back to the full-resolution object evidence (pixels above their
support plane, or pixels without depth / in the table band whose colour is not the table's), then
flooded ring by ring into the remaining evidence pixels whose colour matches the instance: this
recovers thin parts (stems, poles, handles) and sharp boundaries lost by subsampling.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from arm_core.boxes import cropped_intrinsics
from arm_core.camera import world_height
from arm_core.vectors import channel_sum
from arm_segmentation.clustering import chromaticity, hue_distance
from arm_segmentation.table_plane import TableParams, band_for_depth


@dataclass(frozen=True)
class RefineParams:
    """Parameters of the full-resolution refinement (pixels at full resolution)."""

    iterations: int = 12
    chroma_threshold: float = 0.12
    table_colour_threshold: float = 0.1
    search_radius_px: int = 14
    colour_blur_px: int = 1
    min_instance_area_m2: float = 1.5e-4


def upsample(image: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour upsampling of an image subsampled with [::stride, ::stride]."""
    return np.repeat(np.repeat(image, stride, axis=0), stride, axis=1)[: shape[0], : shape[1]]


def upsample_linear(image: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling (float32) of an image subsampled with [::stride, ::stride]: full-resolution
    pixel (y, x) reads the working grid at (y / stride, x / stride), edges replicated."""
    to_working = np.array([[1.0 / stride, 0.0, 0.0], [0.0, 1.0 / stride, 0.0]])
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    image = np.asarray(image, dtype=np.float32)
    return cv2.warpAffine(image, to_working, (shape[1], shape[0]), flags=flags, borderMode=cv2.BORDER_REPLICATE)


def instance_colours(labels: np.ndarray, chroma: np.ndarray) -> np.ndarray:
    """(K + 1, 3) mean chromaticity of each instance (row 0 unused)."""
    n = int(labels.max())
    flat = labels.ravel()
    count = np.maximum(np.bincount(flat, minlength=n + 1), 1)
    return np.stack(
        [np.bincount(flat, weights=chroma[..., k].ravel(), minlength=n + 1) / count for k in range(3)], axis=1
    )


def refine_full_resolution(
    labels_work: np.ndarray,
    chroma_work: np.ndarray,
    support_work: np.ndarray,
    table_chroma_work: np.ndarray | None,
    stride: int,
    rgb: np.ndarray,
    depth_m: np.ndarray,
    K: np.ndarray,
    T_world_camera: np.ndarray,
    table_params: TableParams,
    params: RefineParams = RefineParams(),
    missing_ok: np.ndarray | None = None,
) -> np.ndarray:
    """Full-resolution uint16 labels from working-grid labels (see the module docstring).

    missing_ok: HxW bool, the pixels without depth that may belong to an object (all when None)."""
    shape = depth_m.shape
    n = int(labels_work.max())
    if n == 0:
        return np.zeros(shape, dtype=np.uint16)
    wy, wx = np.nonzero(labels_work)
    margin = -(-params.search_radius_px // stride) + 1
    wy0, wx0 = max(wy.min() - margin, 0), max(wx.min() - margin, 0)
    wy1, wx1 = min(wy.max() + margin + 1, labels_work.shape[0]), min(wx.max() + margin + 1, labels_work.shape[1])
    y0, x0 = wy0 * stride, wx0 * stride
    y1, x1 = min(wy1 * stride, shape[0]), min(wx1 * stride, shape[1])
    crop = (slice(y0, y1), slice(x0, x1))

    def up(image):
        return upsample(image[wy0:wy1, wx0:wx1], stride, (y1 - y0, x1 - x0))

    labels_crop = up(labels_work)
    near = cv2.dilate((labels_crop > 0).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=params.search_radius_px)
    K_crop = cropped_intrinsics(K, crop)
    depth = depth_m[crop]
    support = up(support_work)
    height = world_height(depth, K_crop, T_world_camera) - support
    has_depth = depth > 0
    band = band_for_depth(depth, table_params)
    with np.errstate(invalid="ignore"):
        above = has_depth & (height > band) & (height <= table_params.max_object_height_m)
        table = has_depth & (np.abs(height) <= band)
    chroma = chromaticity(rgb[crop], blur=params.colour_blur_px)
    missing = ~has_depth if missing_ok is None else missing_ok[crop]
    colour_only = (table | missing) & (near > 0)
    if table_chroma_work is not None:
        table_chroma = up(table_chroma_work)
        cy, cx = np.nonzero(colour_only)
        off_table = hue_distance(chroma[cy, cx], table_chroma[cy, cx]) > params.table_colour_threshold
        colour_only[cy[~off_table], cx[~off_table]] = False
    else:
        table_chroma = None
    evidence = above | colour_only
    out = np.where(evidence, labels_crop, 0).astype(np.uint16)
    means = instance_colours(labels_work, chroma_work)
    todo = evidence & (out == 0)
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(params.iterations):
        grown = cv2.dilate(out, kernel)
        gy, gx = np.nonzero(todo & (grown > 0))
        if len(gy) == 0:
            break
        owner = grown[gy, gx]
        pixel = chroma[gy, gx]
        to_instance = channel_sum(np.abs(pixel - means[owner]))
        if table_chroma is not None:
            to_table = hue_distance(pixel, table_chroma[gy, gx])
            ok = (to_instance <= params.chroma_threshold) & (~table[gy, gx] | (to_instance < to_table))
            ok |= above[gy, gx] & (to_instance < to_table) & (to_instance <= 2 * params.chroma_threshold)
            ok |= colour_only[gy, gx] & (to_instance < 0.5 * to_table)
        else:
            ok = to_instance <= params.chroma_threshold
        if not np.any(ok):
            break
        out[gy[ok], gx[ok]] = owner[ok]
        todo[gy[ok], gx[ok]] = False
    pixel_area = np.where(has_depth, depth * depth, 0.0) / (K[0, 0] * K[1, 1])
    instance_area = np.bincount(out.ravel(), weights=pixel_area.ravel(), minlength=n + 1)
    keep = instance_area >= params.min_instance_area_m2
    keep[0] = False
    remap = np.zeros(len(keep), dtype=np.uint16)
    remap[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.uint16)
    full = np.zeros(shape, dtype=np.uint16)
    full[crop] = remap[out]
    return full
