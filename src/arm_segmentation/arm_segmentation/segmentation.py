"""Default unseen-object instance segmentation: support planes, then 3D instance clustering.

`segment(rgb, depth_m, K, T_world_camera)` needs no learned weights and runs on the CPU.
"""

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage

from arm_segmentation.clustering import ClusterParams, chromaticity, cluster_instances, hue_distance
from arm_segmentation.geometry import (
    backproject,
    organized_normals,
    preprocess_depth,
    transform_points,
    validate_frame,
)
from arm_segmentation.refine import RefineParams, refine_full_resolution, upsample
from arm_segmentation.table_plane import (
    SupportLevel,
    TableParams,
    band_for_depth,
    classify_heights,
    estimate_support_levels,
    pixel_area_m2,
    support_heights,
)


@dataclass(frozen=True)
class SegmentationParams:
    """All parameters of the default method. Pixel sizes refer to the working resolution: the
    input subsampled by working_stride (2: a 640x480 frame is processed at 320x240)."""

    working_stride: int = 2
    workspace_min_m: tuple[float, float, float] = (-np.inf, -np.inf, -np.inf)  # world-frame crop box;
    workspace_max_m: tuple[float, float, float] = (np.inf, np.inf, np.inf)  # object points outside are ignored

    fill_radius_px: int = 1
    smooth_sigma_m: float = 0.01
    table_colour_threshold: float = 0.1
    candidate_radius_px: int = 4
    table_colour_window_px: int = 15
    table: TableParams = field(default_factory=TableParams)
    cluster: ClusterParams = field(default_factory=ClusterParams)
    refine: RefineParams = field(default_factory=RefineParams)


@dataclass
class SegmentationResult:
    labels: np.ndarray  # uint16 HxW, 0 = table / background, k > 0 = instance k
    table_mask: np.ndarray  # bool HxW
    levels: list[SupportLevel]


def local_table_chroma(chroma: np.ndarray, table: np.ndarray, window_px: int) -> np.ndarray:
    """HxWx3 mean chromaticity of the table pixels around each pixel (the global median where none).

    Table colour varies with lighting (glare, saturation), so candidates are compared locally.
    """
    weight = table.astype(np.float32)
    ksize = (window_px, window_px)
    count = cv2.boxFilter(weight, -1, ksize, normalize=False)
    total = cv2.boxFilter(chroma * weight[..., None], -1, ksize, normalize=False)
    fallback = np.median(chroma[table][:: max(1, int(table.sum()) // 5000)], axis=0)
    return np.where(count[..., None] > 0.5, total / np.maximum(count, 1.0)[..., None], fallback).astype(np.float32)


def segment_detailed(rgb, depth_m, K, T_world_camera, params: SegmentationParams | None = None):
    """Segment one frame; also returns the table mask and the support levels found.

    Raises geometry.InputError for frames that cannot be interpreted (shapes, intrinsics, pose).
    A frame without a visible table gives an all-zero label image.
    """
    params = params or SegmentationParams()
    rgb_full, depth_full, K_full, T = validate_frame(rgb, depth_m, K, T_world_camera)
    stride = params.working_stride
    rgb, depth, K = rgb_full, depth_full, K_full
    if stride > 1:
        rgb, depth = rgb_full[::stride, ::stride], depth_full[::stride, ::stride]
        K = K_full.copy()
        K[:2] /= stride
    smoothed = preprocess_depth(depth, params.fill_radius_px, params.smooth_sigma_m)
    points_camera = backproject(smoothed, K)
    normals_camera = organized_normals(points_camera, params.cluster.step_px)
    valid = normals_camera[..., 2] != 0
    points_world = transform_points(points_camera, T)
    normals_world = normals_camera @ T[:3, :3].T.astype(np.float32)
    area = pixel_area_m2(points_camera, normals_camera, K)
    area[~valid] = 0.0
    levels = estimate_support_levels(points_world, normals_world, area, valid, params.table)
    support = support_heights(points_world, smoothed, levels, params.table)
    table, objects = classify_heights(points_world[..., 2], smoothed, support, params.table)
    if np.isfinite(params.workspace_min_m).any() or np.isfinite(params.workspace_max_m).any():
        lo = np.asarray(params.workspace_min_m, dtype=np.float32)
        hi = np.asarray(params.workspace_max_m, dtype=np.float32)
        objects &= np.all((points_world >= lo) & (points_world <= hi), axis=-1)
    chroma = chromaticity(rgb)
    candidates = np.zeros_like(objects)
    table_chroma = None
    if np.any(table) and np.any(objects):
        table_chroma = local_table_chroma(chroma, table, params.table_colour_window_px)
        not_table_colour = hue_distance(chroma, table_chroma) > params.table_colour_threshold
        radius = params.candidate_radius_px
        disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        near_objects = cv2.dilate(objects.astype(np.uint8), disk) > 0
        candidates = near_objects & not_table_colour & (table | (smoothed <= 0))
    labels = cluster_instances(
        points_camera, normals_camera, smoothed, chroma, objects, candidates, valid, area, table_chroma, params.cluster
    )
    labels = drop_support_structure(labels, points_world, smoothed, support, levels, params.table)
    if stride > 1:
        labels = refine_full_resolution(
            labels, chroma, support, table_chroma, stride, rgb_full, depth_full, K_full, T, params.table, params.refine
        )
        table = upsample(table, stride, depth_full.shape)
    return SegmentationResult(labels=labels, table_mask=table, levels=levels)


def drop_support_structure(labels, points_world, depth_m, support, levels, params: TableParams) -> np.ndarray:
    """Remove instances that are the side of a higher support level (a shelf's front face).

    Such an instance stands on a lower level and reaches up to a higher level's height at that
    level's footprint; objects on the higher level are measured from it and are kept.
    """
    n = int(labels.max())
    if n == 0 or len(levels) < 2:
        return labels
    z = points_world[..., 2]
    has = (labels > 0) & (depth_m > 0)
    band = band_for_depth(depth_m, params)
    ids = np.arange(1, n + 1)
    support_of = ndimage.maximum(np.nan_to_num(support, nan=-np.inf), labels, ids)
    drop = np.zeros(n + 1, dtype=bool)
    for level in levels:
        near_top = has & (np.abs(z - level.height_m) <= 2 * band)
        ys, xs = np.nonzero(near_top)
        inside = level.contains_xy(points_world[ys, xs, :2], params.footprint_margin_m)
        reaches = np.bincount(labels[ys[inside], xs[inside]], minlength=n + 1) > 0
        drop[1:] |= reaches[1:] & (np.asarray(support_of) < level.height_m - 0.02)
    if not np.any(drop):
        return labels
    return _renumber(np.where(drop[labels], 0, labels))


def _renumber(labels: np.ndarray) -> np.ndarray:
    used = np.unique(labels)
    remap = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    remap[used[used > 0]] = np.arange(1, int(np.count_nonzero(used)) + 1, dtype=np.uint16)
    return remap[labels]


def segment(rgb, depth_m, K, T_world_camera, params: SegmentationParams | None = None) -> np.ndarray:
    """RGB-D frame -> instance labels (uint16 HxW): 0 = table / background, k > 0 = object k."""
    return segment_detailed(rgb, depth_m, K, T_world_camera, params).labels
